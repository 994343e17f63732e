"""Training runs of locomotion policies on our plant, one interface for every trainer: a run is
built from a task name, a method name (:mod:`drake_abs.policy.methods`) and a seed, advanced one
iteration at a time to a budget of environment steps, checkpointed and resumed, and written out
as a policy file anyone can load (:mod:`drake_abs.policy.policy_files`).

A run (:class:`TrainingRun`) has

- ``env_steps``: the control periods stepped so far by the trainer's environments, counted as the
  trainer counts them (steps after an episode ended count nothing);
- ``seconds``: wall time spent training (not scoring, not checkpointing);
- ``iterate()``: one iteration, returning its log row (``rows``: all of them);
- ``recent_return``: the mean return (gymnasium's reward) of the episodes completed lately;
- ``task``: the task it trains on;
- ``save(path)``: the whole training state; ``load(path)`` continues from it (what
  :func:`resume_run` does);
- ``policy_file(**metadata)``: the current policy as a
  :class:`~drake_abs.policy.policy_files.PolicyFile` of gymnasium's observation.

The trainers, by the registry's ``estimator``:

- ``"shac"``, ``"fopg_episode"``: :class:`~drake_abs.policy.shac.ShacTrainer` through the
  method's smoothing of the plant (``abs``: the contact-aware mu of ``contact_aware``; ``exact``:
  hard contact). The task's reward for training has the smooth survive term
  (:class:`~drake_abs.tasks.locomotion.SmoothHealthy`) where the task has a healthy range and
  ``smooth_survive`` is set; the trainer also logs the task's own (gymnasium's) reward.
- ``"ars"``: :class:`~drake_abs.policy.ars_trainer.ArsTrainer`, ARS V2-t as its authors run it
  on gymnasium's tasks (their published settings and survival shift for the task,
  :meth:`~drake_abs.policy.ars_trainer.ArsConfig.published`, unless ``settings.ars`` gives
  others), on the exact plant (a derivative-free method needs no smoothing) with gymnasium's
  reward.
- ``"sb3"``: :class:`~drake_abs.tasks.sb3_baselines.Sb3Trainer`, the library baselines
  (stable-baselines3's PPO and SAC, sb3-contrib's ARS, with the RL Zoo's settings) on the exact
  plant with gymnasium's reward, ``sb3_envs`` environments stepped together (ARS: one), in
  chunks of ``sb3_chunk`` environment steps. Needs the ``baselines`` extra.

:class:`RunSettings` holds what defines a run besides its task, method and seed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Protocol, runtime_checkable

from drake_abs.policy.ars_trainer import ArsConfig, ArsTrainer
from drake_abs.policy.methods import method as registry_method
from drake_abs.policy.policy_files import PolicyFile
from drake_abs.policy.shac import ShacConfig, ShacTrainer
from drake_abs.tasks.locomotion import (
    CONTACT_LAWS,
    TASKS,
    GymLocomotionReward,
    HealthyRanges,
    LocomotionTask,
    SmoothHealthy,
    locomotion_task,
)
from drake_abs.tasks.published_policies import task_policy_file

if TYPE_CHECKING:  # the baselines extra: imported when a run is built
    from drake_abs.tasks.sb3_baselines import Sb3Trainer

__all__ = [
    "ArsRun",
    "RunSettings",
    "Sb3Run",
    "ShacRun",
    "TrainerRun",
    "TrainingRun",
    "resume_run",
    "start_run",
    "training_task",
]

#: the registry's trainers this module runs (see the module docstring)
SHAC_TRAINERS = ("shac", "fopg_episode")


@runtime_checkable
class TrainingRun(Protocol):
    """One training run (module docstring)."""

    @property
    def env_steps(self) -> int: ...

    @property
    def seconds(self) -> float: ...

    @property
    def rows(self) -> list[dict]: ...

    @property
    def recent_return(self) -> float | None: ...

    def iterate(self) -> dict: ...

    def save(self, path: str | Path) -> None: ...

    def load(self, path: str | Path) -> TrainingRun: ...

    def policy_file(self, **metadata) -> PolicyFile: ...


@dataclass(frozen=True)
class RunSettings:
    """What defines a training run besides its task, method and seed.

    Attributes:
        policy: ``"linear"`` or ``"mlp"`` (tanh hidden layers ``shac.hidden``).
        contact_aware: (mu_max, length in m) of the adaptive barrier smoothing of ``abs``
            methods; a larger mu_max is more smoothing. Default mu_max 1e-4: at gymnasium's 8 ms
            Hopper step, 1e-2 (the papers' value at their settings) holds the feet off the
            ground enough that the zero-action Hopper falls within 12 steps (41 to 138 with
            exact contact, 129 to 148 in MuJoCo; 36 to 66 at 1e-4).
        smooth_survive: train on the smooth survive term where the task has a healthy range
            (the score stays gymnasium's reward).
        survive_width: (height width m, pitch width rad) of that term; larger is smoother.
        shac: the SHAC trainer's settings (the method's own choices, whole-episode windows for
            ``fopg_episode``, replace ``window``, ``critic`` and ``gamma``).
        control_period: seconds per action; None: gymnasium's.
        substeps: plant steps per action; None: the task's default.
        contact: the contact law every method trains on: ``"hard"`` (complementarity) or
            ``"mujoco"`` (MuJoCo's soft contact: the ``contact`` option of
            :func:`~drake_abs.tasks.locomotion.locomotion_task`); the score in MuJoCo and on
            our exact plant is the same either way.
        ars: ARS's settings; None: the published ones of the task.
        sb3_envs: environments the library baselines PPO and SAC step together (their
            hyperparameters adapted to keep the data per update,
            :func:`~drake_abs.tasks.sb3_baselines.vectorised_hyperparameters`); sb3-contrib's
            ARS always steps one.
        sb3_chunk: environment steps of one iteration of a library baseline (rounded up to
            whole rollouts or iterations).
    """

    policy: Literal["linear", "mlp"] = "linear"
    contact_aware: tuple[float, float] = (1e-4, 0.05)
    smooth_survive: bool = True
    survive_width: tuple[float, float] = (0.05, 0.05)
    shac: ShacConfig = field(default_factory=ShacConfig)
    control_period: float | None = None
    substeps: int | None = None
    contact: Literal["hard", "mujoco"] = "hard"
    ars: ArsConfig | None = None
    sb3_envs: int = 16
    sb3_chunk: int = 10_000

    def __post_init__(self):
        if self.policy not in ("linear", "mlp"):
            raise ValueError(f"policy must be 'linear' or 'mlp'; got {self.policy!r}")
        if self.ars is not None and not isinstance(self.ars, ArsConfig):
            raise ValueError(f"ars must be an ArsConfig or None; got {type(self.ars).__name__}")
        if not isinstance(self.shac, ShacConfig):
            raise ValueError(f"shac must be a ShacConfig; got {type(self.shac).__name__}")
        for name in ("sb3_envs", "sb3_chunk"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a whole number >= 1; got {value!r}")
        if self.contact not in CONTACT_LAWS:
            raise ValueError(f"contact must be one of {list(CONTACT_LAWS)}; got {self.contact!r}")
        if len(self.contact_aware) != 2 or len(self.survive_width) != 2:
            raise ValueError(
                "contact_aware must be (mu_max, length) and survive_width (height, pitch); got "
                f"{self.contact_aware!r}, {self.survive_width!r}"
            )

    def for_method(self, method: str) -> dict:
        """The settings a run of ``method`` reads, as a dict (what defines its numbers beside the
        task, method and seed): ARS reads ``ars`` and the control period; a library baseline
        ``sb3_envs``, ``sb3_chunk`` and the control period; the SHAC trainer everything
        else."""
        m = registry_method(method)
        values = asdict(self)
        plant = {"control_period": self.control_period, "substeps": self.substeps,
                 "contact": self.contact}  # fmt: skip
        if m.estimator == "ars":
            return plant | {"ars": values["ars"]}
        if m.estimator == "sb3":
            return plant | {"sb3_envs": self.sb3_envs, "sb3_chunk": self.sb3_chunk}
        return {key: v for key, v in values.items()
                if key not in ("ars", "sb3_envs", "sb3_chunk")}  # fmt: skip


def training_task(task_name: str, method: str, settings: RunSettings) -> LocomotionTask:
    """The task a method trains on: the method's smoothing of the plant, and the smooth
    survive term where the task has a healthy range and ``settings.smooth_survive``."""
    if task_name not in TASKS:
        raise ValueError(f"task_name must be one of {sorted(TASKS)}; got {task_name!r}")
    m = registry_method(method)
    smoothing = m.make_smoothing(contact_aware=tuple(settings.contact_aware))
    reward_options = None
    healthy = _healthy_ranges(task_name)
    if settings.smooth_survive and healthy is not None:
        z_width, angle_width = settings.survive_width
        reward_options = {
            "smooth_survive": SmoothHealthy(healthy, z_width=z_width, angle_width=angle_width)
        }
    return locomotion_task(
        task_name, smoothing=smoothing, gradient=m.gradient, reward_options=reward_options,
        control_period=settings.control_period, substeps=settings.substeps,
        contact=settings.contact,
    )  # fmt: skip


def _healthy_ranges(task_name: str) -> HealthyRanges | None:
    """The healthy ranges of a task whose reward is gymnasium's planar one with a healthy term
    (Hopper, Walker2d), else None."""
    make = getattr(GymLocomotionReward, TASKS[task_name].reward, None)
    if make is None:
        return None
    reward = make(1.0)
    return reward.healthy if reward.healthy_reward != 0 else None


class TrainerRun:
    """What every run here shares: a trainer with ``state`` (``env_steps``, ``seconds``,
    ``rows``, ``theta``), ``iterate()``, ``save(path)`` and ``full_state_policy()`` on
    ``task``. Subclasses build them and say how to ``load`` one and what ``recent_return``
    is."""

    task: LocomotionTask
    trainer: ShacTrainer | ArsTrainer | Sb3Trainer
    method: str
    seed: int

    @property
    def env_steps(self) -> int:
        return int(self.trainer.state.env_steps)

    @property
    def seconds(self) -> float:
        return float(self.trainer.state.seconds)

    @property
    def rows(self) -> list[dict]:
        """The trainer's log, one row per iteration."""
        return self.trainer.state.rows

    def iterate(self) -> dict:
        return self.trainer.iterate()

    def save(self, path: str | Path) -> None:
        self.trainer.save(path)

    def policy_file(self, **metadata) -> PolicyFile:
        meta = {"method": self.method, "seed": self.seed, "training_steps": self.env_steps}
        policy = self.trainer.full_state_policy()
        return task_policy_file(self.task, policy, self.trainer.state.theta, **(meta | metadata))


class ShacRun(TrainerRun):
    """A :class:`~drake_abs.policy.shac.ShacTrainer` run (``shac`` and ``fopg_episode``
    methods) as a :class:`TrainingRun`."""

    def __init__(self, task_name: str, method: str, seed: int, settings: RunSettings):
        m = registry_method(method)
        if m.estimator not in SHAC_TRAINERS:
            raise ValueError(f"method must be one of the SHAC trainer's; got {method!r}")
        self.task_name, self.method, self.seed, self.settings = task_name, method, seed, settings
        self.task = training_task(task_name, method, settings)
        #: gymnasium's own reward (without the smooth survive term), logged beside the training
        #: reward
        self.score_reward = None
        if getattr(self.task.reward, "smooth_survive", None) is not None:
            self.score_reward = replace(self.task.reward, smooth_survive=None)
        config = ShacConfig.for_method(method, **_shac_fields(settings))
        self.trainer = ShacTrainer(self.task, config, seed, score_reward=self.score_reward)

    @property
    def recent_return(self) -> float | None:
        """Mean return, by gymnasium's reward, of the last episodes the trainer completed (None
        before the first)."""
        if not self.rows:
            return None
        row = self.rows[-1]
        return row["recent_score"] if row.get("recent_score") is not None else row["recent_return"]

    def load(self, path: str | Path) -> ShacRun:
        """This run continued from the checkpoint at ``path``."""
        self.trainer = ShacTrainer.load(path, self.task, score_reward=self.score_reward)
        return self


class ArsRun(TrainerRun):
    """An :class:`~drake_abs.policy.ars_trainer.ArsTrainer` run (the ``ars`` method) as a
    :class:`TrainingRun`, on the exact plant with gymnasium's reward."""

    def __init__(self, task_name: str, method: str, seed: int, settings: RunSettings):
        if registry_method(method).estimator != "ars":
            raise ValueError(f"method must be an ARS method; got {method!r}")
        self.task_name, self.method, self.seed, self.settings = task_name, method, seed, settings
        self.task = locomotion_task(task_name, control_period=settings.control_period,
                                    substeps=settings.substeps,
                                    contact=settings.contact)  # fmt: skip
        config = settings.ars or ArsConfig.published(self.task.env_id)
        self.trainer = ArsTrainer(self.task, config, seed)

    @property
    def recent_return(self) -> float | None:
        """Mean return (gymnasium's reward) of the last iteration's episodes."""
        return self.rows[-1]["return_mean"] if self.rows else None

    def load(self, path: str | Path) -> ArsRun:
        """This run continued from the checkpoint at ``path``."""
        self.trainer = ArsTrainer.load(path, self.task)
        return self


class Sb3Run(TrainerRun):
    """A library baseline's run (``sb3`` methods:
    :class:`~drake_abs.tasks.sb3_baselines.Sb3Trainer`) as a :class:`TrainingRun`, on the
    exact plant with gymnasium's reward."""

    def __init__(self, task_name: str, method: str, seed: int, settings: RunSettings):
        if registry_method(method).estimator != "sb3":
            raise ValueError(f"method must be a library baseline (sb3_*); got {method!r}")
        from drake_abs.tasks.sb3_baselines import METHOD_KEYS, Sb3Trainer

        algorithm = {key: algo for algo, key in METHOD_KEYS.items()}[method]
        self.task_name, self.method, self.seed, self.settings = task_name, method, seed, settings
        env_options = {"control_period": settings.control_period, "substeps": settings.substeps,
                       "contact": settings.contact}  # fmt: skip
        self.trainer = Sb3Trainer(
            task_name, algorithm, seed, env_options=env_options,
            n_envs=1 if algorithm == "ars" else settings.sb3_envs, chunk=settings.sb3_chunk,
        )  # fmt: skip
        self.task = self.trainer.task

    @property
    def recent_return(self) -> float | None:
        """Mean return (gymnasium's reward) of the episodes that ended lately."""
        return self.trainer.recent_return

    def load(self, path: str | Path) -> Sb3Run:
        """This run continued from the checkpoint at ``path``."""
        self.trainer.load(path)
        return self

    def policy_file(self, **metadata) -> PolicyFile:
        """The library model's policy, labelled with this run's method (the trainer's
        :meth:`~drake_abs.tasks.sb3_baselines.Sb3Trainer.policy_file`)."""
        return self.trainer.policy_file(**({"method": self.method} | metadata))


def _shac_fields(settings: RunSettings) -> dict:
    """The ShacConfig fields of ``settings.shac``, with the run's policy kind."""
    values = asdict(replace(settings.shac, policy=settings.policy))
    return {key: tuple(v) if isinstance(v, list) else v for key, v in values.items()}


def start_run(task_name: str, method: str, seed: int, settings: RunSettings) -> TrainingRun:
    """A new run of ``method`` (a registry name) on ``task_name`` seeded by ``seed``."""
    m = registry_method(method)
    if m.estimator in SHAC_TRAINERS:
        return ShacRun(task_name, method, seed, settings)
    if m.estimator == "ars":
        return ArsRun(task_name, method, seed, settings)
    if m.estimator == "sb3":
        return Sb3Run(task_name, method, seed, settings)
    raise ValueError(
        f"method must be one this module trains (estimators {SHAC_TRAINERS + ('ars', 'sb3')}); "
        f"{method!r} is {m.estimator!r}"
    )


def resume_run(
    path: str | Path, task_name: str, method: str, seed: int, settings: RunSettings
) -> TrainingRun:
    """The run saved at ``path`` (by ``run.save``), continued: the caller checks that it was
    started with the same task, method, seed and settings (the checkpoint holds the trainer's
    state, not the task)."""
    run = start_run(task_name, method, seed, settings)
    return run.load(path)
