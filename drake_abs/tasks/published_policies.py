"""Policy files (:mod:`drake_abs.policy.policy_files`) and the locomotion tasks on our plant: a
task's policy written as a file of gymnasium's observation, a file run on our plant, and its
score there over the episodes gymnasium's scoring runs (the same reset seeds, 1000 steps,
termination).

- :func:`task_name_for_env`: the task (:data:`~drake_abs.tasks.locomotion.TASKS`) that models a
  gymnasium id on our plant.
- :func:`task_policy_file`: a task's policy as a file. A policy of the task's observation
  (``task.policy(inner)``, an :class:`~drake_abs.tasks.adapters.ObservationPolicy`) is its inner
  policy's file; a linear policy of the full state (ARS's
  :class:`~drake_abs.policy.ars_v2.NormalizedLinearPolicy`) only where it is one of the
  observation exactly: the observation is the state without its leading entries, unclipped
  (the HalfCheetah's, not the Hopper's, whose velocities are clipped at 10), and the policy's
  weights on the left-out entries are zero.
- :func:`file_policy` / :func:`load_for_task`: a file as the task's full-state policy
  ``u = clip(file(obs(x)), -1, 1)`` (no parameters: theta has shape (0,)), the second as a
  :class:`~drake_abs.policy.saving.SavedPolicy` with its task, for
  :func:`~drake_abs.tasks.saved_policies.run_episode` and the replay.
- :func:`score_on_plant`: one deterministic episode per reset seed on our plant
  (:func:`~drake_abs.tasks.episodes.score_episodes`: the task's reward and termination, an
  unconverged contact solve flagged and counted), from the state gymnasium's
  ``reset(seed=s)`` draws (:func:`~drake_abs.tasks.saved_policies.reset_state`).

The observation a file takes is gymnasium v5's; the task's observation map computes the same
vector from our state (checked against gymnasium in ``tests/tasks/test_published_policies.py``).
Building a task needs Drake (imported when called).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from drake_abs._validation import as_count
from drake_abs.policy.policy_files import FilePolicy, PolicyFile, load_policy_file, to_policy_file
from drake_abs.policy.saving import SavedPolicy
from drake_abs.tasks.adapters import ObservationPolicy
from drake_abs.tasks.episodes import episode_statistics, score_episodes
from drake_abs.tasks.locomotion import TASKS, LocomotionTask, locomotion_task
from drake_abs.tasks.saved_policies import reset_state

__all__ = [
    "ACTION_RANGE",
    "file_policy",
    "load_for_task",
    "score_on_plant",
    "task_name_for_env",
    "task_policy_file",
]

#: The locomotion tasks' action range (gymnasium's ``ctrlrange``; the task's stepper scales an
#: action by the motors' gears).
ACTION_RANGE = (-1.0, 1.0)


def task_name_for_env(env_id: str) -> str:
    """The name of the task of :data:`~drake_abs.tasks.locomotion.TASKS` that reproduces the
    gymnasium environment ``env_id`` on our plant (``"Hopper-v5"`` -> ``"hopper"``);
    ``ValueError`` listing those that have one."""
    for name, spec in TASKS.items():
        if spec.env_id == env_id:
            return name
    known = sorted(spec.env_id for spec in TASKS.values())
    raise ValueError(f"env_id {env_id!r} has no scene on our plant; those that do: {known}")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("drake-abs")
    except PackageNotFoundError:  # a checkout that is not installed
        return "unknown"


def _selection(task: LocomotionTask) -> np.ndarray:
    """The state entries the task's observation is, when it is a plain selection of them
    (``ValueError`` saying why a full-state policy does not map onto it otherwise)."""
    observation = task.observation
    clip = getattr(observation, "velocity_clip", "unknown")
    skip = getattr(observation, "skip", None)
    if clip == "unknown" or skip is None:
        raise ValueError(
            f"policy acts on the full state, and task {task.name!r}'s observation "
            f"({type(observation).__name__}) is not known to be a selection of it: save the "
            "policy of the observation instead"
        )
    if clip is not None:
        raise ValueError(
            f"policy acts on the full state, but task {task.name!r}'s observation clips the "
            f"velocities at +-{clip}, so the policy is not a policy of the observation exactly: "
            "it cannot be written as a policy file (train it on the observation instead)"
        )
    return np.arange(skip, task.nx)


def task_policy_file(task: LocomotionTask, policy, theta, **metadata) -> PolicyFile:
    """The policy file (of gymnasium's observation) of ``policy`` acting in ``task``.

    Args:
        task: the task the policy acts in (its observation; ``env_id`` goes to the metadata).
        policy: ``task.policy(inner)`` (an observation policy of the task's observation, inner
            a :class:`~drake_abs.policy.policies.LinearPolicy`,
            :class:`~drake_abs.policy.policies.MLPPolicy` or
            :class:`~drake_abs.policy.ars_v2.NormalizedLinearPolicy`), or one of those of the
            full state (module docstring: only where it is one of the observation exactly).
        theta: (P,) its parameters.
        metadata: the file's metadata (``method``, ``seed``, ``training_steps``, ...);
            ``env_id`` (the task's) and ``drake_abs_version`` are added unless given.

    Raises:
        ValueError: a policy of another observation or of sizes that do not fit the task, or a
            full-state policy that is not one of the observation.
    """
    metadata = {"env_id": task.env_id, "drake_abs_version": _version()} | metadata
    metadata = {key: value for key, value in metadata.items() if value is not None}
    if isinstance(policy, ObservationPolicy):
        if policy.observation != task.observation:
            raise ValueError(
                f"policy observes {policy.observation!r}, not task {task.name!r}'s observation "
                f"{task.observation!r}"
            )
        file = to_policy_file(policy.inner, theta, **metadata)
    else:
        if getattr(policy, "nx", None) != task.nx:
            raise ValueError(
                f"policy must be task.policy(inner) or a policy of the full state (nx = "
                f"{task.nx}); got {type(policy).__name__} with nx {getattr(policy, 'nx', None)}"
            )
        keep = _selection(task)
        full = to_policy_file(policy, theta, **metadata)
        W0 = full.weights[0]
        dropped = np.setdiff1d(np.arange(task.nx), keep)
        if np.any(W0[:, dropped] != 0):
            raise ValueError(
                f"policy acts on the full state with nonzero weights on state entries "
                f"{dropped.tolist()}, which task {task.name!r}'s observation leaves out: it is "
                "not a policy of the observation, and cannot be written as a policy file"
            )
        file = PolicyFile(
            (W0[:, keep], *full.weights[1:]), full.biases, full.obs_mean[keep],
            full.obs_std[keep], full.activation, full.metadata, full.output_activation,
        )  # fmt: skip
    if file.n_obs != task.n_obs or file.nu != task.nu:
        raise ValueError(f"policy maps {file.n_obs} observations to {file.nu} actions; task "
                         f"{task.name!r} has {task.n_obs} and {task.nu}")  # fmt: skip
    return file


def file_policy(task: LocomotionTask, file: PolicyFile) -> ObservationPolicy:
    """The task's full-state policy of a file: ``u = clip(file(obs(x)), -1, 1)``, theta of
    shape (0,); ``ValueError`` when the file's sizes are not the task's."""
    if not isinstance(file, PolicyFile):
        raise ValueError(f"file must be a PolicyFile; got {type(file).__name__}")
    if file.n_obs != task.n_obs or file.nu != task.nu:
        raise ValueError(
            f"the policy file maps {file.n_obs} observations to {file.nu} actions; task "
            f"{task.name!r} ({task.env_id}) has {task.n_obs} observations and {task.nu} actions"
        )
    return task.policy(FilePolicy(file, *ACTION_RANGE))


def load_for_task(
    path: str | Path, *, env_id: str | None = None, task: LocomotionTask | None = None
) -> SavedPolicy:
    """Load a policy file as a :class:`~drake_abs.policy.saving.SavedPolicy` of its task on our
    plant (``policy`` the full-state policy, ``theta`` empty, ``task`` the task).

    Args:
        path: the ``.npz`` policy file.
        env_id: its gymnasium environment (default: the file's ``env_id`` metadata).
        task: the task, if built already (default: built here for the environment).
    """
    file = load_policy_file(path)
    env_id = env_id if env_id is not None else file.metadata.get("env_id")
    if task is None:
        if env_id is None:
            raise ValueError(
                f"the policy file {str(path)!r} names no env_id: give the environment (e.g. "
                "env_id='Hopper-v5')"
            )
        task = locomotion_task(task_name_for_env(str(env_id)))
    elif env_id is not None and task.env_id != env_id:
        raise ValueError(f"task {task.name!r} models {task.env_id}, not env_id {env_id!r}")
    policy = file_policy(task, file)
    return SavedPolicy(
        policy=policy, theta=np.zeros(0), task_name=task.name, config=None, inner=policy.inner,
        kind="PolicyFile", acts_on="observation", path=Path(path).expanduser().resolve(),
        metadata=dict(file.metadata), task=task,
    )  # fmt: skip


def score_on_plant(
    task: LocomotionTask,
    file: PolicyFile,
    *,
    seeds: Iterable[int] = range(10),
    max_steps: int = 1000,
) -> dict:
    """Score a policy file on our plant: one deterministic episode per reset seed (module
    docstring), at most ``max_steps`` steps of ``task.dt`` s each.

    Returns:
        ``task``, ``env_id``, ``dt`` (s per step), ``seeds``, ``max_steps``, per episode
        ``returns``, ``lengths`` and ``terminated``; ``mean``, ``std`` (population), ``min``,
        ``max`` of the returns, ``length_mean``; ``unconverged_episodes`` (episodes with at
        least one step whose contact solve did not converge: their states are not exact) and
        ``unconverged_steps`` (all such steps).
    """
    seeds = list(seeds)
    if not seeds:
        raise ValueError("seeds must hold at least one reset seed")
    max_steps = as_count(max_steps, "max_steps", minimum=1)
    policy = file_policy(task, file)
    x0s = np.array([reset_state(task, seed) for seed in seeds])
    episodes = score_episodes(task, policy, np.zeros(0), x0s, max_steps)
    stats = episode_statistics(episodes)
    returns = np.array(stats["returns"])
    return {
        "task": task.name, "env_id": task.env_id, "dt": float(task.dt),
        "seeds": [int(s) for s in seeds], "max_steps": max_steps,
        "returns": stats["returns"], "lengths": stats["lengths"],
        "terminated": [bool(e["terminated"]) for e in episodes],
        "mean": stats["return_mean"], "std": stats["return_std"],
        "min": float(returns.min()), "max": float(returns.max()),
        "length_mean": stats["length_mean"],
        "unconverged_episodes": sum(e["unconverged_steps"] > 0 for e in episodes),
        "unconverged_steps": stats["unconverged_steps"],
    }  # fmt: skip
