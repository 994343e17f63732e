"""Baselines from well-kept libraries, trained on our plant: PPO and SAC of stable-baselines3 and
ARS of sb3-contrib on a locomotion task's environments
(:class:`~drake_abs.tasks.sb3_vec_env.DrakeAbsVecEnv`), with the RL Baselines3 Zoo's published
hyperparameters, and their final policies written in the published policy-file format
(:mod:`drake_abs.policy.policy_files`).

The environments: ``DrakeAbsVecEnv(locomotion_task(name, **env_options), n_envs,
max_episode_steps=1000)``, what ``n_envs`` independent
:class:`~drake_abs.tasks.gym_env.DrakeAbsEnv` give, bit for bit: gymnasium v5's reward,
observation, termination and reset noise (drawn at every reset), one action per control
period (gymnasium's, 8 ms Hopper, 50 ms HalfCheetah), episodes truncated after 1000 actions.
One **environment step** is one control period of one environment stepped, as our own
trainers count: the step that ends an episode counts, a reset does not.

**Several environments at once** (``n_envs`` > 1, PPO and SAC): the ``n_envs`` copies are
stepped in one batched call of our plant (a fraction of the cost per step), with the
hyperparameters adapted so that each update sees the same amount of data
(:func:`vectorised_hyperparameters`: PPO's rollout keeps its 512 steps, ``n_steps = 512 /
n_envs``; SAC keeps one gradient step per transition). Every environment's step counts.
sb3-contrib's ARS stays on one environment (it evaluates one candidate at a time).

**Resumable** (:class:`Sb3Trainer`): a run advances in chunks and is saved and continued to
the last bit, so that a sweep of long runs survives a stop; :func:`train_baseline` runs one
to its budget in one go.

Hyperparameters (:data:`ZOO_SETTINGS`): the RL Baselines3 Zoo's (github.com/DLR-RM/
rl-baselines3-zoo, ``hyperparams/*.yml``) for the MuJoCo task of the same body:

- PPO: ``ppo.yml`` (commit 208b6fd) ``Hopper-v4``, ``HalfCheetah-v4``, ``Walker2d-v4`` (tuned)
  and ``Ant-v4`` (its MuJoCo defaults: the library's own settings); observations and rewards
  normalised by ``VecNormalize`` (``normalize: true``) with the algorithm's gamma, as the zoo
  does;
- SAC: ``sac.yml`` (commit c94924e) ``Hopper-v3``, ``HalfCheetah-v3``, ``Walker2d-v3``,
  ``Ant-v3``: the library's defaults with ``learning_starts = 10000``; no normalisation;
- ARS: ``ars.yml`` (commit c6c209e) ``Hopper-v4``, ``HalfCheetah-v4``, ``Walker2d-v4``,
  ``Ant-v4``: a linear policy, observations normalised by ``VecNormalize(norm_obs=True,
  norm_reward=False)`` (running statistics of every visited observation).

Where this differs from the zoo: the environments are gymnasium v5's tasks on our plant, not
MuJoCo v3/v4; the budget is ``env_steps`` (not the zoo's ``n_timesteps``); ``VecNormalize``'s
``clip_obs`` is infinite (the zoo's default is 10) because the policy file has no clip of the
normalised observation: with it the exported policy is exactly the trained one (a finite
``clip_obs`` can be asked for, and then :func:`sb3_policy_file` refuses to export); one
environment unless ``n_envs`` says more, on the CPU, torch with one thread.
``algorithm_options`` override any setting.

The budget is each library's ``learn(total_timesteps=env_steps)``, which never wastes a step:
SAC stops after exactly ``env_steps`` environment steps (with ``n_envs``: the first multiple of
``n_envs`` at or past them); PPO after the whole rollout in which it reaches them (a multiple of
``n_steps * n_envs``, 512 in the zoo: at most 511 steps over); ARS after the
whole iteration in which it reaches them (an iteration is 2 ``n_delta`` episodes: at most
2 ``n_delta`` x 1000 steps over, e.g. 64000 for the HalfCheetah's 32 directions). The steps
actually taken are counted and returned. Our own trainers also round to whole iterations.
``max_seconds`` stops a run on the wall clock instead (for measuring speed): the rollout or
iteration in progress is then counted but not used.

Seeds: ``seed`` seeds the library (python, numpy, torch, the action space) and the
environment's first reset (later resets continue its generator); with ``n_envs``, environment
m's first reset is seeded with ``seed + m`` (stable-baselines3's convention). With torch on
one thread the runs are bit-reproducible: the same seed gives the same policy to the last bit
(``tests/tasks/test_sb3_baselines.py``).

Exported policies (:func:`sb3_policy_file`): PPO's deterministic action is its actor's MLP
(the hidden layers with their activation, then the linear action head), clipped; SAC's is
``tanh`` of its actor's mean (the file's ``output_activation = "tanh"``); ARS's linear policy
``W z`` (no bias), clipped. ``VecNormalize``'s observation statistics become ``obs_mean`` and
``obs_std = sqrt(var + epsilon)``.

Needs stable-baselines3, sb3-contrib and torch (``pip install 'drake-abs[baselines]'``),
imported when a function here is called, and gymnasium.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal

import gymnasium
import numpy as np

from drake_abs._validation import as_count
from drake_abs.policy.policy_files import PolicyFile
from drake_abs.tasks.locomotion import TASKS, locomotion_task

__all__ = [
    "ALGORITHMS",
    "METHOD_KEYS",
    "ZOO_SETTINGS",
    "BaselineRun",
    "Sb3State",
    "Sb3Trainer",
    "TrainingLog",
    "ZooSettings",
    "baseline_settings",
    "sb3_policy_file",
    "train_baseline",
    "vectorised_hyperparameters",
]

#: The algorithms :func:`train_baseline` runs.
ALGORITHMS = ("ppo", "sac", "ars")

#: The method key a baseline's policy file carries (``method`` metadata; the folder of
#: ``policies/<env id>/<method>/``), by algorithm.
METHOD_KEYS: Mapping[str, str] = MappingProxyType(
    {"ppo": "sb3_ppo", "sac": "sb3_sac", "ars": "sb3_ars"}
)


@dataclass(frozen=True)
class ZooSettings:
    """One algorithm's published settings for one task.

    Attributes:
        source: where they are published (zoo file, commit, environment id).
        hyperparameters: keyword arguments of the algorithm's constructor (``policy_kwargs``'
            ``activation_fn`` by name: ``"relu"``, ``"tanh"``, ...).
        normalize: ``VecNormalize`` keyword arguments, or None (no normalisation).
    """

    source: str
    hyperparameters: Mapping[str, Any]
    normalize: Mapping[str, Any] | None = None


def _ppo_tuned(source, **values) -> ZooSettings:
    policy_kwargs = dict(log_std_init=-2, ortho_init=False, activation_fn="relu",
                         net_arch=dict(pi=[256, 256], vf=[256, 256]))  # fmt: skip
    return ZooSettings(source, MappingProxyType({**values, "policy_kwargs": policy_kwargs}),
                       MappingProxyType({"norm_obs": True, "norm_reward": True}))  # fmt: skip


def _ars(source, **values) -> ZooSettings:
    return ZooSettings(source, MappingProxyType({"policy": "LinearPolicy", **values}),
                       MappingProxyType({"norm_obs": True, "norm_reward": False}))  # fmt: skip


_PPO = "rl-baselines3-zoo hyperparams/ppo.yml (commit 208b6fd), "
_SAC = "rl-baselines3-zoo hyperparams/sac.yml (commit c94924e), "
_ARS = "rl-baselines3-zoo hyperparams/ars.yml (commit c6c209e), "
_SAC_MUJOCO = MappingProxyType({"learning_starts": 10000})

#: The zoo's settings (module docstring) by algorithm and task name.
ZOO_SETTINGS: Mapping[str, Mapping[str, ZooSettings]] = MappingProxyType({
    "ppo": MappingProxyType({
        "hopper": _ppo_tuned(
            _PPO + "Hopper-v4", batch_size=32, n_steps=512, gamma=0.999,
            learning_rate=9.80828e-05, ent_coef=0.00229519, clip_range=0.2, n_epochs=5,
            gae_lambda=0.99, max_grad_norm=0.7, vf_coef=0.835671,
        ),
        "half_cheetah": _ppo_tuned(
            _PPO + "HalfCheetah-v4", batch_size=64, n_steps=512, gamma=0.98,
            learning_rate=2.0633e-05, ent_coef=0.000401762, clip_range=0.1, n_epochs=20,
            gae_lambda=0.92, max_grad_norm=0.8, vf_coef=0.58096,
        ),
        "walker2d": ZooSettings(
            _PPO + "Walker2d-v4",
            MappingProxyType(dict(
                batch_size=32, n_steps=512, gamma=0.99, learning_rate=5.05041e-05,
                ent_coef=0.000585045, clip_range=0.1, n_epochs=20, gae_lambda=0.95,
                max_grad_norm=1.0, vf_coef=0.871923,
            )),
            MappingProxyType({"norm_obs": True, "norm_reward": True}),
        ),
        "ant": ZooSettings(_PPO + "Ant-v4 (its MuJoCo defaults)", MappingProxyType({}),
                           MappingProxyType({"norm_obs": True, "norm_reward": True})),
    }),
    "sac": MappingProxyType({
        "hopper": ZooSettings(_SAC + "Hopper-v3", _SAC_MUJOCO),
        "half_cheetah": ZooSettings(_SAC + "HalfCheetah-v3", _SAC_MUJOCO),
        "walker2d": ZooSettings(_SAC + "Walker2d-v3", _SAC_MUJOCO),
        "ant": ZooSettings(_SAC + "Ant-v3", _SAC_MUJOCO),
    }),
    "ars": MappingProxyType({
        "hopper": _ars(_ARS + "Hopper-v4", learning_rate=0.01, delta_std=0.025, n_delta=8,
                       n_top=4, alive_bonus_offset=-1.0),
        "half_cheetah": _ars(_ARS + "HalfCheetah-v4", learning_rate=0.02, delta_std=0.03,
                             n_delta=32, n_top=4, alive_bonus_offset=0.0),
        "walker2d": _ars(_ARS + "Walker2d-v4", learning_rate=0.03, delta_std=0.025, n_delta=40,
                         n_top=30, alive_bonus_offset=-1.0),
        "ant": _ars(_ARS + "Ant-v4", learning_rate=0.015, delta_std=0.025, n_delta=60,
                    n_top=20, alive_bonus_offset=-1.0),
    }),
})  # fmt: skip

#: ``VecNormalize`` settings this module always uses unless ``algorithm_options["normalize"]``
#: says otherwise: no clip of the normalised observation (module docstring).
_NORMALIZE_DEFAULTS = MappingProxyType({"clip_obs": float("inf")})


def _check_names(task_name: str, algorithm: str) -> None:
    if algorithm not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {list(ALGORITHMS)}; got {algorithm!r}")
    if task_name not in ZOO_SETTINGS[algorithm]:
        raise ValueError(
            f"task_name must be one of {sorted(ZOO_SETTINGS[algorithm])}; got {task_name!r}"
        )


def baseline_settings(
    task_name: str,
    algorithm: Literal["ppo", "sac", "ars"],
    algorithm_options=None,
    n_envs: int = 1,
) -> dict:
    """The settings :func:`train_baseline` uses: ``{"source", "hyperparameters",
    "normalize"}`` (plain data), the zoo's (:data:`ZOO_SETTINGS`) with ``algorithm_options``
    laid over the hyperparameters (its key ``"normalize"``: ``VecNormalize`` keyword arguments
    laid over the zoo's, or False for none; ``"policy_kwargs"`` replaces the zoo's whole).

    These are settings for one environment. With ``n_envs`` > 1 the hyperparameters are
    adapted to ``n_envs`` environments stepped together (:func:`vectorised_hyperparameters`)."""
    _check_names(task_name, algorithm)
    n_envs = as_count(n_envs, "n_envs", minimum=1)
    options = dict(algorithm_options or {})
    zoo = ZOO_SETTINGS[algorithm][task_name]
    normalize = options.pop("normalize", None)
    if normalize is False:
        norm = None
    elif normalize is None:
        norm = None if zoo.normalize is None else {**_NORMALIZE_DEFAULTS, **zoo.normalize}
    elif isinstance(normalize, Mapping):
        norm = {**_NORMALIZE_DEFAULTS, **(zoo.normalize or {}), **normalize}
    else:
        raise ValueError(
            "algorithm_options['normalize'] must be a dict of VecNormalize keyword arguments or "
            f"False; got {normalize!r}"
        )
    hyper = {**zoo.hyperparameters, **options}
    if n_envs > 1:
        hyper = vectorised_hyperparameters(algorithm, hyper, n_envs)
    return {"source": zoo.source, "hyperparameters": hyper, "normalize": norm}


def _library_default(algorithm: str, name: str):
    """The default of a constructor argument of the library's algorithm class."""
    import inspect

    return inspect.signature(_algorithm_class(algorithm)).parameters[name].default


def vectorised_hyperparameters(
    algorithm: Literal["ppo", "sac", "ars"], hyperparameters: Mapping, n_envs: int
) -> dict:
    """One environment's hyperparameters adapted to ``n_envs`` environments stepped together,
    the usual way, so that the data per update stays the same:

    - PPO: ``n_steps`` (steps per environment per rollout) becomes ``n_steps / n_envs``: the
      rollout keeps its size ``n_steps * n_envs`` (the zoo's 512), and ``batch_size`` and
      ``n_epochs`` are unchanged. ``n_steps`` must be a multiple of ``n_envs``.
    - SAC: ``train_freq`` counts steps of all environments at once (each brings ``n_envs``
      transitions), so ``gradient_steps`` becomes ``gradient_steps * n_envs`` (-1 stays -1: it
      already means one per transition): the same gradient steps per transition as with one
      environment (the zoo's one per transition, then ``n_envs`` after each batched step).
      ``learning_starts`` and ``batch_size`` count transitions and are unchanged. An episodic
      ``train_freq`` is refused (stable-baselines3 allows it with one environment only).
    - ARS: refused. sb3-contrib's ARS evaluates each candidate policy in its own episodes on
      ``model.env`` one candidate after another (``evaluate_policy``, ``n_eval_episodes``
      episodes each); with ``n_envs`` environments the other environments step along and
      their steps are spent but not used (with ``n_eval_episodes = 1`` only the last
      environment's episode counts). Its ``async_eval`` runs candidates in worker processes
      (one environment each), not in one batch.

    The library's own default is taken for a missing key (needs the library then).

    Raises:
        ValueError: ARS, an ``n_steps`` that ``n_envs`` does not divide, an episodic
            ``train_freq``.
    """
    if algorithm not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {list(ALGORITHMS)}; got {algorithm!r}")
    n_envs = as_count(n_envs, "n_envs", minimum=1)
    hyper = dict(hyperparameters)
    if n_envs == 1:
        return hyper
    if algorithm == "ars":
        raise ValueError(
            f"n_envs must be 1 for ARS (got {n_envs}): sb3-contrib's ARS evaluates one candidate "
            "policy at a time on its environment, so more environments would step without use"
        )
    if algorithm == "ppo":
        n_steps = hyper["n_steps"] if "n_steps" in hyper else _library_default("ppo", "n_steps")
        if n_steps % n_envs:
            raise ValueError(
                f"n_envs must divide PPO's n_steps = {n_steps} (the rollout of one environment, "
                f"kept as n_steps / n_envs per environment); got n_envs = {n_envs}"
            )
        hyper["n_steps"] = n_steps // n_envs
        return hyper

    def value(name):
        return hyper[name] if name in hyper else _library_default("sac", name)

    train_freq = value("train_freq")
    if not isinstance(train_freq, int | np.integer) and not (
        isinstance(train_freq, tuple) and len(train_freq) == 2 and train_freq[1] == "step"
    ):
        raise ValueError(
            f"SAC's train_freq must count steps (an integer or (n, 'step')) with n_envs > 1; "
            f"got {train_freq!r}"
        )
    gradient_steps = value("gradient_steps")
    hyper["gradient_steps"] = gradient_steps if gradient_steps < 0 else gradient_steps * n_envs
    return hyper


# ------------------------------------------------------------------------------ the training log


class TrainingLog:
    """Counts the environment steps of a training run and records its episodes and the rows of
    its log, from the steps of ``n_envs`` environments (fed the task's own rewards: inside any
    normalisation).

    Whenever the step count reaches or passes a multiple of ``log_every`` (every ``log_every``
    steps with one environment; ``n_envs`` steps are counted at a time) and at
    :meth:`close_log`, a row: ``env_steps``, ``seconds`` (wall time since
    :meth:`start_clock`), ``episodes`` (training episodes that ended since the previous row,
    in the order they ended, environment by environment within a step), ``return_mean`` and
    ``length_mean`` over those (None when none ended), ``unconverged`` (steps so far whose
    contact solve did not converge; ``info["converged"]``). The clock runs only between
    :meth:`start_clock` and :meth:`stop_clock` (training, not scoring or checkpoints).
    """

    def __init__(self, log_every: int, n_envs: int = 1):
        self.log_every = as_count(log_every, "log_every", minimum=1)
        self.n_envs = as_count(n_envs, "n_envs", minimum=1)
        self.steps = 0
        self.unconverged = 0
        self.returns: list[float] = []
        self.lengths: list[int] = []
        self.rows: list[dict] = []
        self._return = np.zeros(self.n_envs)  # of the episodes in progress
        self._length = np.zeros(self.n_envs, dtype=int)
        self._since = 0  # episodes ended before the last row
        self._elapsed = 0.0  # seconds clocked before the current start
        self._start: float | None = None  # when the running clock started; None: stopped

    def start_clock(self) -> None:
        """Run the clock from now on, adding to the seconds clocked so far (nothing if it runs
        already)."""
        if self._start is None:
            self._start = time.perf_counter()

    def stop_clock(self) -> None:
        """Stop the clock (between a run's chunks of training: scoring, checkpoints)."""
        if self._start is not None:
            self._elapsed += time.perf_counter() - self._start
            self._start = None

    @property
    def seconds(self) -> float:
        """Seconds of wall time clocked while training (from :meth:`start_clock`, without the
        spans between a :meth:`stop_clock` and the next start)."""
        running = 0.0 if self._start is None else time.perf_counter() - self._start
        return self._elapsed + running

    def __getstate__(self) -> dict:
        """Picklable with the clock stopped (a checkpoint; the clocked seconds kept)."""
        state = self.__dict__.copy()
        if state["_start"] is not None:
            state["_elapsed"] += time.perf_counter() - state["_start"]
            state["_start"] = None
        return state

    def new_episodes(self) -> None:
        """Every environment starts a new episode (a reset): the ones in progress are dropped."""
        self._return[:] = 0.0
        self._length[:] = 0

    def record(self, rewards, dones, infos: Sequence[Mapping]) -> None:
        """One step of every environment: rewards (n_envs,), dones (n_envs,) (terminated or
        truncated), their ``info`` dicts."""
        rewards = np.asarray(rewards, dtype=float).reshape(-1)
        dones = np.asarray(dones, dtype=bool).reshape(-1)
        if not rewards.size == dones.size == len(infos) == self.n_envs:
            raise ValueError(
                f"rewards, dones and infos must have n_envs = {self.n_envs} entries; got "
                f"{rewards.size}, {dones.size}, {len(infos)}"
            )
        before = self.steps
        self.steps += self.n_envs
        self.unconverged += sum(not info.get("converged", True) for info in infos)
        self._return += rewards
        self._length += 1
        for m in np.flatnonzero(dones):
            self.returns.append(float(self._return[m]))
            self.lengths.append(int(self._length[m]))
            self._return[m], self._length[m] = 0.0, 0
        if self.steps // self.log_every > before // self.log_every:
            self._row()

    def _row(self) -> None:
        recent = slice(self._since, len(self.returns))
        returns, lengths = self.returns[recent], self.lengths[recent]
        self._since = len(self.returns)
        self.rows.append({
            "env_steps": self.steps,
            "seconds": self.seconds,
            "episodes": len(returns),
            "return_mean": float(np.mean(returns)) if returns else None,
            "length_mean": float(np.mean(lengths)) if lengths else None,
            "unconverged": self.unconverged,
        })  # fmt: skip

    def close_log(self) -> None:
        """A last row, unless the last step already wrote one."""
        if not self.rows or self.rows[-1]["env_steps"] != self.steps:
            self._row()


def _vec_step_log(venv, log: TrainingLog):
    """``venv`` (a stable-baselines3 ``VecEnv`` of ``log.n_envs`` environments) with every
    step recorded in ``log`` (wrap the raw environments, inside any normalisation)."""
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class VecStepLog(VecEnvWrapper):
        def reset(self):
            log.new_episodes()
            return self.venv.reset()

        def step_wait(self):
            obs, rewards, dones, infos = self.venv.step_wait()
            log.record(rewards, dones, infos)
            return obs, rewards, dones, infos

    if venv.num_envs != log.n_envs:
        raise ValueError(f"venv has {venv.num_envs} environments, log {log.n_envs}")
    return VecStepLog(venv)


# ---------------------------------------------------------------------------------- training


@dataclass(eq=False)
class BaselineRun:
    """One training run of :func:`train_baseline`.

    Attributes:
        task_name, algorithm, seed: what ran.
        env_id: the gymnasium id the task reproduces (``"Hopper-v5"``).
        env_steps: environment steps taken (control periods stepped).
        seconds: wall time of the training (s), without building the task.
        rows: the training log (:class:`TrainingLog`).
        unconverged: steps whose contact solve did not converge.
        settings: :func:`baseline_settings` of the run (its hyperparameters adapted to
            ``n_envs``).
        model: the trained stable-baselines3 / sb3-contrib model.
        vec_normalize: its ``VecNormalize`` (None without normalisation).
        stopped_early: ``max_seconds`` ran out before the budget was spent.
        n_envs: environments stepped together.
    """

    task_name: str
    algorithm: str
    seed: int
    env_id: str | None
    env_steps: int
    seconds: float
    rows: list[dict]
    unconverged: int
    settings: dict
    model: Any = field(repr=False)
    vec_normalize: Any = field(repr=False, default=None)
    stopped_early: bool = False
    n_envs: int = 1

    def policy_file(self, **metadata) -> PolicyFile:
        """The final policy as a policy file (:func:`sb3_policy_file`), with metadata
        ``env_id``, ``method`` (:data:`METHOD_KEYS`), ``seed``, ``training_steps``, the
        package versions and, with ``n_envs`` > 1, ``n_envs``; ``metadata`` adds or replaces
        keys."""
        meta = {"env_id": self.env_id, "method": METHOD_KEYS[self.algorithm],
                "seed": self.seed, "training_steps": self.env_steps}  # fmt: skip
        if self.n_envs > 1:
            meta["n_envs"] = self.n_envs
        meta = {k: v for k, v in meta.items() if v is not None}
        return sb3_policy_file(self.model, self.vec_normalize, **(meta | metadata))


def _torch_policy_kwargs(policy_kwargs: Mapping | None) -> dict | None:
    """``policy_kwargs`` with ``activation_fn`` given by name turned into torch's class."""
    if policy_kwargs is None:
        return None
    from torch import nn

    out = dict(policy_kwargs)
    names = {"relu": nn.ReLU, "tanh": nn.Tanh, "elu": nn.ELU, "sigmoid": nn.Sigmoid}
    act = out.get("activation_fn")
    if isinstance(act, str):
        if act not in names:
            raise ValueError(f"policy_kwargs['activation_fn'] must be one of {sorted(names)} or a "
                             f"torch module class; got {act!r}")  # fmt: skip
        out["activation_fn"] = names[act]
    return out


class _OutOfTime(Exception):
    """Raised by the callback to stop ARS on the wall clock (``max_seconds``)."""


def _algorithm_class(algorithm: str):
    if algorithm == "ars":
        from sb3_contrib import ARS

        return ARS
    from stable_baselines3 import PPO, SAC

    return {"ppo": PPO, "sac": SAC}[algorithm]


@dataclass
class Sb3State:
    """Where an :class:`Sb3Trainer` is: ``iteration`` (calls of :meth:`Sb3Trainer.iterate`),
    ``env_steps`` (environment steps taken, every environment's), ``seconds`` (wall time spent
    training), ``rows`` (the training log, :class:`TrainingLog`)."""

    iteration: int = 0
    env_steps: int = 0
    seconds: float = 0.0
    rows: list[dict] = field(default_factory=list)


class Sb3Trainer:
    """A stable-baselines3 PPO or SAC, or sb3-contrib ARS, training on a task of our plant in
    chunks (:meth:`iterate`), saved and continued bit for bit (:meth:`save`, :meth:`load`):
    what :func:`train_baseline` runs to a budget, and what a resumable experiment checkpoints.

    Args:
        task_name: as :func:`train_baseline` (also ``algorithm``, ``seed``, ``env_options``,
            ``algorithm_options``, ``log_every``, ``max_episode_steps``, ``n_envs``).
        chunk: environment steps of one :meth:`iterate` (at least; the library's
            ``learn(chunk)``: PPO rounds up to whole rollouts of ``n_steps * n_envs``, ARS to
            whole iterations, SAC to a multiple of ``n_envs``). None: one rollout (PPO), one
            iteration (ARS), 1000 steps per environment (SAC).

    The environments are one :class:`~drake_abs.tasks.sb3_vec_env.DrakeAbsVecEnv` of
    ``n_envs`` (one batched step of our plant), inside ``VecNormalize`` where the settings
    normalise. A run trained in chunks takes the steps one ``learn(total)`` takes: the library
    keeps its step count, its last observation and its buffers between calls, and the
    hyperparameters must be constants (a schedule, a callable, is refused: it would see each
    chunk as a whole run).

    A checkpoint (:meth:`save`) holds the model (the library's own ``save``: weights,
    optimisers, step counts, the last observation), SAC's replay buffer, the normalisation's
    statistics and running returns, the environments' states and generators
    (:meth:`~drake_abs.tasks.sb3_vec_env.DrakeAbsVecEnv.snapshot`), the log, and the random
    generators the libraries draw from (python's, numpy's global, torch's, the action
    space's): a run saved and loaded between two chunks gives the policy of a run never
    stopped, to the last bit (``tests/tasks/test_sb3_baselines.py``).
    """

    #: the checkpoint format (:mod:`drake_abs.policy.checkpoints`)
    FORMAT = "drake-abs sb3 checkpoint"
    FORMAT_VERSION = 1

    def __init__(
        self,
        task_name: Literal["hopper", "half_cheetah", "walker2d", "ant"],
        algorithm: Literal["ppo", "sac", "ars"],
        seed: int,
        *,
        env_options: Mapping | None = None,
        algorithm_options: Mapping | None = None,
        log_every: int = 10_000,
        max_episode_steps: int = 1000,
        n_envs: int = 1,
        chunk: int | None = None,
    ):
        _check_names(task_name, algorithm)
        if task_name not in TASKS:
            raise ValueError(f"task_name must be one of {sorted(TASKS)}; got {task_name!r}")
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise ValueError(f"seed must be a whole number >= 0; got {seed!r}")
        self.task_name, self.algorithm, self.seed = task_name, algorithm, int(seed)
        self.n_envs = as_count(n_envs, "n_envs", minimum=1)
        self.settings = baseline_settings(task_name, algorithm, algorithm_options, self.n_envs)
        _check_constant(self.settings["hyperparameters"])
        if chunk is None:
            chunk = 1000 * self.n_envs if algorithm == "sac" else 1
        self.chunk = as_count(chunk, "chunk", minimum=1)
        self.max_episode_steps = max_episode_steps
        self.log = TrainingLog(log_every, self.n_envs)
        self.task = locomotion_task(task_name, **dict(env_options or {}))
        self.model = self._new_model()
        self.state = Sb3State()

    # ------------------------------------------------------------------------- building

    def _environments(self, vec_normalize=None):
        """``(raw, env, vec_normalize)``: the task's ``DrakeAbsVecEnv``, what the model steps
        (the raw one, logged, inside a ``VecNormalize`` where the settings normalise; a given
        ``vec_normalize``, unpickled, is wrapped around it instead of a new one)."""
        from stable_baselines3.common.vec_env import VecNormalize

        from drake_abs.tasks.sb3_vec_env import DrakeAbsVecEnv

        raw = DrakeAbsVecEnv(self.task, self.n_envs, max_episode_steps=self.max_episode_steps)
        env = _vec_step_log(raw, self.log)
        if vec_normalize is not None:
            returns = vec_normalize.__dict__.pop("_saved_returns", None)
            vec_normalize.set_venv(env)
            if returns is not None:
                vec_normalize.returns = returns
            return raw, vec_normalize, vec_normalize
        if self.settings["normalize"] is None:
            return raw, env, None
        kwargs = dict(self.settings["normalize"])
        hyper = self.settings["hyperparameters"]
        if self.algorithm != "ars" and "gamma" in hyper:
            kwargs.setdefault("gamma", hyper["gamma"])  # as the zoo does
        vec_normalize = VecNormalize(env, **kwargs)
        return raw, vec_normalize, vec_normalize

    def _new_model(self):
        self.raw_env, env, self.vec_normalize = self._environments()
        hyper = dict(self.settings["hyperparameters"])
        policy = hyper.pop("policy", "MlpPolicy")
        kwargs = _torch_policy_kwargs(hyper.pop("policy_kwargs", None))
        if kwargs is not None:
            hyper["policy_kwargs"] = kwargs
        with _one_torch_thread():
            return _algorithm_class(self.algorithm)(
                policy, env, seed=self.seed, device="cpu", verbose=0, **hyper
            )

    # ------------------------------------------------------------------------- training

    def iterate(self, steps: int | None = None, *, deadline: float | None = None) -> dict:
        """Train ``steps`` environment steps more (default ``chunk``; rounded up as ``chunk``
        is), or until ``time.perf_counter()`` passes ``deadline`` (then the rollout or
        iteration in progress is counted but not used, and the run cannot be continued
        exactly: a budget in seconds is for measuring speed). Returns the last log row.

        Raises:
            FloatingPointError: our plant's state became non-finite (the step count in the
                notes); the run stops there.
        """
        steps = self.chunk if steps is None else as_count(steps, "steps", minimum=1)
        stopped = []

        def in_time(_locals, _globals) -> bool:
            if deadline is None or time.perf_counter() < deadline:
                return True
            stopped.append(self.log.steps)
            if self.algorithm == "ars":  # sb3-contrib's ARS ignores a callback's False
                raise _OutOfTime
            return False  # PPO and SAC stop here

        self.log.start_clock()
        try:
            with _one_torch_thread():
                self.model.learn(total_timesteps=steps, callback=in_time,
                                 reset_num_timesteps=False)  # fmt: skip
        except _OutOfTime:
            pass
        except FloatingPointError as err:
            err.add_note(f"Sb3Trainer: after {self.log.steps} environment steps of "
                         f"{self.algorithm} on {self.task_name}, seed {self.seed}")  # fmt: skip
            raise
        finally:
            self.log.stop_clock()
        self.stopped_early = bool(stopped)
        self.log.close_log()
        self.state.iteration += 1
        self.state.env_steps = self.log.steps
        self.state.seconds = self.log.seconds
        self.state.rows = self.log.rows
        return self.log.rows[-1]

    @property
    def recent_return(self) -> float | None:
        """Mean return (the task's reward) of the episodes that ended in the last logged span
        with any (None before the first)."""
        for row in reversed(self.log.rows):
            if row["return_mean"] is not None:
                return row["return_mean"]
        return None

    def policy_file(self, **metadata) -> PolicyFile:
        """The current policy as a policy file (:func:`sb3_policy_file`), with metadata
        ``env_id``, ``method`` (:data:`METHOD_KEYS`), ``seed``, ``training_steps`` and, with
        ``n_envs`` > 1, ``n_envs``; ``metadata`` adds or replaces keys."""
        meta = {"env_id": self.task.env_id, "method": METHOD_KEYS[self.algorithm],
                "seed": self.seed, "training_steps": self.state.env_steps}  # fmt: skip
        if self.n_envs > 1:
            meta["n_envs"] = self.n_envs
        meta = {k: v for k, v in meta.items() if v is not None}
        return sb3_policy_file(self.model, self.vec_normalize, **(meta | metadata))

    # ------------------------------------------------------------------------- checkpoints

    def save(self, path: str | Path) -> Path:
        """Write the whole training state to ``path`` (class docstring)."""
        import io
        import pickle
        import random

        import torch

        from drake_abs.policy.checkpoints import write_checkpoint

        if self.raw_env._actions is not None:
            raise RuntimeError("save between iterations")
        model = io.BytesIO()
        self.model.save(model)
        buffer = None
        if getattr(self.model, "replay_buffer", None) is not None:
            buffer = pickle.dumps(self.model.replay_buffer, protocol=pickle.HIGHEST_PROTOCOL)
        vec_normalize = None
        if self.vec_normalize is not None:
            vec_normalize = pickle.dumps(self.vec_normalize, protocol=pickle.HIGHEST_PROTOCOL)
        payload = {
            "identity": self._identity(),
            "model": model.getvalue(),
            "replay_buffer": buffer,
            "vec_normalize": vec_normalize,
            "returns": None if self.vec_normalize is None else self.vec_normalize.returns.copy(),
            "environments": self.raw_env.snapshot(),
            "log": pickle.dumps(self.log, protocol=pickle.HIGHEST_PROTOCOL),
            "state": self.state,
            "rng": {
                "python": random.getstate(), "numpy": np.random.get_state(),  # noqa: NPY002 (what sb3 draws from)
                "torch": torch.get_rng_state(),
                "action_space": self.model.action_space.np_random.bit_generator.state,
            },
        }  # fmt: skip
        return write_checkpoint(path, payload, kind=self.FORMAT, version=self.FORMAT_VERSION)

    def _identity(self) -> dict:
        return {"task_name": self.task_name, "algorithm": self.algorithm, "seed": self.seed,
                "n_envs": self.n_envs, "settings": self.settings}  # fmt: skip

    def load(self, path: str | Path) -> Sb3Trainer:
        """Continue from the checkpoint at ``path``, written by a trainer built with the same
        task, algorithm, seed, settings and ``n_envs`` (``ValueError`` otherwise; the task's
        ``env_options`` are the caller's to match). Returns this trainer."""
        import io
        import pickle
        import random

        import torch

        from drake_abs.policy.checkpoints import read_checkpoint

        data = read_checkpoint(path, kind=self.FORMAT, version=self.FORMAT_VERSION)
        if data["identity"] != self._identity():
            raise ValueError(
                f"path holds a run of {data['identity']}; this trainer is {self._identity()}"
            )
        self.log = pickle.loads(data["log"])  # noqa: S301 (the library's own checkpoint)
        vec_normalize = None
        if data["vec_normalize"] is not None:
            vec_normalize = pickle.loads(data["vec_normalize"])  # noqa: S301
            vec_normalize._saved_returns = data["returns"]
        self.raw_env, env, self.vec_normalize = self._environments(vec_normalize)
        with _one_torch_thread():
            self.model = _algorithm_class(self.algorithm).load(
                io.BytesIO(data["model"]), env=env, device="cpu", force_reset=False
            )
        if data["replay_buffer"] is not None:
            self.model.replay_buffer = pickle.loads(data["replay_buffer"])  # noqa: S301
        self.raw_env.restore(data["environments"])  # after the load reseeded it
        rng = data["rng"]
        random.setstate(rng["python"])
        np.random.set_state(rng["numpy"])  # noqa: NPY002 (what sb3 draws from)
        torch.set_rng_state(rng["torch"])
        self.model.action_space.np_random.bit_generator.state = rng["action_space"]
        self.state = data["state"]
        return self


def _check_constant(hyperparameters: Mapping) -> None:
    """A run trained in chunks needs constant hyperparameters (a schedule would restart)."""
    for name, value in hyperparameters.items():
        if callable(value):
            raise ValueError(
                f"algorithm_options[{name!r}] must be a constant, not a schedule: a run trained "
                "in chunks would see each chunk as a whole run"
            )


class _one_torch_thread:
    """Torch on one thread inside the block (the runs' reproducibility), restored after."""

    def __enter__(self):
        import torch

        self._threads = torch.get_num_threads()
        torch.set_num_threads(1)

    def __exit__(self, *exc):
        import torch

        torch.set_num_threads(self._threads)
        return False


def train_baseline(
    task_name: Literal["hopper", "half_cheetah", "walker2d", "ant"],
    algorithm: Literal["ppo", "sac", "ars"],
    seed: int,
    env_steps: int,
    *,
    env_options: Mapping | None = None,
    algorithm_options: Mapping | None = None,
    log_every: int = 10_000,
    max_episode_steps: int = 1000,
    max_seconds: float | None = None,
    n_envs: int = 1,
) -> BaselineRun:
    """Train ``algorithm`` (stable-baselines3's PPO or SAC, sb3-contrib's ARS) on the task
    ``task_name`` on our plant for ``env_steps`` environment steps (module docstring), in
    one go (an :class:`Sb3Trainer` run to the budget).

    Args:
        task_name: a task of :data:`~drake_abs.tasks.locomotion.TASKS`.
        algorithm: ``"ppo"``, ``"sac"`` or ``"ars"``.
        seed: seeds the library and the environment's resets (a whole number >= 0).
        env_steps: the budget, in environment steps (control periods).
        env_options: keyword arguments of
            :func:`~drake_abs.tasks.locomotion.locomotion_task` (``smoothing``,
            ``control_period``, ``substeps``, ``reward_options``, ...).
        algorithm_options: replace the zoo's settings (:func:`baseline_settings`), e.g.
            ``{"learning_starts": 100}`` or ``{"normalize": {"clip_obs": 10.0}}``.
        log_every: environment steps between the rows of the training log.
        max_episode_steps: steps after which an episode is truncated (gymnasium's 1000).
        max_seconds: stop after this much wall time (s) if the budget is not spent by then
            (``stopped_early`` in the result); None: no limit.
        n_envs: environments stepped together in one
            :class:`~drake_abs.tasks.sb3_vec_env.DrakeAbsVecEnv` (one batched step of our
            plant for all of them); more than 1 adapts the hyperparameters
            (:func:`vectorised_hyperparameters`; PPO and SAC only).

    Returns:
        A :class:`BaselineRun`; ``.policy_file()`` is the final policy as a policy file.

    Raises:
        ValueError: a bad argument, named.
        FloatingPointError: our plant's state became non-finite (the step count is in the
            message's notes); training stops there.
    """
    env_steps = as_count(env_steps, "env_steps", minimum=1)
    if max_seconds is not None and not (
        isinstance(max_seconds, int | float) and np.isfinite(max_seconds) and max_seconds > 0
    ):
        raise ValueError(f"max_seconds must be a number > 0 (s) or None; got {max_seconds!r}")
    trainer = Sb3Trainer(
        task_name, algorithm, seed, env_options=env_options,
        algorithm_options=algorithm_options, log_every=log_every,
        max_episode_steps=max_episode_steps, n_envs=n_envs, chunk=env_steps,
    )  # fmt: skip
    deadline = None if max_seconds is None else time.perf_counter() + max_seconds
    trainer.iterate(env_steps, deadline=deadline)
    return BaselineRun(
        task_name=task_name, algorithm=algorithm, seed=trainer.seed, env_id=trainer.task.env_id,
        env_steps=trainer.state.env_steps, seconds=trainer.state.seconds,
        rows=trainer.state.rows, unconverged=trainer.log.unconverged,
        settings=trainer.settings, model=trainer.model, vec_normalize=trainer.vec_normalize,
        stopped_early=trainer.stopped_early, n_envs=trainer.n_envs,
    )  # fmt: skip


# ------------------------------------------------------------------------------------ export


def _sequential(modules) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[str | None]]:
    """The (W, b) of each Linear of a chain of torch modules and the activation after each
    (None: none); ``ValueError`` for a module that is neither."""
    from torch import nn

    names = {nn.Tanh: "tanh", nn.ReLU: "relu", nn.Sigmoid: "sigmoid"}
    layers, after = [], []
    for module in modules:
        if isinstance(module, nn.Linear):
            W = module.weight.detach().cpu().double().numpy().copy()
            b = (np.zeros(W.shape[0]) if module.bias is None
                 else module.bias.detach().cpu().double().numpy().copy())  # fmt: skip
            layers.append((W, b))
            after.append(None)
            continue
        if isinstance(module, nn.ELU) and module.alpha == 1.0:
            name = "elu"
        elif isinstance(module, nn.Identity | nn.Flatten):
            continue
        else:
            name = names.get(type(module))
        if name is None or not layers or after[-1] is not None:
            raise ValueError(
                f"cannot write {module!r} in a policy file: a chain of Linear layers, each with "
                "at most one activation (tanh, relu, elu with alpha 1, sigmoid), is expected"
            )
        after[-1] = name
    if not layers:
        raise ValueError("the policy has no Linear layer to write")
    return layers, after


def _check_identity_features(policy) -> None:
    from stable_baselines3.common.torch_layers import FlattenExtractor

    extractor = getattr(policy, "features_extractor", None)
    if extractor is not None and not isinstance(extractor, FlattenExtractor):
        raise ValueError(f"the policy's features extractor must be FlattenExtractor (the "
                         f"observation itself); got {type(extractor).__name__}")  # fmt: skip


def _actor_chain(model) -> tuple[list, str | None]:
    """The torch modules of the deterministic actor, and an activation the library applies
    after them (SAC's tanh)."""
    from stable_baselines3 import PPO, SAC

    policy = model.policy
    _check_identity_features(policy)
    if isinstance(model, PPO):
        if getattr(policy, "use_sde", False) or policy.squash_output:
            raise ValueError("PPO with gSDE or a squashed output is not exported (the zoo's "
                             "MuJoCo settings use neither)")  # fmt: skip
        return [*policy.mlp_extractor.policy_net, policy.action_net], None
    if isinstance(model, SAC):
        actor = policy.actor
        _check_identity_features(actor)
        if actor.use_sde:
            raise ValueError("SAC with gSDE is not exported (the zoo's MuJoCo settings do "
                             "not use it)")  # fmt: skip
        return [*actor.latent_pi, actor.mu], "tanh"  # the squashed Gaussian's mode: tanh(mean)
    from sb3_contrib import ARS

    if isinstance(model, ARS):
        return list(policy.action_net), None
    raise ValueError(
        f"model must be a stable-baselines3 PPO or SAC or an sb3-contrib ARS; got "
        f"{type(model).__name__}"
    )


def _versions(contrib: bool) -> dict[str, str]:
    """The versions of stable-baselines3 (and sb3-contrib) and drake-abs, as metadata."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    dists = [("sb3_version", "stable-baselines3"), ("drake_abs_version", "drake-abs")]
    if contrib:
        dists.insert(1, ("sb3_contrib_version", "sb3-contrib"))
    for key, dist in dists:
        try:
            out[key] = version(dist)
        except PackageNotFoundError:
            out[key] = "unknown"
    return out


def sb3_policy_file(model, vec_normalize=None, **metadata) -> PolicyFile:
    """A trained model's deterministic policy as a policy file (module docstring): its action
    of a raw observation o is ``model.predict(vec_normalize.normalize_obs(o),
    deterministic=True)`` (without ``vec_normalize``: of o itself), clipped to [-1, 1].

    Args:
        model: a stable-baselines3 PPO or SAC, or an sb3-contrib ARS, on a Box observation and
            a Box action space [-1, 1].
        vec_normalize: its ``VecNormalize`` (observation statistics only; a finite
            ``clip_obs`` is refused: the format cannot clip the normalised observation).
        metadata: the file's metadata keys; ``policy_kind`` (the library's policy class) and
            the library and drake-abs versions are added.

    Raises:
        ValueError: an architecture the format cannot express, an action space other than
            [-1, 1], a finite ``clip_obs``.
    """
    space = model.action_space
    if not isinstance(space, gymnasium.spaces.Box) or not (
        np.all(space.low == -1.0) and np.all(space.high == 1.0)
    ):
        raise ValueError(f"the model's action space must be Box(-1, 1) (the locomotion tasks'); "
                         f"got {space}")  # fmt: skip
    chain, squash = _actor_chain(model)
    layers, after = _sequential(chain)
    hidden, output = after[:-1], after[-1]
    if squash is not None:
        if output is not None:
            raise ValueError(f"the actor's last layer already has an activation ({output})")
        output = squash
    if len(set(hidden)) > 1 or None in hidden:
        raise ValueError(f"the format has one activation for every hidden layer; the actor's "
                         f"hidden layers have {hidden}")  # fmt: skip
    mean = std = None
    if vec_normalize is not None and vec_normalize.norm_obs:
        if np.isfinite(vec_normalize.clip_obs):
            raise ValueError(
                f"vec_normalize clips the normalised observation at +-{vec_normalize.clip_obs}, "
                "which a policy file cannot express: train with clip_obs = inf (this module's "
                "default) to export the policy exactly"
            )
        rms = vec_normalize.obs_rms
        mean = np.asarray(rms.mean, dtype=float).copy()
        std = np.sqrt(np.asarray(rms.var, dtype=float) + vec_normalize.epsilon)
    contrib = type(model).__module__.startswith("sb3_contrib")
    meta = {"policy_kind": type(model.policy).__name__, **_versions(contrib), **metadata}
    if len(layers) == 1:
        return PolicyFile.linear(*layers[0], mean, std, output_activation=output, **meta)
    return PolicyFile.mlp(layers, hidden[0], mean, std, output_activation=output, **meta)
