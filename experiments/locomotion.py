"""Learning locomotion through contact: return against samples and wall time on gymnasium's Hopper
and HalfCheetah on our plant (Zhang et al. 2023, Figure 4, measured there in Dojo).

Every method of :data:`METHODS` (names and descriptions in :mod:`drake_abs.policy.methods`:
FOPG through adaptive barrier smoothing (ours), exact contact and two fixed mu; ZOPG; AoBG with
a fixed ``alpha`` (Suh et al. 2022 choose alpha per step from the two estimates' variances: a
simplification, stated here); PIPPS; ARS V2-t with its published settings; an MBPO-style loop
without SAC) trains on the same task (:mod:`drake_abs.tasks.locomotion`), with the same sample
budget per iteration, for ``iterations`` iterations and every seed of ``seeds``, in the loop of
:func:`drake_abs.tasks.locomotion_training.train_method` (which says how each method trains, and
how skipped iterations and samples are counted). Each baseline module states where it follows
its paper and where it departs.

After every iteration the policy is evaluated on the true system (exact contact, whatever model
the method trains on), deterministically, from ``eval_episodes`` of gymnasium's reset states
(drawn once per task with ``eval_seed``) over ``eval_horizon`` steps; the curves are that return
against cumulative training samples and against wall time, mean and spread (min-max) over the
seeds. Every final policy is saved in ``policies/`` (npz + json) and can be replayed
(``drake-abs replay``).

Outputs in ``out``: ``figure4_<task>.png`` (return against samples and against seconds),
``curves.csv`` (every evaluation), ``summary.json``, ``policies/``.
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.experiments.outputs import file_list, progress, results_dir
from drake_abs.policy.mbpo import MbpoConfig
from drake_abs.policy.methods import make_smoothing, method
from drake_abs.policy.policies import LinearPolicy
from drake_abs.tasks.locomotion_training import LocomotionTraining, train_method

NAME = "locomotion"
TASKS = ("hopper", "half_cheetah")
#: the methods compared (names of drake_abs.policy.methods)
METHODS = ("fopg_abs", "fopg_exact", "fopg_bs_1e-10", "fopg_bs_1e-2", "zopg", "aobg", "pipps",
           "ars", "mbpo")  # fmt: skip


@dataclass(frozen=True)
class Config(LocomotionTraining):
    """Sizes (:class:`~drake_abs.tasks.locomotion_training.LocomotionTraining`: per iteration
    every method uses ``rollouts`` rollouts of ``horizon`` steps, ...), the tasks, methods and
    seeds, and the evaluation: ``eval_episodes`` reset states drawn with ``eval_seed``."""

    tasks: tuple[str, ...] = TASKS
    methods: tuple[str, ...] = METHODS
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    eval_episodes: int = 4
    eval_seed: int = 12345

    @classmethod
    def test_size(cls) -> Config:
        small = MbpoConfig(ensemble_size=2, hidden=(8,), model_epochs=2, branches=8,
                           policy_updates=2, rollout_length=3)  # fmt: skip
        return cls(seeds=(0, 1), iterations=3, rollouts=4, horizon=8, eval_episodes=2,
                   eval_horizon=8, mbpo=small)  # fmt: skip


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Train every method on every task for every seed; write the figures, the curves and
    summary.json to ``out`` (default results/locomotion)."""
    from drake_abs.policy.saving import save_policy
    from drake_abs.tasks.locomotion import locomotion_task

    config = config or Config()
    if any(name not in TASKS for name in config.tasks):
        raise ValueError(f"tasks must be among {TASKS}; got {config.tasks!r}")
    methods = {m: method(m) for m in config.methods}  # unknown methods refused here
    smoothing = {m: e.make_smoothing(contact_aware=config.contact_aware)
                 for m, e in methods.items()}  # fmt: skip
    out = results_dir(NAME, out)
    (out / "policies").mkdir(exist_ok=True)
    start = time.perf_counter()
    bar = progress(total=len(config.tasks) * len(config.methods) * len(config.seeds),
                   desc=f"{NAME}: runs")  # fmt: skip
    results: dict = {}
    csv_rows = []
    for name in config.tasks:
        results[name] = {}
        true_task = locomotion_task(name, smoothing=make_smoothing("exact"))  # the scoring
        x_eval = true_task.initial_states(np.random.default_rng(config.eval_seed),
                                          config.eval_episodes)  # fmt: skip
        for m, entry in methods.items():
            task = locomotion_task(name, smoothing=smoothing[m], gradient=entry.gradient)
            runs, skipped = [], []
            for seed in config.seeds:
                run_ = train_method(task, m, config, seed, x_eval, true_task)
                runs.append(run_["rows"])
                skipped.append(run_.get("skipped", 0))
                # ARS's own policy class; the others: the task's linear policy of the observation
                policy = run_.get("policy", task.policy(LinearPolicy(task.n_obs, task.nu)))
                save_policy(out / "policies" / f"{name}_{m}_seed{seed}", policy, run_["theta"],
                            task=name, config={"task": name, "method": m, "seed": seed,
                                               **asdict(config)})  # fmt: skip
                csv_rows += [{"task": name, "method": m, "seed": seed, **r} for r in run_["rows"]]
                bar.set_postfix_str(f"{name} {m} seed {seed}: {run_['rows'][-1]['return']:.3g}")
                bar.update()
            results[name][m] = _curve(runs) | {"skipped_iterations": skipped}
    bar.close()
    files = {"summary": out / "summary.json", "curves": out / "curves.csv"}
    for name in config.tasks:
        files[f"figure4_{name}"] = _plot(name, results[name], out / f"figure4_{name}.png")
    with (out / "curves.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(dict.fromkeys(k for r in csv_rows for k in r)))
        writer.writeheader()
        writer.writerows(csv_rows)
    summary = {"config": asdict(config), "tasks": results,
               "seconds": time.perf_counter() - start, "folder": str(out)}  # fmt: skip
    summary["files"] = file_list(files) | {"policies": str((out / "policies").resolve())}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def _curve(runs: list[list[dict]]) -> dict:
    """Mean, min and max over seeds of the evaluated return per iteration, with the mean
    cumulative samples and seconds."""
    R = np.array([[r["return"] for r in rows] for rows in runs])
    S = np.array([[r["samples"] for r in rows] for rows in runs], float)
    T = np.array([[r["seconds"] for r in rows] for rows in runs])
    return {
        "return_mean": R.mean(axis=0).tolist(), "return_min": R.min(axis=0).tolist(),
        "return_max": R.max(axis=0).tolist(), "samples_mean": S.mean(axis=0).tolist(),
        "seconds_mean": T.mean(axis=0).tolist(), "final_returns": R[:, -1].tolist(),
        "initial_return": float(R[0, 0]),
    }  # fmt: skip


def _plot(name: str, curves: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    for m, c in curves.items():
        style = {"color": "tab:red", "lw": 2} if m == "fopg_abs" else {}
        for ax, x in zip(axes, (c["samples_mean"], c["seconds_mean"]), strict=True):
            (line,) = ax.plot(x, c["return_mean"], label=method(m).label, **style)
            ax.fill_between(x, c["return_min"], c["return_max"], alpha=0.15,
                            color=line.get_color())  # fmt: skip
    axes[0].set(xlabel="training samples (environment steps)", ylabel="evaluated return")
    axes[1].set(xlabel="wall time of training (s)", ylabel="evaluated return")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{name.replace('_', '-')}: return against samples and time (Zhang et al. 2023, "
                 "Fig. 4; mean and min-max over seeds)")  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def report(summary: dict) -> str:
    cfg = summary["config"]
    lines = [f"Locomotion learning (Zhang et al. 2023, Figure 4) on our plant: "
             f"{len(cfg['seeds'])} seeds, {cfg['iterations']} iterations of {cfg['rollouts']} "
             f"rollouts x {cfg['horizon']} steps; {summary['seconds']:.0f} s"]  # fmt: skip
    for name, curves in summary["tasks"].items():
        lines.append(f"{name}: evaluated return (start -> end, mean [min, max] over seeds)")
        ranked = sorted(curves.items(), key=lambda kv: -kv[1]["return_mean"][-1])
        for m, c in ranked:
            lines.append(f"  {m:16s} {c['initial_return']:9.3g} -> "
                         f"{c['return_mean'][-1]:9.3g} "
                         f"[{min(c['final_returns']):.3g}, {max(c['final_returns']):.3g}]  "
                         f"{c['samples_mean'][-1]:.0f} samples, "
                         f"{c['seconds_mean'][-1]:.1f} s")  # fmt: skip
    return "\n".join(lines)


if __name__ == "__main__":
    print(report(run(Config.test_size(), "results/locomotion-test")))
