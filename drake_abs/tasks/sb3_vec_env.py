"""stable-baselines3's vectorised environment (``VecEnv``) over a task's batched stepper:
``n_envs`` copies of a task stepped in one call of ``task.stepper.step`` per environment step.

:class:`DrakeAbsVecEnv` gives what ``DummyVecEnv([DrakeAbsEnv(task), ...])`` (``n_envs``
independent :class:`~drake_abs.tasks.gym_env.DrakeAbsEnv`) gives for the same actions and
seeds: the same observations, rewards, dones, infos and resets, bit for bit (the batched
contact solve of our scenes rounds as the batch of one does:
``tests/tasks/test_sb3_vec_env.py``). It is faster because one batched step of B states costs
less than B steps of one (random actions, on two loaded cores: the Hopper 3.0 ms per step of
one environment, 0.84 ms per environment at B = 8, 0.58 ms at 16; the HalfCheetah, whose
states fall into more distinct contact sets, 9.0, 5.4 and 4.2 ms).

One ``step_async(actions)`` / ``step_wait()`` (actions (n_envs, nu) in [-1, 1]):

1. every environment's (x, u) in one :func:`~drake_abs.tasks.gym_env.step_task` (the task's
   stepper, reward, termination and info: what ``DrakeAbsEnv.step`` runs on a batch of one);
2. environment m is done when terminated (the task's) or truncated (its episode reached
   ``max_episode_steps`` steps); ``info["TimeLimit.truncated"] = truncated and not
   terminated``, as sb3's ``DummyVecEnv`` sets it;
3. a done environment keeps the step's observation in ``info["terminal_observation"]`` and is
   reset (sb3's auto-reset): the task's initial state plus its reset noise
   (``task.initial_states(rng_m, 1)``, gymnasium's noise) drawn from its own generator rng_m;
   the observation returned is the new episode's first;
4. ``info["converged"]``: whether the contact solve of that environment's step converged. An
   unconverged step is treated as ``DrakeAbsEnv`` treats it: reported, not an error; its state
   (the solver's last iterate, finite) is kept. A non-finite next state raises
   ``FloatingPointError`` (the rows named), as ``DrakeAbsEnv`` does.

Rewards are returned in float64 (the task's own numbers; ``DummyVecEnv`` keeps float32 copies,
and the algorithms store float32 in their buffers either way).

**Seeding** (sb3's convention, the one ``DummyVecEnv`` gives its environments): ``seed(s)`` (the
algorithm calls it with its own seed; or the constructor's ``seed``) makes the next
:meth:`~DrakeAbsVecEnv.reset` seed environment m's generator with ``s + m``
(``gymnasium.utils.seeding.np_random(s + m)``, what ``DrakeAbsEnv.reset(seed=s + m)``
seeds); every later reset of environment m, automatic or by ``reset()`` without a new seed,
continues its generator. A reset with no seed ever given draws fresh entropy (gymnasium's
behaviour).

Needs stable-baselines3 (the ``baselines`` extra) and gymnasium; only the baselines
(:mod:`drake_abs.tasks.sb3_baselines`) import this module.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvStepReturn

from drake_abs._validation import as_count
from drake_abs.tasks.gym_env import episode_limit, step_task, task_of
from drake_abs.tasks.locomotion import LocomotionTask

__all__ = ["DrakeAbsVecEnv"]


class DrakeAbsVecEnv(VecEnv):
    """``n_envs`` environments of one task as a stable-baselines3 ``VecEnv``, stepped in one
    batch (module docstring).

    Args:
        task: a task (:class:`~drake_abs.tasks.locomotion.LocomotionTask` or any object
            :class:`~drake_abs.tasks.gym_env.DrakeAbsEnv` takes), or a task's name (built with
            ``task_options``).
        n_envs: number of environments, >= 1.
        max_episode_steps: steps after which an episode is truncated (None: never).
        seed: if given, ``seed(seed)`` now: the first reset seeds environment m with
            ``seed + m``.

    Spaces as ``DrakeAbsEnv``'s: actions ``Box(-1, 1, (nu,), float32)``, observations
    ``Box(-inf, inf, (n_obs,), float64)``.
    """

    def __init__(
        self,
        task: LocomotionTask | str,
        n_envs: int,
        *,
        max_episode_steps: int | None = 1000,
        seed: int | None = None,
        **task_options,
    ):
        task = task_of(task, task_options)
        n_envs = as_count(n_envs, "n_envs", minimum=1)
        self.max_episode_steps = episode_limit(max_episode_steps)
        self.task = task
        self.render_mode = None
        self.dt = float(task.dt)
        self._x = np.tile(np.asarray(task.x0, dtype=float), (n_envs, 1))
        self._steps = np.zeros(n_envs, dtype=int)
        self._rngs: list[np.random.Generator | None] = [None] * n_envs
        self._actions: np.ndarray | None = None
        super().__init__(
            n_envs,
            spaces.Box(-np.inf, np.inf, (task.n_obs,), np.float64),
            spaces.Box(-1.0, 1.0, (task.nu,), np.float32),
        )
        if seed is not None:
            self.seed(seed)

    # ------------------------------------------------------------------------------- state

    @property
    def states(self) -> np.ndarray:
        """(n_envs, nx) the environments' current states x = (q, v) (a copy)."""
        return self._x.copy()

    @property
    def episode_steps(self) -> np.ndarray:
        """(n_envs,) steps taken in each environment's current episode (a copy)."""
        return self._steps.copy()

    def _observe(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self.task.observation(x), dtype=np.float64)

    def _reset_infos(self, x: np.ndarray) -> list[dict[str, float]]:
        make = getattr(self.task, "reset_info", None)
        values = {} if make is None else make(x)
        return [{k: float(v[m]) for k, v in values.items()} for m in range(x.shape[0])]

    def _draw(self, rows: Sequence[int], seeds: Sequence[int | None]) -> None:
        """New episodes for the environments ``rows``: reseed each generator whose seed is
        given (or that has none yet), draw its initial state."""
        for m, seed in zip(rows, seeds, strict=True):
            if seed is not None or self._rngs[m] is None:
                self._rngs[m], _ = seeding.np_random(seed)
            self._x[m] = self.task.initial_states(self._rngs[m], 1)[0]
            self._steps[m] = 0

    # ------------------------------------------------------------------------- VecEnv API

    def reset(self) -> np.ndarray:
        """Start a new episode in every environment (seeded as the module docstring says).
        Returns the observations (n_envs, n_obs); their ``info`` is in ``reset_infos``."""
        self._draw(range(self.num_envs), self._seeds)
        self._reset_seeds()
        self._reset_options()  # options are ignored, as DrakeAbsEnv.reset ignores them
        self.reset_infos = self._reset_infos(self._x)
        return self._observe(self._x)

    def step_async(self, actions: np.ndarray) -> None:
        """Store the actions (n_envs, nu) for :meth:`step_wait`."""
        a = np.asarray(actions, dtype=float)
        shape = (self.num_envs, self.task.nu)
        if a.shape != shape:
            raise ValueError(f"actions must have shape (n_envs, nu) = {shape}; got {a.shape}")
        self._actions = a

    def step_wait(self) -> VecEnvStepReturn:
        """Step every environment in one batch; auto-reset the done ones. Returns
        (observations (n_envs, n_obs), rewards (n_envs,), dones (n_envs,), infos)."""
        if self._actions is None:
            raise RuntimeError("step_wait needs a step_async(actions) before it")
        actions, self._actions = self._actions, None
        steps = step_task(self.task, self._x, actions)
        self._x = steps.x_next.copy()
        self._steps += 1
        if self.max_episode_steps is None:
            truncated = np.zeros(self.num_envs, dtype=bool)
        else:
            truncated = self._steps >= self.max_episode_steps
        dones = steps.terminated | truncated
        obs = self._observe(self._x)
        infos: list[dict[str, Any]] = []
        for m in range(self.num_envs):
            info = {k: float(v[m]) for k, v in steps.info.items()}
            info["converged"] = bool(steps.converged[m])
            info["TimeLimit.truncated"] = bool(truncated[m] and not steps.terminated[m])
            infos.append(info)
        done = np.flatnonzero(dones)
        if done.size:
            for m in done:
                infos[m]["terminal_observation"] = obs[m].copy()
            self._draw(done.tolist(), [None] * done.size)
            obs[done] = self._observe(self._x[done])
            for m, info in zip(done, self._reset_infos(self._x[done]), strict=True):
                self.reset_infos[m] = info
        return obs, steps.reward.copy(), dones, infos

    # --------------------------------------------------------------------------- snapshots

    #: what :meth:`snapshot` holds: every attribute that changes as the environments step
    _SNAPSHOT = ("_x", "_steps", "_rngs", "_seeds", "_options", "reset_infos")

    def snapshot(self) -> dict[str, Any]:
        """The environments' whole changing state (states, episode steps, generators, pending
        seeds), as plain picklable data: :meth:`restore` on an environment of the same task and
        ``n_envs`` continues exactly where this one is (a checkpoint of a training run)."""
        if self._actions is not None:
            raise RuntimeError("snapshot between steps, not between step_async and step_wait")
        return {"n_envs": self.num_envs, **{k: copy.deepcopy(getattr(self, k, None))
                                            for k in self._SNAPSHOT}}  # fmt: skip

    def restore(self, snapshot: Mapping[str, Any]) -> None:
        """Continue from a :meth:`snapshot` (of an environment of the same task and
        ``n_envs``; ``ValueError`` otherwise)."""
        if snapshot.get("n_envs") != self.num_envs:
            raise ValueError(
                f"snapshot is of {snapshot.get('n_envs')} environments; this has {self.num_envs}"
            )
        if np.shape(snapshot["_x"]) != self._x.shape:
            raise ValueError(f"snapshot's states have shape {np.shape(snapshot['_x'])}; this "
                             f"task's are {self._x.shape}")  # fmt: skip
        for key in self._SNAPSHOT:
            setattr(self, key, copy.deepcopy(snapshot[key]))
        self._actions = None

    def close(self) -> None:
        """Nothing to release."""

    def _indices(self, indices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int | np.integer):
            return [int(indices)]
        return [int(i) for i in indices]

    def get_attr(self, attr_name: str, indices: int | Iterable[int] | None = None) -> list[Any]:
        """An attribute every environment shares (``task``, ``dt``, ``max_episode_steps``,
        ``render_mode``, ...), once per index; ``AttributeError`` if there is none."""
        value = getattr(self, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        """Not supported: the environments share one task."""
        raise NotImplementedError(
            "DrakeAbsVecEnv's environments share one task: build a new DrakeAbsVecEnv instead "
            f"of setting {attr_name!r}"
        )

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs):
        """Not supported: there are no per-environment objects to call."""
        raise NotImplementedError(
            f"DrakeAbsVecEnv has no per-environment objects; cannot call {method_name!r}"
        )

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        """False for every index: no gymnasium wrappers."""
        return [False for _ in self._indices(indices)]
