"""FOPG gradient variance against unroll length (Zhang et al. 2023, section 8.2, Figure 3), with
the bias
beside it.

The task, "the hopping ball": the 2-D point mass of Zhang et al. 2023, Figure 1a
(:func:`point_mass_lcs`,
h = 0.01 s, 1 kg, inelastic hard contact with the ground) under a linear policy that is a
vertical spring ``u_y = -k_s (p_y - y_eq)`` (k_s = 100 N/m, y_eq = 0.1 m) plus Gaussian action
noise ``sigma xi_t`` (sigma = 1 N on both axes). Dropped from 0.3 m, moving sideways at 0.5 m/s,
the ball hops: the spring lifts it off the ground and it lands again about every 0.6 s, so the
number of impacts grows with the horizon. The reward tracks p_y = 0.2 m. theta = (K (2 x 4), k
(2)) is fixed at the spring; nothing is trained here.

For each horizon H and smoothing policy (Exact, BS with fixed mu over several decades, ABS
contact-aware, ABS Gaussian-matched; the adaptive ones in both gradient modes) the FOPG variance
``v = E||g - E g||^2`` is measured from repeated independent batches of M rollouts
(:func:`drake_abs.policy.gradient_stats.variance_bias_sweep`; every policy at one H sees the same
noise), and the bias against the exact objective's reference gradient (first- and zeroth-order,
many samples, see :func:`drake_abs.policy.gradient_stats.reference_gradient`).

Per policy, two fits of the measured variance over H >= ``fit_from``: exponential
(``log v = a + r H``, the paper's claim; r per step) and power law (``log v = a + p log H``);
the residuals say which describes the data better. The paper's second claim, "the variance
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

from drake_abs import point_mass_lcs
from drake_abs.contact.lcs import LcsStepper
from drake_abs.contact.smoothing import ContactAware, Exact, Fixed, GaussianMatched, SmoothingPolicy
from drake_abs.experiments._common import file_list, progress, readable, results_dir
from drake_abs.policy.estimators import PolicyObjective
from drake_abs.policy.gradient_stats import fopg, variance_bias_sweep
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward

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
        return cls(
            horizons=(10, 50, 100),
            fixed_mus=(1e-10, 1e-4, 1e-1),
            samples=16,
            batches=6,
            reference_samples=256,
            reference_batches=8,
        )


TIME_STEP = 0.01
SPRING = 100.0  # N/m
Y_EQ = 0.1  # m
X0 = (0.0, 0.3, 0.5, 0.0)  # (p_x, p_y, v_x, v_y)
Y_GOAL = 0.2  # m


def hopping_ball(
    smoothing: SmoothingPolicy, mode: str = "frozen", horizon: int = 200, sigma: float = 1.0
) -> PolicyObjective:
    """The hopping-ball objective (see the module docstring) under ``smoothing``."""
    lcs = point_mass_lcs(2, time_step=TIME_STEP)
    reward = QuadraticReward(
        Q=np.diag([0.0, 1.0, 0.0, 0.0]),
        R=np.zeros((2, 2)),
        x_goal=np.array([0.0, Y_GOAL, 0.0, 0.0]),
    )
    policy = LinearPolicy(4, 2)
    return PolicyObjective(
        LcsStepper(lcs, smoothing, mode), policy, reward, np.array(X0), horizon, sigma
    )


def spring_theta() -> np.ndarray:
    """theta of ``u = (0, -k_s (p_y - y_eq))``: K row-major (2 x 4), then k (2)."""
    theta = np.zeros(10)
    theta[4 + 1] = -SPRING
    theta[9] = SPRING * Y_EQ
    return theta


def policies(config: Config) -> dict[str, SmoothingPolicy]:
    out: dict[str, SmoothingPolicy] = {"exact": Exact()}
    out.update({f"BS mu={mu:g}": Fixed(mu) for mu in config.fixed_mus})
    out["ABS contact-aware"] = ContactAware(*config.contact_aware)
    out["ABS Gaussian-matched"] = GaussianMatched(config.gaussian_sigma)
    return out


def fit_growth(horizons, variances) -> dict:
    """Least-squares fits of log v against H (exponential) and against log H (power law)."""
    H = np.asarray(horizons, float)
    lv = np.log(np.asarray(variances, float))
    if H.size < 3:
        return {"points": int(H.size), "rate_per_step": None, "power": None}
    rate, a = np.polyfit(H, lv, 1)
    power, b = np.polyfit(np.log(H), lv, 1)
    rms_exp = float(np.sqrt(np.mean((lv - (a + rate * H)) ** 2)))
    rms_pow = float(np.sqrt(np.mean((lv - (b + power * np.log(H))) ** 2)))
    return {
        "points": int(H.size),
        "rate_per_step": float(rate),
        "rate_per_second": float(rate / TIME_STEP),
        "rms_log_residual_exponential": rms_exp,
        "power": float(power),
        "rms_log_residual_power_law": rms_pow,
        "better_fit": "exponential" if rms_exp < rms_pow else "power law",
    }


def curve_label(row: dict) -> str:
    return row["policy"] if row["modes_coincide"] else f"{row['policy']} ({row['mode']})"


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Measure the variance (and bias) sweep; write the figures and summary.json to ``out``
    (default results/gradient-variance); ``summary["files"]`` lists them (absolute paths)."""
    config = config or Config()
    out = results_dir(NAME, out)
    start = time.perf_counter()
    theta = spring_theta()
    pols = policies(config)
    points = len(config.horizons) * sum(1 if p.is_constant else len(MODES) for p in pols.values())
    bar = progress(total=points, desc="gradient-variance: points")

    def tick(line: str) -> None:
        bar.set_postfix_str(line)
        bar.update()

    rows = variance_bias_sweep(
        lambda pol, mode, H: hopping_ball(pol, mode, H, config.sigma),
        theta,
        pols,
        config.horizons,
        batches=config.batches,
        seed=config.seed,
        estimator=fopg(config.samples),
        modes=MODES,
        reference_samples=config.reference_samples or None,
        reference_batches=config.reference_batches,
        progress=tick,
    )
    bar.close()
    curves: dict[str, dict] = {}
    for row in rows:
        c = curves.setdefault(curve_label(row), {"horizon": [], "variance": [], "variance_se": []})
        c["horizon"].append(row["horizon"])
        c["variance"].append(row["trace_variance"])
        c["variance_se"].append(row["trace_variance_se"])
        c.setdefault("largest_batch_share", []).append(row["largest_batch_share"])
        if "bias" in row:
            c.setdefault("bias", []).append(row["bias"]["bias"])
            c.setdefault("bias_noise", []).append(row["bias"]["noise"])
    for c in curves.values():
        keep = [i for i, h in enumerate(c["horizon"]) if h >= config.fit_from]
        c["fit"] = fit_growth([c["horizon"][i] for i in keep], [c["variance"][i] for i in keep])
    ordering = _mu_ordering(rows, config)
    summary = {
        "config": asdict(config),
        "task": {
            "time_step_s": TIME_STEP,
            "spring_N_per_m": SPRING,
            "y_eq_m": Y_EQ,
            "x0": X0,
            "y_goal_m": Y_GOAL,
            "theta": theta.tolist(),
        },  # fmt: skip
        "curves": curves,
        "mu_ordering": ordering,
        "unconverged_steps": int(sum(r["unconverged_steps"] for r in rows)),
        "rows": rows,
        "seconds": time.perf_counter() - start,
    }
    files = {
        "figure3": _plot_variance(curves, out / "figure3_variance.png"),
        "summary": out / "summary.json",
    }
    if config.reference_samples:
        files["bias"] = _plot_bias(curves, out / "bias.png")
    summary["folder"] = str(out)
    summary["files"] = file_list(files)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def _mu_ordering(rows: list[dict], config: Config) -> dict:
    return mu_ordering(rows, config.horizons)


def mu_ordering(rows: list[dict], horizons) -> dict:
    """Per horizon: is the BS variance non-increasing in mu? Counts adjacent pairs (in mu order)
    where the larger mu has the larger variance by more than 2 standard errors."""
    out = {}
    for H in horizons:
        series = [
            r for r in rows
            if r["horizon"] == H and r["policy"].startswith("BS mu=")
        ]  # fmt: skip
        series.sort(key=lambda r: float(r["policy"].split("=")[1]))
        violations = 0
        for a, b in zip(series, series[1:], strict=False):
            se = np.hypot(a["trace_variance_se"], b["trace_variance_se"])
            violations += int(b["trace_variance"] - a["trace_variance"] > 2 * se)
        v = [r["trace_variance"] for r in series]
        out[str(H)] = {
            "pairs": max(len(series) - 1, 0),
            "significant_increases": violations,
            "ratio_smallest_to_largest_mu": v[0] / v[-1] if v else None,
        }
    return out


def line_style(name: str, names: list[str]) -> dict:
    """Line style: black for exact, a colour ramp over the BS mus (ordered), one colour per ABS
    design, dashed for the total gradient mode."""
    import matplotlib

    bs = [n for n in names if n.startswith("BS mu=")]
    if name.startswith("BS mu="):
        color = matplotlib.colormaps["viridis"](bs.index(name) / max(len(bs) - 1, 1))
    elif name.startswith("ABS contact-aware"):
        color = "tab:red"
    elif name.startswith("ABS Gaussian-matched"):
        color = "tab:orange"
    else:
        color = "black"
    return {"color": color, "linestyle": "--" if "(total)" in name else "-"}


def _plot_variance(curves: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5))
    for name, c in curves.items():
        ax.errorbar(
            c["horizon"], c["variance"], yerr=c["variance_se"], marker="o", ms=3,
            label=readable(name),
            capsize=2, **line_style(name, list(curves)),
        )  # fmt: skip
    ax.set(
        xlabel="unroll length H (steps of 0.01 s)",
        ylabel="FOPG gradient variance E||g - Eg||^2",
        yscale="log",
        title="Hopping ball: FOPG variance against horizon (Zhang et al. 2023, Fig. 3)",
    )
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def _plot_bias(curves: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5))
    for name, c in curves.items():
        H = np.array(c["horizon"], float)
        b = np.array([np.nan if x is None else x for x in c["bias"]], float)
        style = line_style(name, list(curves))
        ax.plot(H, b, marker="o", ms=3, label=readable(name), **style)
        unresolved = np.isnan(b)
        ax.scatter(
            H[unresolved], 2 * np.array(c["bias_noise"])[unresolved], marker="v",
            color=style["color"], s=14,
        )  # fmt: skip
    ax.set(
        xlabel="unroll length H (steps of 0.01 s)",
        ylabel="bias ||E g - grad J_exact||",
        yscale="log",
        title="FOPG bias against the exact reference (triangles: unresolved, < 2 noise)",
    )
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def report(summary: dict) -> str:
    lines = [
        "FOPG gradient variance against horizon, hopping ball (Zhang et al. 2023, Figure 3); "
        f"{summary['seconds']:.0f} s, unconverged steps {summary['unconverged_steps']}",
        f"{'policy':34s} {'v at H=' + str(summary['config']['horizons'][-1]):>12s} "
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
