"""Saved policies of the locomotion tasks: loading one back into its task, and running it
deterministically (no exploration noise) on our plant.

- :func:`save_policy` is :func:`drake_abs.policy.saving.save_policy` (``STEM.npz`` + ``STEM.json``;
  ``task=`` the task or its name).
- :func:`load_policy` rebuilds a saved policy; one saved for a task's observation becomes
  ``locomotion_task(name).policy(inner)`` (the task is built: Drake), and the task comes with it
  (``SavedPolicy.task``).
- :func:`reset_state` is the state gymnasium's ``reset(seed=seed)`` starts from (the task's initial
  state plus its reset noise, drawn as gymnasium draws it), and :func:`run_episode` runs a policy
  from a state for a number of steps, as :class:`drake_abs.tasks.gym_env.DrakeAbsEnv` steps it
  (the task's stepper on a batch of one, its reward and termination), without gymnasium.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from drake_abs._validation import as_count, as_finite_array
from drake_abs.engine.protocols import Policy
from drake_abs.policy.saving import SavedPolicy, save_policy
from drake_abs.policy.saving import load_policy as load_generic
from drake_abs.tasks.locomotion import TASKS, LocomotionTask, locomotion_task

__all__ = ["Episode", "load_policy", "reset_state", "run_episode", "save_policy"]


def load_policy(path: str | Path, *, task: LocomotionTask | None = None) -> SavedPolicy:
    """Load a saved policy (``STEM.json``, ``STEM.npz`` or ``STEM``) with its task.

    Args:
        path: the saved policy.
        task: the task to act in, if built already (its ``name`` must be the saved task's);
            default: ``locomotion_task(name)`` with the scene's own smoothing (exact contact for
            gymnasium's scenes), built here.

    Returns:
        The :class:`~drake_abs.policy.saving.SavedPolicy`: ``policy`` the full-state policy of
        the task (``policy.act(theta, x (M, nx))``), ``inner`` the saved policy, ``task`` the
        task (None for a policy saved without one).

    Raises:
        ValueError: see :func:`drake_abs.policy.saving.load_policy`; also a saved task that is
            not a locomotion task, a ``task`` of another name, or a policy whose sizes do not fit
            the task.
    """
    built: dict[str, LocomotionTask] = {}

    def task_of(name) -> LocomotionTask:
        if task is not None:
            if task.name != name:
                raise ValueError(
                    f"task is {task.name!r}, but the saved policy acts in task {name!r}"
                )
            return task
        if name not in TASKS:
            raise ValueError(
                f"the saved policy acts in task {name!r}, which is not a locomotion task "
                f"({sorted(TASKS)}): pass task= (a LocomotionTask of that name)"
            )
        if name not in built:
            built[name] = locomotion_task(name)
        return built[name]

    def wrap(name: str, inner: Policy) -> Policy:
        return task_of(name).policy(inner)

    saved = load_generic(path, wrap=wrap)
    if saved.task_name is None:
        if task is not None:
            raise ValueError(
                f"task is {task.name!r}, but the saved policy {str(saved.path)!r} names no task"
            )
        return saved
    the_task = task_of(saved.task_name)
    if saved.policy.nx != the_task.nx or saved.policy.nu != the_task.nu:
        raise ValueError(
            f"the saved policy (nx {saved.policy.nx}, nu {saved.policy.nu}) does not fit task "
            f"{the_task.name!r} (nx {the_task.nx}, nu {the_task.nu})"
        )
    return replace(saved, task=the_task)


def reset_state(task: LocomotionTask, seed: int) -> np.ndarray:
    """(nx,) the state an episode starts from after ``reset(seed=seed)``: the task's x0 plus its
    reset noise drawn from ``np.random.default_rng(seed)``, which is gymnasium's seeding (the
    same state as gymnasium's own Hopper-v5 / HalfCheetah-v5 and
    :class:`~drake_abs.tasks.gym_env.DrakeAbsEnv` start from with that seed)."""
    seed = as_count(seed, "seed", minimum=0)
    return task.initial_states(np.random.default_rng(seed), 1)[0]


@dataclass(frozen=True)
class Episode:
    """One deterministic episode on our plant.

    Attributes:
        states: (T + 1, nx) x_0 .. x_T, one every ``dt`` s.
        actions: (T, nu) the policy's actions (in [-1, 1] for a sensible policy; not clipped,
            as gymnasium does not clip what its control cost sees).
        rewards: (T,) the task's reward of each transition.
        terminated: the task terminated the episode (the Hopper fell): at its last step, or
            (``stop_at_termination=False``) at any step.
        converged: every contact solve converged.
        dt: the time step (s).
    """

    states: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminated: bool
    converged: bool
    dt: float

    @property
    def steps(self) -> int:
        """T, the number of steps taken."""
        return int(self.rewards.size)

    @property
    def total_return(self) -> float:
        """The sum of the rewards."""
        return float(self.rewards.sum())

    @property
    def seconds(self) -> float:
        """T dt, the simulated duration (s)."""
        return self.steps * self.dt

    @property
    def forward_distance(self) -> float:
        """The forward distance travelled, ``x_T[0] - x_0[0]`` in m (for the locomotion
        tasks)."""
        return float(self.states[-1, 0] - self.states[0, 0])


def run_episode(
    task: LocomotionTask,
    policy: Policy,
    theta,
    x0,
    steps: int,
    *,
    stop_at_termination: bool = True,
) -> Episode:
    """Run ``policy`` deterministically (no exploration noise) on ``task``'s stepper from ``x0``.

    Args:
        task: the task (its stepper, reward, termination and ``dt``).
        policy: a policy of the task's full state (e.g. ``SavedPolicy.policy``).
        theta: (P,) its parameters.
        x0: (nx,) the first state (e.g. :func:`reset_state`).
        steps: the most steps to take (>= 1).
        stop_at_termination: end the episode where the task terminates it (as gymnasium does),
            else run all ``steps``.

    Returns:
        The :class:`Episode`; the same states and rewards as
        :class:`~drake_abs.tasks.gym_env.DrakeAbsEnv` stepped with the same actions.
    """
    steps = as_count(steps, "steps", minimum=1)
    x = as_finite_array(x0, "x0", ndim=(1,))
    if x.shape != (task.nx,):
        raise ValueError(f"x0 must have shape (nx,) = ({task.nx},); got {x.shape}")
    if policy.nx != task.nx or policy.nu != task.nu:
        raise ValueError(
            f"policy must take the task's state (nx {task.nx}) and give its action (nu "
            f"{task.nu}); it has nx {policy.nx}, nu {policy.nu}"
        )
    theta = as_finite_array(theta, "theta", ndim=(1,))
    reward = task.reward
    states, actions, rewards = [x], [], []
    terminated, converged = False, True
    for _ in range(steps):
        u = np.asarray(policy.act(theta, x[None]), dtype=float).reshape(1, task.nu)
        step = task.stepper.step(x[None], u, jacobians=False)
        x_next = np.asarray(step.x_next, dtype=float).reshape(1, task.nx)
        if not np.all(np.isfinite(x_next)):
            raise FloatingPointError(f"run_episode: the next state is not finite at {x}")
        converged &= bool(np.asarray(step.converged).ravel()[0])
        if hasattr(reward, "transition"):
            r = reward.transition(x[None], u, x_next)[0]
        else:
            r = reward.stage(x[None], u)[0]
        rewards.append(float(np.asarray(r).ravel()[0]))
        actions.append(u[0])
        x = x_next[0]
        states.append(x)
        if hasattr(reward, "terminated") and bool(reward.terminated(x_next)[0]):
            terminated = True
        if terminated and stop_at_termination:
            break
    return Episode(
        states=np.array(states), actions=np.array(actions).reshape(-1, task.nu),
        rewards=np.array(rewards), terminated=terminated, converged=converged, dt=float(task.dt),
    )  # fmt: skip
