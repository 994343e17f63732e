"""``drake-abs train TASK --method M``: one training run of a locomotion task with a method of the
registry (:mod:`drake_abs.policy.methods`), through :mod:`drake_abs.tasks.training_runs`.

The run advances one trainer iteration at a time until it has stepped ``steps`` environment steps
(control periods, as the trainer counts them: the last iteration may pass the budget), printing a
line at every tenth of the budget, and writes to its folder

- ``policy.npz``: the final policy as a policy file (:mod:`drake_abs.policy.policy_files`;
  ``drake-abs evaluate`` and ``drake-abs replay`` read it);
- ``summary.json``: the task, method, seed, budget, the steps and seconds the run took, its last
  training return and the settings the method read.

The settings start from the ``gym-locomotion`` experiment's (:class:`RunSettings` with its SHAC
settings, the policy's step size decaying to 0 over the run's own budget; ARS: the published
settings of the task), and ``--set KEY=VALUE`` changes any field of :class:`RunSettings` (dotted
for a field of a group: ``shac.envs=8``, ``ars.directions=4``).
"""

from __future__ import annotations

import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import TextIO

from drake_abs.experiments import outputs
from drake_abs.experiments.gym_locomotion import SHAC
from drake_abs.policy.ars_trainer import ArsConfig
from drake_abs.policy.methods import METHODS
from drake_abs.policy.methods import method as registry_method
from drake_abs.tasks.locomotion import TASKS
from drake_abs.tasks.training_runs import SHAC_TRAINERS, RunSettings, start_run

#: The budget when ``--steps`` is not given: the ``gym-locomotion`` experiment's.
DEFAULT_STEPS = 1_000_000
#: The registry's estimators :func:`drake_abs.tasks.training_runs.start_run` trains.
TRAINED_ESTIMATORS = (*SHAC_TRAINERS, "ars", "sb3")
#: Progress lines per run (one at every such fraction of the budget).
PROGRESS_LINES = 10


def trainable_methods() -> list[str]:
    """The registry's methods a run can train (SHAC, whole-episode FOPG, ARS, the library
    baselines), by name."""
    return [name for name, m in METHODS.items() if m.estimator in TRAINED_ESTIMATORS]


def default_out(task: str, method: str, seed: int) -> Path:
    """The default folder of a run: ``results/train-<task>-<method>-seed<seed>`` (absolute)."""
    return outputs.default_out(f"train-{task}-{method}-seed{seed}")


def base_settings(task: str, method: str, steps: int) -> RunSettings:
    """The settings a run starts from before ``--set``: the ``gym-locomotion`` experiment's SHAC
    settings with the policy's step size decaying linearly to 0 over ``steps`` (SHAC's
    schedule), and for an ARS method the published settings of ``task`` (what
    :class:`~drake_abs.tasks.training_runs.ArsRun` uses when none are given; here so that
    ``--set ars.KEY=...`` can change one of them).

    Raises:
        ValueError: an unknown task or method, or an ARS method on a task with no published
            settings.
    """
    if task not in TASKS:
        raise ValueError(f"task must be one of {sorted(TASKS)}; got {task!r}")
    m = registry_method(method)
    if m.estimator not in TRAINED_ESTIMATORS:
        raise ValueError(f"method must be one of {trainable_methods()}; got {method!r}")
    ars = ArsConfig.published(TASKS[task].env_id) if m.estimator == "ars" else None
    return RunSettings(shac=replace(SHAC, actor_lr_decay_steps=int(steps)), ars=ars)


def _progress_line(run, steps: int) -> str:
    recent = run.recent_return
    score = "no episode ended yet" if recent is None else f"recent return {recent:.2f}"
    return (
        f"  {run.env_steps:>{len(str(steps))}d} / {steps} env steps, iteration {len(run.rows)}, "
        f"{score}, {run.seconds:.1f} s"
    )


def train(
    task: str,
    method: str,
    *,
    steps: int,
    seed: int,
    out: str | Path,
    settings: RunSettings,
    echo: TextIO | None = None,
) -> dict:
    """Train one run of ``method`` on ``task`` for ``steps`` environment steps; write
    ``policy.npz`` and ``summary.json`` to ``out`` (created); return the summary.

    Args:
        task: a locomotion task name (:data:`drake_abs.tasks.locomotion.TASKS`).
        method: a method :func:`trainable_methods` lists.
        steps: the budget, environment steps (> 0).
        seed: the run's seed (>= 0).
        out: the results folder.
        settings: the run's settings (e.g. :func:`base_settings` with changes).
        echo: where the progress lines go (default: standard output).
    """
    echo = sys.stdout if echo is None else echo
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps must be a whole number >= 1; got {steps!r}")
    folder = outputs.results_dir(f"train-{task}-{method}-seed{seed}", out)
    label = registry_method(method).label
    print(f"training {label} ({method}) on {task}, seed {seed}, {steps} environment steps",
          file=echo, flush=True)  # fmt: skip
    run = start_run(task, method, seed, settings)
    marks = [math.ceil(k * steps / PROGRESS_LINES) for k in range(1, PROGRESS_LINES + 1)]
    bar = outputs.progress(total=steps, desc=f"{task} {method}")
    try:
        while run.env_steps < steps:
            before = run.env_steps
            run.iterate()
            if run.env_steps <= before:
                raise RuntimeError(
                    f"an iteration of {method} stepped no environment ({before} steps before "
                    "and after): the run cannot reach its budget"
                )
            bar.update(min(run.env_steps, steps) - before)
            if any(before < mark <= run.env_steps for mark in marks):
                bar.write(_progress_line(run, steps), file=echo)  # above the bar, if shown
    finally:
        bar.close()
    policy = run.policy_file().save(folder / "policy.npz")
    summary = {
        "task": task,
        "method": method,
        "label": label,
        "seed": int(seed),
        "steps": int(steps),
        "env_steps": int(run.env_steps),
        "iterations": len(run.rows),
        "seconds": float(run.seconds),
        "recent_return": run.recent_return,
        "settings": settings.for_method(method),
        "files": outputs.file_list({"policy": policy, "summary": folder / "summary.json"}),
        "version": _version(),
    }
    outputs.write_json(folder / "summary.json", summary, finite=True)
    return summary


def report(summary: dict) -> str:
    """The plain-text report of a run from its summary."""
    recent = summary["recent_return"]
    score = "no episode ended" if recent is None else f"{recent:.2f}"
    return "\n".join([
        f"{summary['label']} ({summary['method']}) on {summary['task']}, seed {summary['seed']}: "
        f"{summary['env_steps']} environment steps in {summary['iterations']} iterations, "
        f"{summary['seconds']:.1f} s of training",
        f"  recent training return (gymnasium's reward): {score}",
        f"  policy file: {summary['files']['policy']} (drake-abs evaluate / replay read it)",
    ])  # fmt: skip


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("drake-abs")
    except PackageNotFoundError:
        return "unknown"
