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

The data, losses, fits and descent are :mod:`drake_abs.learning.ground_height_fit`.
Outputs in ``out``: ``table1.csv``, ``figure1_landscapes.png``, ``figure3_bounds.png``,
``generalization.png``, ``summary.json``.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs._validation import as_count, check_counts
from drake_abs.experiments.outputs import (
    file_list,
    progress,
    pyplot,
    results_dir,
    save_figure,
    write_csv,
    write_json,
)
from drake_abs.learning import generalization as gb
from drake_abs.learning import ground_height_fit as fit
from drake_abs.learning.ground_toy import GroundToy

NAME = "implicit-learning"
LOSSES = fit.KINDS


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

    def __post_init__(self):
        # an impossible count is refused here, before any work (a sweep point that ran with
        # seeds=0 used to finish "done" with a NaN metric)
        check_counts(self, ("landscape_points", "landscape_steps", "sizes", "seeds",
                            "test_points", "descent_steps", "descent_points",
                            "lipschitz_points"))  # fmt: skip
        as_count(self.seed, "seed", minimum=0)

    @classmethod
    def test_size(cls) -> Config:
        return cls(landscape_points=200, landscape_steps=81, sizes=(10, 100), seeds=3,
                   test_points=2000, descent_steps=30, descent_points=100,
                   lipschitz_points=2000)  # fmt: skip


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    config = config or Config()
    out = results_dir(NAME, out)
    start = time.perf_counter()
    toy = GroundToy()
    rng = np.random.default_rng(config.seed)
    eps, delta = config.eps, config.delta

    def sample(n):
        return fit.sample_near_ground(toy, rng, n, noise=config.noise, near=config.near)

    bounds = gb.toy_bounds(toy, eps)
    ours = gb.lipschitz_table(toy, eps)
    measured = gb.measured_lipschitz(toy, eps, rng, config.lipschitz_points)
    table = [{"constant": k, "ours_closed_form": ours[k], "ours_measured": measured[k],
              "paper": gb.PAPER_TABLE_1[k]} for k in ours]  # fmt: skip
    lip_ours = gb.loss_lipschitz(ours, bounds, eps)
    lip_paper = gb.loss_lipschitz(gb.PAPER_TABLE_1, bounds, eps)

    # Figure 1: landscapes, zeroed (minimum 0) and, for comparing shapes across losses of
    # different units, divided by the largest value on the interval
    data = sample(config.landscape_points)
    thetas = np.linspace(-config.landscape_range, config.landscape_range, config.landscape_steps)
    losses = {"explicit (= naive implicit)": ("explicit", 0.0),
              f"violation implicit, eps = {eps:g}": ("violation", 0.0),
              **{f"explicit through the solver, mu = {mu:g}": ("explicit", mu)
                 for mu in config.mus}}  # fmt: skip
    curves = {k: fit.loss_landscape(toy, kind, thetas, data, eps=eps, mu=mu)
              for k, (kind, mu) in losses.items()}  # fmt: skip
    landscapes = {k: (v - v.min()).tolist() for k, v in curves.items()}
    shapes = {k: (np.array(v) / max(max(v), 1e-300)).tolist() for k, v in landscapes.items()}
    argmins = {k: float(thetas[int(np.argmin(v))]) for k, v in curves.items()}

    # Figure 3: bounds
    def bound(lip, kind, n, d=delta):
        B = bounds.B_vimp if kind == "vimp" else bounds.B_exp
        return gb.generalization_bound(lip[kind], bounds.B_theta, B, n, delta=d)

    sizes = np.array(config.bound_sizes)
    bound_curves = {kind: bound(lip_ours, kind, sizes).tolist() for kind in ("exp", "nimp", "vimp")}
    bound_curves["vimp (paper's Table 1)"] = bound(lip_paper, "vimp", sizes).tolist()
    deltas = np.logspace(-6, -0.5, 12)
    vimp_delta = [float(bound(lip_ours, "vimp", 1e6, d)) for d in deltas]

    # measured generalisation (medians over the training sets of each size) and gradient descent
    test = sample(config.test_points)
    errs = {kind: np.zeros((len(config.sizes), config.seeds)) for kind in LOSSES}
    gaps = {kind: np.zeros((len(config.sizes), config.seeds)) for kind in LOSSES}
    bar = progress(total=len(config.sizes) * config.seeds, desc=f"{NAME}: fits")
    for i, n in enumerate(config.sizes):
        for j in range(config.seeds):
            train = sample(n)
            for kind in LOSSES:
                theta = fit.fit_height(toy, kind, train, eps=eps, search=config.search)
                errs[kind][i, j] = abs(theta)
                on_test, on_train = (fit.mean_loss(toy, kind, theta, d, eps=eps)[0]
                                     for d in (test, train))  # fmt: skip
                gaps[kind][i, j] = on_test - on_train
            bar.update()
    bar.close()
    measured_gen = {kind: {"theta_error": np.median(errs[kind], axis=1).tolist(),
                           "gap": np.median(gaps[kind], axis=1).tolist()}
                    for kind in LOSSES}  # fmt: skip
    descent_data = sample(config.descent_points)
    descent = {kind: {f"{t0:+g}": fit.descend_height(toy, kind, descent_data, t0, eps=eps,
                                                     steps=config.descent_steps)
                      for t0 in config.starts} for kind in LOSSES}  # fmt: skip

    files = {"table1": write_csv(out / "table1.csv", table), "summary": out / "summary.json"}
    files.update(_plots(out, thetas, shapes, bound_curves, deltas, vimp_delta, config,
                        measured_gen))  # fmt: skip
    summary = {
        "config": asdict(config), "toy": asdict(toy), "lambda_max": toy.lambda_max,
        "bounds": asdict(bounds), "table1": table,
        "loss_lipschitz": {"ours": lip_ours, "paper_table": lip_paper},
        "landscape_thetas": thetas.tolist(), "landscapes": landscapes,
        "landscape_argmin": argmins, "bound_sizes": sizes.tolist(), "bounds_vs_n": bound_curves,
        "data_ratio_exp_over_vimp": {"ours": gb.data_ratio(lip_ours, bounds, 1e4, delta),
                                     "paper_table": gb.data_ratio(lip_paper, bounds, 1e4, delta)},
        "measured_generalization": {"sizes": list(config.sizes), **measured_gen},
        "descent_final_theta": descent, "seconds": time.perf_counter() - start,
        "folder": str(out),
    }  # fmt: skip
    summary["files"] = file_list(files)
    write_json(files["summary"], summary, indent=1)
    return summary


def _plots(out, thetas, landscapes, bound_curves, deltas, vimp_delta, config, gen):
    plt, paths = pyplot(), {}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    zoom = np.abs(thetas) <= 0.02
    for label, y in landscapes.items():
        axes[0].plot(thetas * 100, y, label=label)
        y = np.array(y)[zoom]
        axes[1].plot(thetas[zoom] * 100, y / max(y.max(), 1e-300), label=label)
    axes[0].set(xlabel="ground height theta (cm; true 0)",
                ylabel="(mean loss - minimum) / largest value shown")  # fmt: skip
    axes[1].set(xlabel="theta (cm), zoomed (each curve rescaled on this interval)")
    axes[0].legend(fontsize=7)
    fig.suptitle("Loss landscapes of the 1-D toy (Bianchini et al. 2022, Fig. 1)")
    paths["figure1_landscapes"] = save_figure(fig, out / "figure1_landscapes.png", dpi=130)

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for label, y in bound_curves.items():
        axes[0].loglog(config.bound_sizes, y, label=label)
    axes[0].set(xlabel="data points n",
                ylabel=f"bound on generalisation error (delta = {config.delta:g})")  # fmt: skip
    axes[0].legend(fontsize=8)
    axes[1].semilogx(deltas, vimp_delta)
    axes[1].set(xlabel="failure probability delta", ylabel="violation-loss bound at n = 1e6")
    fig.suptitle("Theorem 1 on the toy (Bianchini et al. 2022, Fig. 3)")
    paths["figure3_bounds"] = save_figure(fig, out / "figure3_bounds.png", dpi=130)

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for kind in LOSSES:
        axes[0].loglog(config.sizes, gen[kind]["theta_error"], "o-", label=kind)
        axes[1].semilogx(config.sizes, gen[kind]["gap"], "o-", label=kind)
    axes[0].set(xlabel="training points n", ylabel="median |theta_hat - theta*| (m)")
    axes[1].set(xlabel="training points n", ylabel="median test loss - training loss")
    axes[0].legend()
    fig.suptitle(f"Measured generalisation (noise {config.noise:g} m/s, {config.seeds} sets "
                 "per size)")  # fmt: skip
    paths["generalization"] = save_figure(fig, out / "generalization.png", dpi=130)
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
