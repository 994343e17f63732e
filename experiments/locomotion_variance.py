"""FOPG gradient variance against unroll length on gymnasium's Hopper and HalfCheetah on our plant
(Zhang et al. 2023, Figure 3, whose locomotion panels were measured in Dojo).

The tasks are :func:`drake_abs.tasks.locomotion.locomotion_task`: gymnasium v5's models, reward
terms (forward velocity, control cost; the Hopper's healthy reward and termination),
observations and action range, on our time-stepping contact model (h = 0.01 s). The policy is
linear in the observation, ``a = K o + k`` (the paper's Dojo policies are small networks; a
linear policy keeps the measurement about the dynamics), at fixed parameters drawn once from
N(0, ``theta_scale``^2) with ``seed``; the exploration noise is ``sigma`` in action units
(actions live in [-1, 1]). Nothing is trained here.

For each task, unroll length H and smoothing (exact contact, barrier smoothing with fixed mu over
several decades, contact-aware ABS in both gradient modes) the FOPG variance
``v = E||g - E g||^2`` is measured from ``batches`` independent estimates of ``samples``
rollouts each (:func:`drake_abs.policy.gradient_stats.variance_bias_sweep`; every smoothing at
one H sees the same noise). Per curve, exponential and power-law fits of v over H and per
horizon whether v decreases as mu increases (the paper's second claim),
:mod:`drake_abs.policy.variance_growth`.

Outputs in ``out``: ``figure3_locomotion.png`` (one panel per task, variance against H, log
scale), ``summary.json``.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.contact.smoothing import Exact
from drake_abs.experiments.outputs import file_list, progress, readable, results_dir
from drake_abs.policy import variance_growth as vg
from drake_abs.policy.gradient_stats import fopg, variance_bias_sweep
from drake_abs.policy.policies import LinearPolicy

NAME = "locomotion-variance"
MODES = ("frozen", "total")
TASKS = ("hopper", "half_cheetah")


@dataclass(frozen=True)
class Config:
    """Sizes. ``fixed_mus``: the barrier-smoothing values (larger is smoother);
    ``contact_aware``: (mu_max, length in m) of the adaptive design; ``samples`` rollouts per
    estimate, ``batches`` estimates per point; ``sigma`` exploration noise (action units);
    ``theta_scale`` the spread of the fixed policy parameters."""

    tasks: tuple[str, ...] = TASKS
    horizons: tuple[int, ...] = (5, 10, 25, 50, 100, 200)
    fixed_mus: tuple[float, ...] = (1e-10, 1e-6, 1e-4, 1e-2)
    contact_aware: tuple[float, float] = (1e-2, 0.05)
    samples: int = 32
    batches: int = 16
    sigma: float = 0.1
    theta_scale: float = 0.1
    fit_from: int = 10
    seed: int = 0

    @classmethod
    def test_size(cls) -> Config:
        return cls(horizons=(5, 10, 20), fixed_mus=(1e-10, 1e-2), samples=8, batches=4)


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Measure the variance sweep on each task; write the figure and summary.json to ``out``
    (default results/locomotion-variance); ``summary["files"]`` lists them (absolute paths)."""
    from drake_abs.tasks.locomotion import locomotion_task

    config = config or Config()
    if any(name not in TASKS for name in config.tasks):
        raise ValueError(f"tasks must be among {TASKS}; got {config.tasks!r}")
    out = results_dir(NAME, out)
    start = time.perf_counter()
    designs = vg.sweep_smoothings(config.fixed_mus, config.contact_aware)
    per_task = len(config.horizons) * sum(1 if p.is_constant else len(MODES)
                                          for p in designs.values())  # fmt: skip
    bar = progress(total=per_task * len(config.tasks), desc=f"{NAME}: points")

    def tick(line: str) -> None:
        bar.set_postfix_str(line)
        bar.update()

    results = {}
    for name in config.tasks:
        tasks: dict = {}  # (smoothing, mode) -> task: each scene built once per design

        def objective(smoothing, mode, H, name=name, tasks=tasks):
            key = (repr(smoothing), mode)
            if key not in tasks:
                tasks[key] = locomotion_task(name, smoothing=smoothing, gradient=mode)
            task = tasks[key]
            return task.objective(LinearPolicy(task.n_obs, task.nu), H, config.sigma)

        n_params = objective(Exact(), "frozen", 1).policy.n_params
        dt = next(iter(tasks.values())).dt  # s, the scene's time step
        theta = config.theta_scale * np.random.default_rng(config.seed).standard_normal(n_params)
        rows = variance_bias_sweep(
            objective, theta, designs, config.horizons, batches=config.batches,
            seed=config.seed, estimator=fopg(config.samples), modes=MODES, progress=tick,
        )  # fmt: skip
        curves = vg.variance_curves(
            rows,
            fit_from=config.fit_from,
            time_step=dt,
            extra=lambda r: {"dropped": r.get("dropped_rollouts", 0)},
        )
        results[name] = {
            "curves": curves, "mu_ordering": vg.mu_ordering(rows, config.horizons),
            "unconverged_steps": int(sum(r["unconverged_steps"] for r in rows)),
            "theta": theta.tolist(), "rows": rows,
        }  # fmt: skip
    bar.close()
    summary = {"config": asdict(config), "tasks": results,
               "seconds": time.perf_counter() - start}  # fmt: skip
    files = {"figure3": _plot(results, out / "figure3_locomotion.png"),
             "summary": out / "summary.json"}  # fmt: skip
    summary["folder"] = str(out)
    summary["files"] = file_list(files)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def _plot(results: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(6.5 * len(results), 4.8), squeeze=False)
    for ax, (name, res) in zip(axes[0], results.items(), strict=True):
        curves = res["curves"]
        for label, c in curves.items():
            style = vg.curve_style(label, list(curves), matplotlib.colormaps["viridis"])
            ax.errorbar(c["horizon"], c["variance"], yerr=c["variance_se"], marker="o", ms=3,
                        capsize=2, label=readable(label), **style)  # fmt: skip
        ax.set(xlabel="unroll length H (steps of 0.01 s)", yscale="log",
               ylabel="FOPG gradient variance E||g - Eg||^2",
               title=f"{name.replace('_', '-')} (gymnasium v5 task on our plant)")  # fmt: skip
        ax.legend(fontsize=7)
    fig.suptitle("FOPG variance against unroll length (Zhang et al. 2023, Fig. 3, locomotion)")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def report(summary: dict) -> str:
    lines = [f"FOPG gradient variance against unroll length on gymnasium's locomotion tasks "
             f"(Zhang et al. 2023, Figure 3); {summary['seconds']:.0f} s"]  # fmt: skip
    for name, res in summary["tasks"].items():
        H = summary["config"]["horizons"][-1]
        lines.append(f"{name}: unconverged steps {res['unconverged_steps']}")
        lines.append(f"  {'smoothing':32s} {'v at H=' + str(H):>12s} {'rate/step':>10s} "
                     f"{'power':>7s}  better fit")  # fmt: skip
        for label, c in res["curves"].items():
            f = c["fit"]
            rate = "n/a" if f["rate_per_step"] is None else f"{f['rate_per_step']:.4f}"
            power = "n/a" if f["power"] is None else f"{f['power']:.2f}"
            lines.append(f"  {label:32s} {c['variance'][-1]:12.3g} {rate:>10s} {power:>7s}  "
                         f"{f.get('better_fit', 'n/a')}")  # fmt: skip
        for h, o in res["mu_ordering"].items():
            ratio = o["ratio_smallest_to_largest_mu"]
            ratio = "n/a" if ratio is None else format(ratio, ".3g")
            lines.append(
                f"  H={h}: BS variance smallest/largest mu = {ratio}; significant "
                f"increases with mu: {o['significant_increases']} of {o['pairs']}"
            )
    return "\n".join(lines)


if __name__ == "__main__":
    print(report(run(Config.test_size(), "results/locomotion-variance-test")))
