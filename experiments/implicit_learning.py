"""Learning the ground height of a falling point mass with the explicit, naive-implicit and
violation-implicit losses (Bianchini et al. 2022: Table 1, Figure 1, Figure 3), computed from
drake-abs's implementation (:mod:`drake_abs.learning`).

1. **Table 1**: the Lipschitz constants of the toy in closed form (our derivation), measured
   from the implementation (largest difference quotients over random points of the domain,
   with the solver's implicit derivatives), and as printed in the paper; then the losses'
   constants (their eqs. 11-13) from ours and from the printed table.
2. **Figure 1**: the loss landscapes (mean loss over a data set against theta, shifted to a
   zero minimum) of the prediction loss (explicit = naive implicit here), the violation loss at
   ``eps``, and the prediction loss through the solver at central-path values ``mus`` (larger
   mu: smoother).
3. **Figure 3**: Theorem 1's generalisation bound against data size for the three losses, and
   for the violation loss against the failure probability delta.
4. **Measured generalisation** (not in the paper): for each data size, ``seeds`` training sets
   of noisy data; theta fitted by minimising each loss (a dense grid over ``search`` then a
   bounded scalar refinement, so that the fit's error is statistical, not an optimiser's);
   reported: the error of the recovered height and the gap between the loss on ``test_points``
   fresh points and on the training set. And gradient descent from ground heights off by
   ``starts`` (m), with each loss's gradient, to show what the landscapes mean for training.

Data: heights above the ground uniform in [0, phi_max] except a fraction ``near`` drawn within
one step's travel of the ground (``[0, 2 v_max dt]``; uniform heights put about 1% of the
points in contact), speeds uniform in [-v_max, v_max], the next velocity from the exact model
plus Gaussian noise ``noise`` (m/s). The true height is 0.

Outputs in ``out``: ``table1.csv``, ``figure1_landscapes.png``, ``figure3_bounds.png``,
``generalization.png``, ``summary.json``.
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

from drake_abs.experiments.outputs import file_list, progress, results_dir
from drake_abs.learning.generalization import (
    PAPER_TABLE_1,
    generalization_bound,
    lipschitz_table,
    loss_lipschitz,
    measured_lipschitz,
    toy_bounds,
)
from drake_abs.learning.ground_toy import GroundToy

NAME = "implicit-learning"
LOSSES = ("explicit", "violation")


@dataclass(frozen=True)
class Config:
    """Sizes; ``eps`` is the violation loss's relaxation (larger: looser complementarity),
    ``mus`` the central-path values of the smoothed prediction losses (larger: smoother)."""

    eps: float = 0.25
    mus: tuple[float, ...] = (1e-5, 1e-3)
    near: float = 0.5
    noise: float = 0.05
    landscape_points: int = 2000
    landscape_range: float = 0.1
    landscape_steps: int = 401
    sizes: tuple[int, ...] = (10, 30, 100, 300, 1000, 3000)
    seeds: int = 20
    test_points: int = 20000
    search: float = 0.1
    starts: tuple[float, ...] = (-0.05, -0.02, 0.02, 0.05)
    descent_steps: int = 200
    descent_points: int = 300
    lipschitz_points: int = 20000
    bound_sizes: tuple[float, ...] = (1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10)
    delta: float = 0.05
    seed: int = 0

    @classmethod
    def test_size(cls) -> Config:
        return cls(landscape_points=200, landscape_steps=81, sizes=(10, 100), seeds=3,
                   test_points=2000, descent_steps=30, descent_points=100,
                   lipschitz_points=2000)  # fmt: skip


def sample(toy: GroundToy, rng, n: int, config: Config):
    """n data points (z, v, y) at true height 0 (module docstring)."""
    z, v, y = toy.sample(rng, n, 0.0, config.noise)
    near = rng.random(n) < config.near
    z[near] = rng.uniform(0.0, 2 * toy.v_max * toy.dt, near.sum())
    y[near] = toy.f(0.0, z[near], v[near]) + config.noise * rng.standard_normal(near.sum())
    return z, v, y


def mean_loss(toy: GroundToy, kind: str, theta: float, data, config: Config, mu: float = 0.0):
    """Mean loss and its derivative in theta over a data set; kind "explicit" (through the
    solver at mu; mu = 0 is also the naive-implicit loss) or "violation"."""
    z, v, y = data
    if kind == "explicit":
        loss, grad, ok = toy.explicit_loss(theta, z, v, y, mu)
        if not ok.all():
            raise RuntimeError(f"{(~ok).sum()} LCP solves did not converge at theta={theta}")
        return float(loss.mean()), float(grad.mean())
    r = toy.violation_implicit_loss(theta, z, v, y, config.eps)
    if not r.converged.all():
        raise RuntimeError("the violation loss's inner minimisation did not converge")
    return float(r.loss.mean()), float(r.grad[:, 0].mean())


def fit(toy: GroundToy, kind: str, data, config: Config) -> float:
    """The height minimising the mean loss: a grid over [-search, search], then a bounded
    scalar refinement around the best grid point."""
    grid = np.linspace(-config.search, config.search, 201)
    values = [mean_loss(toy, kind, t, data, config)[0] for t in grid]
    k = int(np.argmin(values))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    res = minimize_scalar(lambda t: mean_loss(toy, kind, t, data, config)[0], bounds=(lo, hi),
                          method="bounded", options={"xatol": 1e-9})  # fmt: skip
    return float(res.x) if res.fun <= values[k] else float(grid[k])


def descend(toy: GroundToy, kind: str, data, theta0: float, config: Config) -> float:
    """Gradient descent with a normalised step (so that the losses' scales do not matter):
    ``theta -= step * sign(grad)``, step halving on a sign change, from 5 mm."""
    theta, step, last = theta0, 5e-3, 0.0
    for _ in range(config.descent_steps):
        _, g = mean_loss(toy, kind, theta, data, config)
        if g == 0.0:
            break  # a flat landscape: no information
        s = np.sign(g)
        if last and s != last:
            step *= 0.5
        theta -= step * s
        last = s
    return theta


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    config = config or Config()
    out = results_dir(NAME, out)
    start = time.perf_counter()
    toy = GroundToy()
    rng = np.random.default_rng(config.seed)
    eps = config.eps
    bounds = toy_bounds(toy, eps)
    ours = lipschitz_table(toy, eps)
    measured = measured_lipschitz(toy, eps, rng, config.lipschitz_points)
    table = [{"constant": k, "ours_closed_form": ours[k], "ours_measured": measured[k],
              "paper": PAPER_TABLE_1[k]} for k in ours]  # fmt: skip
    lip_ours = loss_lipschitz(ours, bounds, eps)
    lip_paper = loss_lipschitz(PAPER_TABLE_1, bounds, eps)

    # Figure 1: landscapes
    data = sample(toy, rng, config.landscape_points, config)
    thetas = np.linspace(-config.landscape_range, config.landscape_range, config.landscape_steps)
    curves = {"explicit (= naive implicit)": [mean_loss(toy, "explicit", t, data, config)[0]
                                              for t in thetas]}  # fmt: skip
    curves[f"violation implicit, eps = {eps:g}"] = [
        mean_loss(toy, "violation", t, data, config)[0] for t in thetas
    ]
    for mu in config.mus:
        curves[f"explicit through the solver, mu = {mu:g}"] = [
            mean_loss(toy, "explicit", t, data, config, mu)[0] for t in thetas
        ]
    # zeroed (minimum 0) and, for comparing shapes across losses of different units, divided by
    # the largest value on the interval
    landscapes = {k: (np.array(v) - min(v)).tolist() for k, v in curves.items()}
    shapes = {k: (np.array(v) / max(max(v), 1e-300)).tolist() for k, v in landscapes.items()}
    argmins = {k: float(thetas[int(np.argmin(v))]) for k, v in curves.items()}

    # Figure 3: bounds
    sizes = np.array(config.bound_sizes)
    bound_curves = {kind: generalization_bound(lip_ours[kind], bounds.B_theta,
                                               bounds.B_vimp if kind == "vimp" else bounds.B_exp,
                                               sizes, delta=config.delta).tolist()
                    for kind in ("exp", "nimp", "vimp")}  # fmt: skip
    bound_curves["vimp (paper's Table 1)"] = generalization_bound(
        lip_paper["vimp"], bounds.B_theta, bounds.B_vimp, sizes, delta=config.delta
    ).tolist()
    deltas = np.logspace(-6, -0.5, 12)
    vimp_delta = [float(generalization_bound(lip_ours["vimp"], bounds.B_theta, bounds.B_vimp,
                                             1e6, delta=d)) for d in deltas]  # fmt: skip

    # measured generalisation and gradient descent
    test = sample(toy, rng, config.test_points, config)
    measured_gen = {kind: {"theta_error": [], "gap": []} for kind in LOSSES}
    bar = progress(total=len(config.sizes) * config.seeds, desc=f"{NAME}: fits")
    for n in config.sizes:
        errs = {kind: [] for kind in LOSSES}
        gaps = {kind: [] for kind in LOSSES}
        for _ in range(config.seeds):
            train = sample(toy, rng, n, config)
            for kind in LOSSES:
                theta = fit(toy, kind, train, config)
                errs[kind].append(abs(theta))
                gaps[kind].append(mean_loss(toy, kind, theta, test, config)[0]
                                  - mean_loss(toy, kind, theta, train, config)[0])  # fmt: skip
            bar.update()
        for kind in LOSSES:
            measured_gen[kind]["theta_error"].append(float(np.median(errs[kind])))
            measured_gen[kind]["gap"].append(float(np.median(gaps[kind])))
    bar.close()
    descent_data = sample(toy, rng, config.descent_points, config)
    descent = {kind: {f"{t0:+g}": descend(toy, kind, descent_data, t0, config)
                      for t0 in config.starts} for kind in LOSSES}  # fmt: skip

    files = {"table1": out / "table1.csv", "summary": out / "summary.json"}
    with files["table1"].open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(table[0]))
        writer.writeheader()
        writer.writerows(table)
    files.update(_plots(out, thetas, shapes, sizes, bound_curves, deltas, vimp_delta,
                        config, measured_gen))  # fmt: skip
    summary = {
        "config": asdict(config), "toy": asdict(toy), "lambda_max": toy.lambda_max,
        "bounds": asdict(bounds), "table1": table,
        "loss_lipschitz": {"ours": lip_ours, "paper_table": lip_paper},
        "landscape_thetas": thetas.tolist(), "landscapes": landscapes,
        "landscape_argmin": argmins, "bound_sizes": sizes.tolist(), "bounds_vs_n": bound_curves,
        "data_ratio_exp_over_vimp": {
            "ours": _data_ratio(lip_ours, bounds, 1e4, config.delta),
            "paper_table": _data_ratio(lip_paper, bounds, 1e4, config.delta),
        },
        "measured_generalization": {"sizes": list(config.sizes), **measured_gen},
        "descent_final_theta": descent, "seconds": time.perf_counter() - start,
        "folder": str(out),
    }  # fmt: skip
    summary["files"] = file_list(files)
    files["summary"].write_text(json.dumps(summary, indent=1))
    return summary


def _data_ratio(lip: dict, bounds, n0: float, delta: float) -> float:
    """How many times more data than ``n0`` the explicit loss's bound needs to fall to the
    violation loss's bound at ``n0`` (the bounds fall monotonically in n: bisection in log n)."""
    from scipy.optimize import brentq

    target = float(generalization_bound(lip["vimp"], bounds.B_theta, bounds.B_vimp, n0,
                                        delta=delta))  # fmt: skip

    def gap(log_n):
        return float(generalization_bound(lip["exp"], bounds.B_theta, bounds.B_exp,
                                          np.exp(log_n), delta=delta)) - target  # fmt: skip

    return float(np.exp(brentq(gap, np.log(n0), np.log(n0) + 60.0)) / n0)


def _plots(out, thetas, landscapes, sizes, bound_curves, deltas, vimp_delta, config, gen):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = {}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for label, y in landscapes.items():
        axes[0].plot(thetas * 100, y, label=label)
    axes[0].set(xlabel="ground height theta (cm; true 0)",
                ylabel="(mean loss - minimum) / largest value shown")  # fmt: skip
    zoom = np.abs(thetas) <= 0.02
    for label, y in landscapes.items():
        y = np.array(y)[zoom]
        axes[1].plot(thetas[zoom] * 100, y / max(y.max(), 1e-300), label=label)
    axes[1].set(xlabel="theta (cm), zoomed (each curve rescaled on this interval)")
    axes[0].legend(fontsize=7)
    fig.suptitle("Loss landscapes of the 1-D toy (Bianchini et al. 2022, Fig. 1)")
    fig.tight_layout()
    paths["figure1_landscapes"] = out / "figure1_landscapes.png"
    fig.savefig(paths["figure1_landscapes"], dpi=130)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for label, y in bound_curves.items():
        axes[0].loglog(sizes, y, label=label)
    axes[0].set(xlabel="data points n", ylabel=f"bound on generalisation error (delta = "
                f"{config.delta:g})")  # fmt: skip
    axes[0].legend(fontsize=8)
    axes[1].semilogx(deltas, vimp_delta)
    axes[1].set(xlabel="failure probability delta", ylabel="violation-loss bound at n = 1e6")
    fig.suptitle("Theorem 1 on the toy (Bianchini et al. 2022, Fig. 3)")
    fig.tight_layout()
    paths["figure3_bounds"] = out / "figure3_bounds.png"
    fig.savefig(paths["figure3_bounds"], dpi=130)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for kind in LOSSES:
        axes[0].loglog(config.sizes, gen[kind]["theta_error"], "o-", label=kind)
        axes[1].semilogx(config.sizes, gen[kind]["gap"], "o-", label=kind)
    axes[0].set(xlabel="training points n", ylabel="median |theta_hat - theta*| (m)")
    axes[1].set(xlabel="training points n", ylabel="median test loss - training loss")
    axes[0].legend()
    fig.suptitle(f"Measured generalisation (noise {config.noise:g} m/s, {config.seeds} sets "
                 "per size)")  # fmt: skip
    fig.tight_layout()
    paths["generalization"] = out / "generalization.png"
    fig.savefig(paths["generalization"], dpi=130)
    plt.close(fig)
    return paths


def report(summary: dict) -> str:
    lines = ["Learning the ground height (Bianchini et al. 2022), Table 1:",
             f"  {'constant':22s} {'ours':>10s} {'measured':>10s} {'paper':>10s}"]  # fmt: skip
    for row in summary["table1"]:
        flag = (
            "" if np.isclose(row["ours_closed_form"], row["paper"], rtol=2e-3) else "  <- differs"
        )
        lines.append(f"  {row['constant']:22s} {row['ours_closed_form']:10.4g} "
                     f"{row['ours_measured']:10.4g} {row['paper']:10.4g}{flag}")  # fmt: skip
    lo, lp = summary["loss_lipschitz"]["ours"], summary["loss_lipschitz"]["paper_table"]
    lines.append("  loss Lipschitz constants (eqs. 11-13), ours / from the printed table: "
                 + ", ".join(f"{k} {lo[k]:.4g} / {lp[k]:.4g}" for k in lo))  # fmt: skip
    ratio = summary["data_ratio_exp_over_vimp"]
    lines.append(f"  to match the violation bound at n = 1e4, the explicit bound needs "
                 f"{ratio['ours']:.3g} times the data (from the printed table: "
                 f"{ratio['paper_table']:.3g})")  # fmt: skip
    gen = summary["measured_generalization"]
    for kind in LOSSES:
        lines.append(f"  {kind:9s} median |theta error| by n {gen['sizes']}: "
                     + ", ".join(f"{e:.2e}" for e in gen[kind]["theta_error"]))  # fmt: skip
    lines.append(f"  gradient descent from {list(summary['descent_final_theta']['explicit'])}: "
                 + "; ".join(f"{k}: " + ", ".join(f"{t:+.4f}" for t in v.values())
                             for k, v in summary["descent_final_theta"].items()))  # fmt: skip
    lines.append(f"  {summary['seconds']:.0f} s; results in {summary['folder']}")
    return "\n".join(lines)


if __name__ == "__main__":
    print(report(run(Config.test_size(), "results/implicit-learning-test")))
