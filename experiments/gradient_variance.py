"""FOPG gradient variance against unroll length (Zhang et al. 2023, section 8.2, Figure 3), with
the bias beside it.

The task is the hopping ball (:mod:`drake_abs.tasks.hopping_ball`: the 2-D point mass, h = 0.01
s, inelastic hard contact, under the spring policy ``u_y = -k_s (p_y - y_eq)`` plus Gaussian
action noise sigma = 1 N; the number of impacts grows with the horizon). theta is fixed at the
spring; nothing is trained here.

For each horizon H and smoothing (Exact, BS with fixed mu over several decades, ABS
contact-aware, ABS Gaussian-matched; the adaptive ones in both gradient modes) the FOPG variance
``v = E||g - E g||^2`` is measured from repeated independent batches of M rollouts
(:func:`drake_abs.policy.gradient_stats.variance_bias_sweep`; every smoothing at one H sees the
same noise), and the bias against the exact objective's reference gradient (first- and
zeroth-order, many samples, see :func:`drake_abs.policy.gradient_stats.reference_gradient`).

Per smoothing, two fits of the measured variance over H >= ``fit_from``
(:func:`drake_abs.policy.variance_growth.fit_growth`): exponential (the paper's claim) and power
law; the residuals say which describes the data better. The paper's second claim, "the variance
decreases as mu increases", is checked at every horizon over the fixed-mu (BS) series.

Outputs in ``out``: ``figure3_variance.png`` (variance against H, log scale), ``bias.png`` (bias
against H), ``summary.json``.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.experiments.outputs import file_list, progress, readable, results_dir
from drake_abs.policy import variance_growth as vg
from drake_abs.policy.gradient_stats import fopg, variance_bias_sweep
from drake_abs.tasks import hopping_ball as ball

NAME = "gradient-variance"
MODES = ("frozen", "total")  # the gradient modes measured (variance_bias_sweep's default)


@dataclass(frozen=True)
class Config:
    """Sizes. ``fixed_mus`` are the BS values (larger is smoother); ``samples`` rollouts per
    estimate, ``batches`` independent estimates per point, ``reference_samples`` rollouts per
    reference estimator (0: no bias)."""

    horizons: tuple[int, ...] = (10, 25, 50, 100, 150, 200, 300, 400, 600)
    fixed_mus: tuple[float, ...] = (1e-10, 1e-8, 1e-6, 1e-4, 1e-3, 1e-2, 1e-1)
    contact_aware: tuple[float, float] = (1e-2, 0.05)  # (mu_max, length in m)
    gaussian_sigma: float = 0.02  # m
    samples: int = 64
    batches: int = 30
    reference_samples: int = 8192
    reference_batches: int = 16
    fit_from: int = 50
    sigma: float = 1.0
    seed: int = 0

    @classmethod
    def test_size(cls) -> Config:
        return cls(horizons=(10, 50, 100), fixed_mus=(1e-10, 1e-4, 1e-1), samples=16, batches=6,
                   reference_samples=256, reference_batches=8)  # fmt: skip


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Measure the variance (and bias) sweep; write the figures and summary.json to ``out``
    (default results/gradient-variance); ``summary["files"]`` lists them (absolute paths)."""
    config = config or Config()
    out = results_dir(NAME, out)
    start = time.perf_counter()
    theta = ball.spring_theta()
    designs = vg.sweep_smoothings(config.fixed_mus, config.contact_aware, config.gaussian_sigma)
    points = len(config.horizons) * sum(1 if p.is_constant else len(MODES)
                                        for p in designs.values())  # fmt: skip
    bar = progress(total=points, desc="gradient-variance: points")

    def tick(line: str) -> None:
        bar.set_postfix_str(line)
        bar.update()

    rows = variance_bias_sweep(
        lambda smoothing, mode, H: ball.hopping_ball(smoothing, mode, H, config.sigma), theta,
        designs, config.horizons, batches=config.batches, seed=config.seed,
        estimator=fopg(config.samples), modes=MODES,
        reference_samples=config.reference_samples or None,
        reference_batches=config.reference_batches, progress=tick,
    )  # fmt: skip
    bar.close()

    def extra(row: dict) -> dict:
        bias = {"bias": row["bias"]["bias"], "bias_noise": row["bias"]["noise"]}
        return {"largest_batch_share": row["largest_batch_share"]} | (bias if "bias" in row else {})

    curves = vg.variance_curves(rows, fit_from=config.fit_from, time_step=ball.TIME_STEP,
                             extra=extra)  # fmt: skip
    task = {"time_step_s": ball.TIME_STEP, "spring_N_per_m": ball.SPRING, "y_eq_m": ball.Y_EQ,
            "x0": ball.X0, "y_goal_m": ball.Y_GOAL, "theta": theta.tolist()}  # fmt: skip
    summary = {
        "config": asdict(config), "task": task, "curves": curves,
        "mu_ordering": vg.mu_ordering(rows, config.horizons),
        "unconverged_steps": int(sum(r["unconverged_steps"] for r in rows)), "rows": rows,
        "seconds": time.perf_counter() - start,
    }  # fmt: skip
    files = {"figure3": _plot(curves, out / "figure3_variance.png", "variance"),
             "summary": out / "summary.json"}  # fmt: skip
    if config.reference_samples:
        files["bias"] = _plot(curves, out / "bias.png", "bias")
    summary["folder"] = str(out)
    summary["files"] = file_list(files)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def _plot(curves: dict, path: Path, what: str) -> Path:
    """Variance (with standard errors) or bias (unresolved points as triangles at twice the
    noise) against H, one line per curve."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5))
    for name, c in curves.items():
        style = vg.curve_style(name, list(curves), matplotlib.colormaps["viridis"])
        H = np.array(c["horizon"], float)
        if what == "variance":
            ax.errorbar(H, c["variance"], yerr=c["variance_se"], marker="o", ms=3, capsize=2,
                        label=readable(name), **style)  # fmt: skip
            continue
        b = np.array([np.nan if x is None else x for x in c["bias"]], float)
        ax.plot(H, b, marker="o", ms=3, label=readable(name), **style)
        gone = np.isnan(b)
        ax.scatter(H[gone], 2 * np.array(c["bias_noise"])[gone], marker="v", s=14,
                   color=style["color"])  # fmt: skip
    title = {
        "variance": "Hopping ball: FOPG variance against horizon (Zhang et al. 2023, Fig. 3)",
        "bias": "FOPG bias against the exact reference (triangles: unresolved, < 2 noise)",
    }
    ylabel = {"variance": "FOPG gradient variance E||g - Eg||^2",
              "bias": "bias ||E g - grad J_exact||"}  # fmt: skip
    ax.set(xlabel="unroll length H (steps of 0.01 s)", ylabel=ylabel[what], yscale="log",
           title=title[what])  # fmt: skip
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def report(summary: dict) -> str:
    lines = [
        "FOPG gradient variance against horizon, hopping ball (Zhang et al. 2023, Figure 3); "
        f"{summary['seconds']:.0f} s, unconverged steps {summary['unconverged_steps']}",
        f"{'smoothing':34s} {'v at H=' + str(summary['config']['horizons'][-1]):>12s} "
        f"{'rate/step':>10s} {'power':>7s}  {'better fit':11s} {'bias at H':>10s} "
        "largest-batch share",
    ]
    for name, c in summary["curves"].items():
        f = c["fit"]
        rate = "n/a" if f["rate_per_step"] is None else f"{f['rate_per_step']:.4f}"
        power = "n/a" if f["power"] is None else f"{f['power']:.2f}"
        bias = c.get("bias", [None])[-1]
        bias = "unresolved" if bias is None else f"{bias:.3g}"
        lines.append(
            f"{name:34s} {c['variance'][-1]:12.3g} {rate:>10s} {power:>7s}  "
            f"{f.get('better_fit', 'n/a'):11s} {bias:>10s} {c['largest_batch_share'][-1]:.2f}"
        )
    for H, o in summary["mu_ordering"].items():
        lines.append(
            f"H={H}: BS variance, smallest/largest mu = {o['ratio_smallest_to_largest_mu']:.3g}; "
            f"significant increases with mu: {o['significant_increases']} of {o['pairs']} pairs"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    print(report(run(Config.test_size(), "results/gradient-variance-test")))
