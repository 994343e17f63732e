"""A ``gymnasium.Env`` of any scene and task, so that any reinforcement-learning library can train
on our plant.

:class:`~drake_abs.tasks.gym_env.DrakeAbsEnv` steps the task's stepper on a batch of one and
scores the step with the task's own reward and termination (the code the batched objective runs,
not a copy).

Spaces as gymnasium's v5 MuJoCo environments: actions ``Box(-1, 1, (nu,), float32)`` (the
task's stepper scales them to joint torques), observations ``Box(-inf, inf, (n_obs,),
float64)``. ``reset(seed=...)`` draws the task's reset noise from the environment's
``np_random``; with the same seed it draws what gymnasium's own Hopper-v5 / HalfCheetah-v5 draw.
Episodes are truncated after ``max_episode_steps`` steps (default 1000, gymnasium's), at the
scene's time step (``dt``; see :mod:`drake_abs.tasks.locomotion` on how it differs from
gymnasium's).

:func:`step_task` is that step for a batch of B environments in one call of the stepper (what
:class:`DrakeAbsEnv` runs with B = 1, and :mod:`drake_abs.tasks.sb3_vec_env` with B = n_envs).

The gymnasium ids ``drake_abs/Hopper-v0``, ``drake_abs/HalfCheetah-v0``, ``drake_abs/Walker2d-v0``
and ``drake_abs/Ant-v0`` make this environment; ``import drake_abs`` registers them
(:mod:`drake_abs.tasks.gym_registration`, whose
:func:`~drake_abs.tasks.gym_registration.register_envs` and
:data:`~drake_abs.tasks.gym_registration.ENV_IDS` this module re-exports).

Needs gymnasium (a dependency of the package, as the locomotion tasks' scenes read its model
files), not MuJoCo; the rest of :mod:`drake_abs.tasks` imports neither.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np
from gymnasium import spaces

from drake_abs._validation import as_count, as_finite_array
from drake_abs.engine.steppers import inside_ground, refuse_inside_ground
from drake_abs.tasks.gym_registration import ENV_IDS, register_envs
from drake_abs.tasks.locomotion import LocomotionTask, locomotion_task

__all__ = ["ENV_IDS", "DrakeAbsEnv", "TaskSteps", "register_envs", "step_task"]


class DrakeAbsEnv(gymnasium.Env):
    """gymnasium's environment interface over a task: a
    :class:`~drake_abs.tasks.locomotion.LocomotionTask` (or its name), or any object with the
    same ``stepper`` (taking actions in [-1, 1]), ``reward`` (``transition`` or ``stage``;
    optional ``terminated``), ``observation``, ``initial_states(rng, M)``, ``x0``, ``nu``,
    ``n_obs``, ``dt`` and optional ``info(x, u, x_next)`` and ``reset_info(x)``.

    Args:
        task: the task, or ``"hopper"`` / ``"half_cheetah"`` (built with ``task_options``, see
            :func:`~drake_abs.tasks.locomotion.locomotion_task`).
        max_episode_steps: steps after which an episode is truncated (None: never; a
            ``TimeLimit`` wrapper, as ``gymnasium.make`` adds, does it then).
        render_mode: only None (no rendering).

    ``step`` returns gymnasium's ``info`` keys (``x_position``, ``x_velocity``,
    ``reward_forward``, ``reward_ctrl``, and for the Hopper ``reward_survive``,
    ``z_distance_from_origin``) plus ``converged``: whether the contact solver converged (a
    False step's state is not exact), and ``penetration``: how deep (m) the new state is
    inside the ground (0 when no contact candidate is below its surface; above the plant's
    tolerance, :data:`drake_abs.multibody.stepper.PENETRATION_TOL`, the state is not one the
    step models). ``reset``'s ``info`` has gymnasium's keys only.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        task: LocomotionTask | str = "hopper",
        *,
        max_episode_steps: int | None = 1000,
        render_mode: str | None = None,
        **task_options,
    ):
        task = task_of(task, task_options)
        if render_mode is not None:
            raise ValueError(f"render_mode must be None (no rendering); got {render_mode!r}")
        self.max_episode_steps = episode_limit(max_episode_steps)
        self.task = task
        self.render_mode = None
        self.dt = float(task.dt)
        self.metadata = {"render_modes": [], "render_fps": int(np.round(1.0 / self.dt))}
        self.action_space = spaces.Box(-1.0, 1.0, (task.nu,), np.float32)
        self.observation_space = spaces.Box(-np.inf, np.inf, (task.n_obs,), np.float64)
        self._x = np.array(task.x0, dtype=float)
        self._steps = 0

    @property
    def state(self) -> np.ndarray:
        """The current state x = (q, v) (nx,) (a copy)."""
        return self._x.copy()

    def set_state(self, q, v) -> None:
        """Set the state to (q, v) (as MuJoCo environments' ``set_state(qpos, qvel)``). A state
        deeper inside the ground than the plant's tolerance
        (the stepper's ``penetration_tolerance``: 1 cm with hard contact, 5 cm with soft,
        :data:`drake_abs.multibody.stepper.PENETRATION_TOL`) is refused (``ValueError``
        with its depth): the step would push the body out in one step and call it converged."""
        x = np.concatenate([as_finite_array(q, "q").ravel(), as_finite_array(v, "v").ravel()])
        if x.shape != self._x.shape:
            raise ValueError(
                f"q and v must be finite with {self._x.size} entries in all; got {x.shape}"
            )
        refuse_inside_ground(self.task.stepper, x, "the state (q, v)")
        self._x = x

    def _obs(self) -> np.ndarray:
        return np.asarray(self.task.observation(self._x[None])[0], dtype=np.float64)

    def _info(self, name: str, *args) -> dict[str, float]:
        make = getattr(self.task, name, None)
        return {} if make is None else {k: float(v[0]) for k, v in make(*args).items()}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode at the task's initial state plus its reset noise (drawn from
        ``np_random``, seeded by ``seed``). Returns (observation, info)."""
        super().reset(seed=seed)
        self._x = self.task.initial_states(self.np_random, 1)[0]
        self._steps = 0
        return self._obs(), self._info("reset_info", self._x[None])

    def step(self, action):
        """Apply ``action`` (nu,) for one time step. Returns (observation, reward, terminated,
        truncated, info)."""
        a = as_finite_array(action, "action", ndim=(1,))
        if a.shape != (self.task.nu,):
            raise ValueError(f"action must have shape (nu,) = ({self.task.nu},); got {a.shape}")
        steps = step_task(self.task, self._x[None], a[None])
        info = {k: float(v[0]) for k, v in steps.info.items()}
        info["converged"] = bool(steps.converged[0])
        self._x = steps.x_next[0]
        self._steps += 1
        truncated = self.max_episode_steps is not None and self._steps >= self.max_episode_steps
        return self._obs(), float(steps.reward[0]), bool(steps.terminated[0]), truncated, info


@dataclass(frozen=True)
class TaskSteps:
    """One environment step of B copies of a task (:func:`step_task`).

    Attributes:
        x_next: (B, nx) the states after the step.
        reward: (B,) the task's reward of each transition.
        terminated: (B,) bool, the task's termination at x_next (all False without one).
        converged: (B,) bool, whether the contact solve converged (a False row's x_next is the
            solver's last iterate: not exact, but finite).
        info: gymnasium's ``info`` entries of the task (``task.info``), each (B,), with
            ``penetration`` (m, how deep x_next is inside the ground) where the plant tells.
    """

    x_next: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray
    converged: np.ndarray
    info: dict[str, np.ndarray]


def task_of(task: LocomotionTask | str, task_options: dict) -> LocomotionTask:
    """``task`` itself, or the task of that name built with ``task_options`` (which apply to a
    task given by name only: ValueError otherwise)."""
    if isinstance(task, str):
        return locomotion_task(task, **task_options)
    if task_options:
        raise ValueError(f"task_options {sorted(task_options)} apply to a task given by name only")
    return task


def episode_limit(max_episode_steps: int | None) -> int | None:
    """``max_episode_steps`` checked: a whole number >= 1, or None (no limit)."""
    if max_episode_steps is None:
        return None
    return as_count(max_episode_steps, "max_episode_steps", minimum=1)


def step_task(task, x, u) -> TaskSteps:
    """Step B environments of ``task`` (as :class:`DrakeAbsEnv` takes it) in one call of its
    stepper and score each transition with the task's own reward, termination and info.

    Args:
        task: a task (see :class:`DrakeAbsEnv`).
        x: (B, nx) states.
        u: (B, nu) actions in [-1, 1].

    Raises:
        ValueError: x or u of the wrong shape.
        FloatingPointError: a next state is not finite (the rows, states and actions named).
    """
    x = as_finite_array(x, "x", ndim=(2,))
    u = as_finite_array(u, "u", ndim=(2,))
    nx, nu = task.x0.size, task.nu
    if x.ndim != 2 or x.shape[1] != nx or u.shape != (x.shape[0], nu):
        raise ValueError(
            f"x and u must have shapes (B, nx) = (B, {nx}) and (B, nu) = (B, {nu}); got "
            f"{x.shape} and {u.shape}"
        )
    step = task.stepper.step(x, u, jacobians=False)
    x_next = np.asarray(step.x_next, dtype=float).reshape(x.shape)
    bad = np.flatnonzero(~np.all(np.isfinite(x_next), axis=1))
    if bad.size:
        raise FloatingPointError(
            f"step_task: the next state of row(s) {bad.tolist()} is not finite (states "
            f"{x[bad].tolist()}, actions {u[bad].tolist()})"
        )
    reward = task.reward
    extra = {"step": step} if getattr(reward, "uses_step", False) else {}
    if hasattr(reward, "transition"):
        r = reward.transition(x, u, x_next, **extra)[0]
    else:
        r = reward.stage(x, u)[0]
    if hasattr(reward, "terminated"):
        terminated = np.asarray(reward.terminated(x_next), dtype=bool).reshape(x.shape[0])
    else:
        terminated = np.zeros(x.shape[0], dtype=bool)
    make = getattr(task, "info", None)
    info = {} if make is None else dict(make(x, u, x_next, *([step] if extra else [])))
    if "penetration" not in info:  # a task that does not report it: from its plant
        found = inside_ground(task.stepper, x_next)
        if found is not None:
            info["penetration"] = found[0]
    converged = np.asarray(step.converged, dtype=bool).reshape(x.shape[0])
    return TaskSteps(x_next, np.asarray(r, dtype=float), terminated, converged, info)
