"""Zhang et al. 2023, section 8.3: learn the angle of a throw so that the ball ends up at a goal,
with contact before the goal; learning curves of ZOPG, FOPG (exact), FOPG-BS and FOPG-ABS.

The task (ours; the paper's Appendix C.2 illustration is not in the text we have),
:mod:`drake_abs.tasks.ball_throw`: a ball of radius 5 cm and 1 kg is thrown from 1 m (its
centre) at a fixed speed of 3 m/s; it lands inelastically on ground with Coulomb friction 0.4,
slides (it translates only) and stops. The policy is the throwing angle; the return is
``-(p_x(T) - goal)^2`` (m^2) at the end of the horizon, when the ball has come to rest; every
throw lands well before the goal, so the contact (the landing impulse and the friction of the
slide) decides where it stops.

Methods (names of :mod:`drake_abs.policy.methods`), each trained with Adam from the same initial
angle and the same five seeds: ``zopg`` (likelihood ratio on the exact model), ``fopg_exact``,
``fopg_bs`` (one fixed mu, ``bs_mu``) and ``fopg_abs`` (contact-aware mu). Every model's
gradient is ``Config.gradient``: "frozen" (mu held, Zhang et al. 2023, Algorithm 1, the method
this experiment reproduces). Every run is evaluated each iteration by the deterministic return
(no exploration) of the exact model, the true objective; the curves are that evaluation against
iterations and against simulated steps. ``summary.json`` and the run logs name the methods by
their registry names (``fopg_abs``), the plots by their labels (``FOPG-ABS``).
"""

from __future__ import annotations

import json
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.contact.lcs import GradientMode
from drake_abs.contact.smoothing import Smoothing
from drake_abs.engine import rollout
from drake_abs.experiments.outputs import file_list, progress, results_dir
from drake_abs.lcp.ipm import LCPConvergenceWarning
from drake_abs.policy.estimators import PolicyObjective
from drake_abs.policy.methods import method
from drake_abs.policy.training import Adam, train
from drake_abs.tasks.ball_throw import throw_objective

NAME = "ball-throw"
METHODS = ("zopg", "fopg_exact", "fopg_bs", "fopg_abs")  # names of drake_abs.policy.methods

#: The claims of Zhang et al. 2023, section 8.3, that this experiment sets ours beside (no
#: numbers are given).
PAPER_CLAIMS = {
    "bs_beats_zopg_and_fopg": "FOPG-BS: higher asymptotic return and faster convergence than "
    "both ZOPG and vanilla FOPG",
    "abs_beats_all": "FOPG-ABS: superior to all the other variants",
}


@dataclass(frozen=True)
class Config:
    """Sizes and parameters. Angles in rad, lengths in m, speeds in m/s, mu in m N s (larger mu
    is more smoothing)."""

    height: float = 1.0
    speed: float = 3.0
    radius: float = 0.05
    mass: float = 1.0
    friction: float = 0.4
    time_step: float = 0.01
    horizon: int = 150
    goal: float = 1.5
    angle0: float = 1.3
    sigma: float = 0.05
    rollouts: int = 32
    iterations: int = 80
    learning_rate: float = 0.02
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    bs_mu: float = 1e-5
    abs_mu_max: float = 1e-3
    abs_length: float = 0.02
    gradient: GradientMode = "frozen"  # Zhang et al. 2023, Algorithm 1
    methods: tuple[str, ...] = METHODS
    landscape_points: int = 301

    @classmethod
    def test_size(cls) -> Config:
        return cls(rollouts=8, iterations=12, learning_rate=0.03, seeds=(0, 1), landscape_points=41)


def smoothing_for(name: str, config: Config) -> Smoothing:
    """The contact smoothing of a method's model (``zopg`` and ``fopg_exact``: exact)."""
    return method(name).make_smoothing(
        mu=config.bs_mu, contact_aware=(config.abs_mu_max, config.abs_length)
    )


def objective(config: Config, smoothing: Smoothing | None = None) -> PolicyObjective:
    """The throw (:func:`~drake_abs.tasks.ball_throw.throw_objective`) with the config's sizes
    and ``config.gradient``, on the model smoothed by ``smoothing`` (default: exact)."""
    sizes = ("height", "speed", "radius", "mass", "friction", "time_step", "horizon", "goal",
             "sigma")  # fmt: skip
    return throw_objective(smoothing, config.gradient, **{k: getattr(config, k) for k in sizes})


def _throws(obj: PolicyObjective, angles: np.ndarray, gradient: bool):
    """One deterministic throw per angle: the angle enters as the first step's input (noise of
    a zero policy), so the return's theta-derivative is its angle-derivative."""
    noise = np.zeros((angles.size, obj.horizon, 1))
    noise[:, 0, 0] = angles
    x0 = np.tile(obj.x0, (angles.size, 1))
    return rollout(obj.stepper, obj.policy, np.zeros(1), x0, noise, obj.reward, sigma=1.0,
                   gradient=gradient)  # fmt: skip


def true_return(config: Config, angles) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic return and resting position p_x(T) of throws at ``angles`` (exact model)."""
    r = _throws(objective(config), np.atleast_1d(np.asarray(angles, float)), gradient=False)
    return r.returns, r.x[:, -1, 0]


def landscape(config: Config, angles: np.ndarray) -> dict:
    """p_x(T) and its pathwise derivative over ``angles`` for the exact, BS and ABS models."""
    out = {}
    for name in ("fopg_exact", "fopg_bs", "fopg_abs"):
        r = _throws(objective(config, smoothing_for(name, config)), angles, gradient=True)
        out[name] = {"p_final": r.x[:, -1, 0].tolist(), "dreturn_dangle": r.grad[:, 0].tolist()}
    return out


def _estimator(name: str, config: Config):
    obj = objective(config, smoothing_for(name, config))
    return lambda th, rng: method(name).estimate(obj, th, rng, config.rollouts)


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Train every method from every seed; write plots, summary.json and per-run logs to
    ``out`` (default results/ball-throw); ``summary["files"]`` lists them (absolute paths)."""
    config = config or Config()
    out = results_dir(NAME, out)
    angles = np.linspace(-0.5, 1.5, config.landscape_points)
    returns, p_final = true_return(config, angles)
    best = int(np.argmax(returns))
    curves, runs = {}, {}
    start_all = time.perf_counter()
    bar = progress(total=len(config.methods) * len(config.seeds), desc="ball-throw: training")
    for name in config.methods:
        estimator = _estimator(name, config)
        evals, steps, unconverged, seconds, finals = [], [], 0, 0.0, []
        for seed in config.seeds:
            bar.set_postfix_str(f"{name}, seed {seed}")
            start = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", LCPConvergenceWarning)  # counted per row
                run_ = train(
                    estimator, np.array([config.angle0]), Adam(lr=config.learning_rate),
                    config.iterations, seed=seed,
                    evaluate=lambda th: float(true_return(config, th[0])[0][0]),
                    log_dir=out / "runs", name=f"{name}_seed{seed}",
                    config={"method": name, **asdict(config)}, progress=False,
                )  # fmt: skip
            seconds += time.perf_counter() - start
            rows = run_.rows
            evals.append([row["eval_return"] for row in rows])
            per_iter = [row["rollouts"] * config.horizon for row in rows[:-1]]
            steps.append(np.concatenate([[0], np.cumsum(per_iter)]).tolist())
            unconverged += sum(row["unconverged_steps"] for row in rows[:-1])
            finals.append(float(run_.theta[0]))
            bar.update()
        ev = np.array(evals)
        final = ev[:, -1]
        curves[name] = {"eval_return": ev.tolist(), "simulated_steps": steps[0]}
        runs[name] = {
            "final_return_mean": float(final.mean()), "final_return_std": float(final.std()),
            "final_returns": final.tolist(), "auc_per_seed": ev.mean(axis=1).tolist(),
            "final_angle_mean": float(np.mean(finals)), "final_angle_std": float(np.std(finals)),
            "iterations_to_threshold": _iterations_to(ev, threshold=-1e-2),
            "area_under_curve": float(ev.mean(axis=0).mean()),
            "unconverged_steps": int(unconverged), "seconds": seconds,
        }  # fmt: skip
    summary = {
        "config": asdict(config), "best_angle_on_grid": float(angles[best]),
        "best_return_on_grid": float(returns[best]),
        "initial_return": float(true_return(config, config.angle0)[0][0]), "methods": runs,
        "claims": _claims(runs), "seconds": time.perf_counter() - start_all,
    }  # fmt: skip
    bar.close()
    files = _plot(out, config, curves, angles, p_final, landscape(config, angles))
    files |= {"curves": out / "curves.json", "runs": out / "runs", "summary": out / "summary.json"}
    summary["folder"] = str(out)
    summary["files"] = file_list(files)
    (out / "curves.json").write_text(json.dumps(curves))
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def _iterations_to(ev: np.ndarray, threshold: float) -> float | None:
    """Mean over seeds of the first iteration whose evaluated return is >= threshold (None if a
    seed never gets there)."""
    hits = [np.flatnonzero(row >= threshold) for row in ev]
    if any(h.size == 0 for h in hits):
        return None
    return float(np.mean([h[0] for h in hits]))


def _better(runs: dict, a: str, b: str, key: str) -> bool:
    """a beats b on ``key`` (per-seed values) by more than twice the standard error of the
    difference of the means (seeds are independent runs)."""
    x, y = np.array(runs[a][key]), np.array(runs[b][key])
    se = np.sqrt(x.var(ddof=1) / x.size + y.var(ddof=1) / y.size) if x.size > 1 else 0.0
    return bool(x.mean() - y.mean() > 2 * se)


def _claims(runs: dict) -> dict:
    """Our verdict on each of the paper's claims: a method is better when its final evaluated
    return and its area under the curve (faster convergence) both beat the other's by more than
    two standard errors over seeds."""
    final = {m: r["final_return_mean"] for m, r in runs.items()}
    auc = {m: r["area_under_curve"] for m, r in runs.items()}

    def beats(a, others):
        return all(_better(runs, a, b, "final_returns") and _better(runs, a, b, "auc_per_seed")
                   for b in others)  # fmt: skip

    out = {}
    if {"zopg", "fopg_exact", "fopg_bs"} <= set(runs):
        out["bs_beats_zopg_and_fopg"] = {
            "paper": PAPER_CLAIMS["bs_beats_zopg_and_fopg"],
            "ours_final": final, "ours_auc": auc,
            "agree": beats("fopg_bs", ["zopg", "fopg_exact"]),
        }  # fmt: skip
    if "fopg_abs" in runs and len(runs) > 1:
        out["abs_beats_all"] = {
            "paper": PAPER_CLAIMS["abs_beats_all"],
            "ours_final": final, "ours_auc": auc,
            "agree": beats("fopg_abs", [m for m in runs if m != "fopg_abs"]),
        }  # fmt: skip
    return out


def _plot(out: Path, config: Config, curves: dict, angles, p_final, land) -> dict[str, Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    for name, c in curves.items():
        ev = np.array(c["eval_return"])
        mean, std = ev.mean(axis=0), ev.std(axis=0)
        for ax, xs in zip(
            axes, (np.arange(ev.shape[1]), np.array(c["simulated_steps"])), strict=True
        ):
            ax.plot(xs, mean, label=method(name).label)
            ax.fill_between(xs, mean - std, mean + std, alpha=0.2)
    axes[0].set(xlabel="iteration", ylabel="return  -(p_x(T) - goal)^2  (m^2)",
                title=f"ball throw: mean and std over {len(config.seeds)} seeds")  # fmt: skip
    axes[1].set(xlabel="simulated steps", ylabel="return (m^2)", title="against simulated steps")
    for ax in axes:
        ax.set_yscale("symlog", linthresh=1e-3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(out / "learning_curves.png", dpi=120)
    plt.close(fig)
    files = {"learning_curves": out / "learning_curves.png"}

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    names = {"fopg_exact": "exact", "fopg_bs": f"barrier smoothing, mu = {config.bs_mu:g}",
             "fopg_abs": f"adaptive (ABS), mu_max = {config.abs_mu_max:g}"}  # fmt: skip
    for name, data in land.items():
        axes[0].plot(angles, data["p_final"], label=names[name])
        axes[1].plot(angles, data["dreturn_dangle"], label=names[name])
    axes[0].axhline(config.goal, color="k", ls=":", label="goal")
    axes[0].set(xlabel="throwing angle (rad)", ylabel="resting position p_x(T) (m)",
                title="where the ball stops")  # fmt: skip
    axes[1].set(xlabel="throwing angle (rad)", ylabel="d return / d angle (m^2/rad)",
                title="pathwise derivative of the return")  # fmt: skip
    for ax in axes:
        ax.legend()
    fig.tight_layout()
    fig.savefig(out / "landscape.png", dpi=120)
    plt.close(fig)
    files["landscape"] = out / "landscape.png"
    return files


def report(summary: dict) -> str:
    lines = [
        "ball throw (Zhang et al. 2023, section 8.3): evaluated return -(p_x(T) - goal)^2 in m^2, "
        f"mean +- std over seeds; best on the angle grid {summary['best_return_on_grid']:.2e} "
        f"at {summary['best_angle_on_grid']:.3f} rad; start {summary['initial_return']:.3f}",
    ]
    for m, r in summary["methods"].items():
        its = r["iterations_to_threshold"]
        lines.append(
            f"  {method(m).label:9s} final {r['final_return_mean']:+.2e} +- "
            f"{r['final_return_std']:.1e}, "
            f"angle {r['final_angle_mean']:.3f} +- {r['final_angle_std']:.3f} rad, "
            f"iterations to -1e-2: {'never (some seed)' if its is None else f'{its:.1f}'}, "
            f"unconverged steps {r['unconverged_steps']}, {r['seconds']:.1f} s"
        )
    for c in summary["claims"].values():
        verdict = "agree" if c["agree"] else "DIFFERENT (not better by > 2 standard errors)"
        lines.append(f"  paper: {c['paper']} -> ours {verdict}")
    return "\n".join(lines)


if __name__ == "__main__":
    print(report(run(Config.test_size(), "results/ball-throw-test")))
