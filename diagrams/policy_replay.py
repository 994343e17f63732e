"""A saved policy replayed on our plant into a Meshcat HTML recording.

:func:`replay_policy_html` loads a policy saved by :func:`drake_abs.policy.saving.save_policy`
(for a locomotion task: :func:`drake_abs.tasks.saved_policies.load_policy`), runs it
deterministically (no exploration noise, sigma = 0) from the state gymnasium's
``reset(seed=seed)`` gives (the task's initial state plus its reset noise) with the task's own
scene (exact contact), and records the states with
:func:`~drake_abs.diagrams.scene_visualization.record_rollout_html`: one self-contained HTML
page, played offline in a browser; Meshcat binds to localhost only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from pydrake.geometry import Meshcat

from drake_abs.diagrams.scene_visualization import record_rollout_html
from drake_abs.multibody.scene import Scene
from drake_abs.policy.saving import SavedPolicy
from drake_abs.tasks.locomotion import TASKS
from drake_abs.tasks.saved_policies import Episode, load_policy, reset_state, run_episode

__all__ = ["DEFAULT_STEPS", "PolicyReplay", "replay_policy_html", "replay_scene"]

#: The steps replayed when none are given (gymnasium's episode length).
DEFAULT_STEPS = 1000


@dataclass(frozen=True)
class PolicyReplay:
    """What :func:`replay_policy_html` wrote and ran: ``path`` (the HTML page), ``episode`` (the
    :class:`~drake_abs.tasks.saved_policies.Episode`: states, actions, rewards, whether the task
    terminated it), ``task_name`` and ``seed``."""

    path: Path
    episode: Episode
    task_name: str
    seed: int


def replay_scene(task) -> Scene:
    """The task's scene with one frame per action: its ``time_step`` set to the task's control
    period ``task.dt`` (the states recorded are one per action, each ``substeps`` plant
    steps)."""
    plant = getattr(task, "plant", None) or getattr(task.stepper, "stepper", None)
    scene = getattr(plant, "scene", None)
    if not isinstance(scene, Scene):
        if task.name not in TASKS:
            raise ValueError(
                f"task {task.name!r} has no scene to draw (its stepper has no 'scene')"
            )
        scene = Scene.load(TASKS[task.name].scene)
    return replace(scene, time_step=float(task.dt))


def replay_policy_html(
    saved_or_path: SavedPolicy | str | Path,
    html_path: str | Path,
    *,
    steps: int | None = None,
    seed: int = 0,
    stop_at_termination: bool = True,
    meshcat: Meshcat | None = None,
) -> PolicyReplay:
    """Run a saved policy deterministically on our plant and write the Meshcat recording.

    Args:
        saved_or_path: a :class:`~drake_abs.policy.saving.SavedPolicy` with its task (as
            :func:`drake_abs.tasks.saved_policies.load_policy` returns), or the saved policy's
            ``STEM.json`` / ``STEM.npz`` / ``STEM`` (loaded with that function).
        html_path: the HTML file to write (its folder is created).
        steps: the most actions to run (one every ``task.dt`` s, gymnasium's control period for
            its tasks: 8 ms Hopper, 50 ms HalfCheetah); default :data:`DEFAULT_STEPS`
            (gymnasium's episode length).
        seed: the reset seed (gymnasium's ``reset(seed=seed)``: the same start state).
        stop_at_termination: end where the task ends the episode (the Hopper falls), as
            gymnasium does; else run all ``steps``.
        meshcat: the Meshcat to draw in (default: a new one bound to localhost).

    Returns:
        A :class:`PolicyReplay` (``path``: the page; ``episode``: what ran).

    Raises:
        ValueError: a policy that names no task (there is no scene to replay it in), or bad
            ``steps`` / ``seed``.
    """
    if isinstance(saved_or_path, SavedPolicy):
        saved = saved_or_path
    elif isinstance(saved_or_path, str | Path):
        saved = load_policy(saved_or_path)
    else:
        raise ValueError(
            "saved_or_path must be a SavedPolicy or a saved policy's path; got "
            f"{type(saved_or_path).__name__}"
        )
    task = saved.task
    if task is None:
        raise ValueError(
            f"saved_or_path: the policy {str(saved.path)!r} acts in no task "
            f"(task {saved.task_name!r} not built): replay needs a task policy, e.g. saved with "
            "save_policy(..., task='hopper') and loaded with "
            "drake_abs.tasks.saved_policies.load_policy"
        )
    steps = DEFAULT_STEPS if steps is None else steps
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps must be a whole number >= 1 (time steps); got {steps!r}")
    x0 = reset_state(task, seed)
    episode = run_episode(task, saved.policy, saved.theta, x0, steps,
                          stop_at_termination=stop_at_termination)  # fmt: skip
    path = record_rollout_html(replay_scene(task), episode.states, html_path, meshcat=meshcat)
    return PolicyReplay(path=Path(path), episode=episode, task_name=task.name, seed=int(seed))
