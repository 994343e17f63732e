"""Zhang et al. 2023, Figure 6: barrier smoothing (BS) against randomised smoothing (RS) on impact
contact (a dropped ball) and on frictional contact (a pushed box).

(a) Impact. A ball (:func:`~drake_abs.tasks.point_mass.point_mass_lcs`, 1-D, 1 kg, h = 0.01 s)
starts at height y0 moving down at ``drop_speed``; f(y0) = its vertical velocity after
``impact_steps`` steps. Balls starting below the contact height y_c have landed (v = 0, inelastic),
those above are still falling, so f jumps by dv = -(v0 - g T) at y_c: the ground-truth derivative is
an impulse of mass dv at y_c (in discrete time a ramp of slope -1/h and width ~|v| h) and 0
elsewhere. Compared over a grid of y0:

- GT: the exact model's derivative (the rollout Jacobian, which resolves the ramp).
- BS: the derivative of the model smoothed by ``Fixed(mu)``, several mu (larger is smoother).
- RS, first-order ("bundled", what Zhang et al. (2023) and Suh et al. 2022 call randomised
  smoothing): ``(1/N) sum_i f'(y0 + w_i)`` with ``w ~ N(0, sigma^2)`` and f' the exact
  derivative, several N. Its expectation is the Gaussian-smoothed GT, but with few samples it
  mostly misses the ramp: the typical estimate is the constant 0, i.e. an empirical bias.
- RS, zeroth-order: ``(1/N) sum_i (f(y0 + w_i) - f(y0)) w_i / sigma^2`` (Gaussian finite
  differences), unbiased for the same smoothed derivative, but noisy.

(b) Friction. The translating box (:class:`~drake_abs.tasks.box_lcs.TranslatingBox`, 1 kg, friction
0.5) rests on the ground and is pushed by a constant force u (N) for ``push_steps`` steps;
f(u) = its final position. Below the threshold alpha m g it does not move (f' = 0); above, f'
is the constant sum of h^2 (T - t) / m. The gradient df/du by the exact model (GT), by BS
(Fixed(mu), one rollout) and by first-order RS (N rollouts at u + w, ``w ~ N(0, sigma_u^2)``),
with RS's spread over repeated draws, its wall time and simulated steps, and the N it needs to
bring its standard error at the threshold below a tolerance (extrapolated from the measured
1/sqrt(N) law, and checked against the measured N).

The probes are :mod:`drake_abs.tasks.contact_probes`, the estimators
:mod:`drake_abs.policy.randomized_smoothing`. All samples come from one seeded numpy Generator.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from drake_abs.contact.smoothing import Fixed
from drake_abs.contact.unconverged import UnconvergedStepWarning
from drake_abs.experiments.outputs import (
    file_list,
    progress,
    pyplot,
    results_dir,
    save_figure,
    write_json,
)
from drake_abs.lcp.ipm import LCPConvergenceWarning
from drake_abs.policy.randomized_smoothing import gaussian_smoothed, randomized_smoothing
from drake_abs.tasks.box_lcs import TranslatingBox
from drake_abs.tasks.contact_probes import (
    GRAVITY,
    drop_contact_height,
    drop_response,
    push_response,
    push_slope,
)

NAME = "smoothing-vs-rs"

#: Absolute derivative (1/s) below which an RS estimate counts as the smooth region's zero (the
#: exact solver's floor leaves ~1e-9; the ramp is -1/h = -500).
ZERO = 1e-3

PAPER_CLAIMS = {
    "bs_approximates_impulse": "Fig. 6a: the BS gradient approximates the unit impulse at "
    "contact (the ground truth)",
    "rs_constant_biased": "Fig. 6a: the RS gradient is a constant and has a large bias",
    "rs_noisy_costly": "Fig. 6b: on frictional contact RS gradients are noisy and "
    "computationally costly",
}


@dataclass(frozen=True)
class Config:
    """(a) lengths in m, speeds m/s, mu in m N s; (b) forces in N, mu in m N s. Larger mu is
    more smoothing."""

    seed: int = 0
    # (a) impact
    impact_time_step: float = 0.002
    drop_speed: float = 2.0
    impact_steps: int = 100
    heights: int = 601
    rs_heights: int = 61
    fine_heights: int = 8001
    height_window: float = 0.15
    impact_mus: tuple[float, ...] = (1e-4, 1e-3, 1e-2)
    impact_sigma: float = 0.05
    impact_samples: tuple[int, ...] = (10, 100, 1000)
    impact_repeats: int = 10
    # (b) friction
    time_step: float = 0.01
    friction: float = 0.5
    push_steps: int = 50
    pushes: int = 121
    push_window: float = 3.0
    friction_mus: tuple[float, ...] = (1e-6, 1e-5, 1e-4)
    push_sigma: float = 0.5
    push_samples: tuple[int, ...] = (4, 16, 64, 256)
    push_repeats: int = 20
    tolerances: tuple[float, ...] = (0.1, 0.01)

    @classmethod
    def test_size(cls) -> Config:
        return cls(
            heights=121, rs_heights=15, fine_heights=2001, impact_samples=(10, 100),
            impact_repeats=5, pushes=21,
            push_samples=(4, 32), push_repeats=6,
        )  # fmt: skip

    def drop(self, heights, smoothing=None):
        """:func:`~drake_abs.tasks.contact_probes.drop_response` with these settings."""
        return drop_response(heights, drop_speed=self.drop_speed, steps=self.impact_steps,
                             time_step=self.impact_time_step, smoothing=smoothing)  # fmt: skip

    def box(self) -> TranslatingBox:
        return TranslatingBox(friction=self.friction, time_step=self.time_step)

    def push(self, forces, smoothing=None):
        """:func:`~drake_abs.tasks.contact_probes.push_response` with these settings."""
        return push_response(self.box(), forces, steps=self.push_steps, smoothing=smoothing)


def _tick(bar, text: str) -> None:
    bar.set_postfix_str(text)
    bar.update()


def _scalars(cases: dict) -> dict:
    """Each case's entries without its curves (the lists)."""
    return {k: {n: v for n, v in c.items() if not isinstance(v, list)} for k, c in cases.items()}


# ---------------------------------------------------------------------------- (a) impact


def impact_experiment(config: Config, rng: np.random.Generator, bar) -> dict:
    y_c = drop_contact_height(config.drop_speed, config.impact_steps, config.impact_time_step)
    window = config.height_window
    ys = y_c + np.linspace(-window, window, config.heights)
    f_gt, g_gt, conv = config.drop(ys)
    dy = ys[1] - ys[0]
    out = {"y": ys.tolist(), "y_c": y_c, "jump": float(f_gt[-1] - f_gt[0]), "gt": g_gt.tolist(),
           "gt_mass": None, "gt_value": f_gt.tolist(), "unconverged": int((~conv).sum()),
           "bs": {}, "rs_fo": {}, "rs_zo": {}}  # fmt: skip
    for mu in config.impact_mus:
        f, g, conv = config.drop(ys, Fixed(mu))
        out["unconverged"] += int((~conv).sum())
        out["bs"][f"{mu:g}"] = {
            "grad": g.tolist(),
            "value": f.tolist(),
            "peak_y": float(ys[np.argmin(g)]),
            "mass": float(np.sum(g) * dy),
            "max_abs_error_away": float(np.abs(g - g_gt)[np.abs(ys - y_c) > 0.05].max()),
        }
        _tick(bar, f"impact, BS mu = {mu:g}")
    # RS on a coarser grid of heights (all samples of all heights in one batch per draw). The
    # expectation of both RS estimators is the GT convolved with the Gaussian, computed on a
    # fine grid; RS's bias against the GT is that convolution minus the GT (predictable).
    sigma = config.impact_sigma
    fine = y_c + np.linspace(-window - 5 * sigma, window + 5 * sigma, config.fine_heights)
    _, g_fine, _ = config.drop(fine)
    out["gt_mass"] = float(np.sum(g_fine) * (fine[1] - fine[0]))
    yr = y_c + np.linspace(-window, window, config.rs_heights)
    f_r, g_r, _ = config.drop(yr)
    expected = gaussian_smoothed(yr, fine, g_fine, sigma)
    out.update(y_rs=yr.tolist(), gt_rs=g_r.tolist(), rs_expected=expected.tolist())
    near = np.abs(yr - y_c) < sigma
    for N in config.impact_samples:
        fo, zo, seconds = [], [], 0.0
        for _ in range(config.impact_repeats):
            start = time.perf_counter()
            est = randomized_smoothing(config.drop, yr, sigma, N, rng, values_at=f_r)
            seconds += time.perf_counter() - start
            fo.append(est.first_order)
            zo.append(est.zeroth_order)
            _tick(bar, f"impact, RS N = {N}")
        for key, est in (("rs_fo", np.array(fo)), ("rs_zo", np.array(zo))):
            mean, std = est.mean(axis=0), est.std(axis=0)
            out[key][str(N)] = {
                "first_draw": est[0].tolist(),
                "mean": mean.tolist(),
                "std": std.tolist(),
                # how often a draw returned exactly the smooth region's value 0 near contact
                "fraction_zero_near_contact": float(np.mean(np.abs(est[:, near]) < ZERO)),
                "max_abs_bias_vs_gt": float(np.abs(mean - g_r).max()),
                "max_abs_error_vs_expected": float(np.abs(mean - expected).max()),
                "max_standard_error": float((std / np.sqrt(len(est))).max()),
                "max_std": float(std.max()),
                "seconds_per_height": seconds / (config.impact_repeats * yr.size),
            }
    return out


# ---------------------------------------------------------------------------- (b) friction


def friction_experiment(config: Config, rng: np.random.Generator, bar) -> dict:
    """The pushed box's gradient by the exact model, BS and first-order RS. A push whose rollout
    took an unconverged step has a NaN derivative (not the model's; BS reports it as None)."""
    box = config.box()
    u_c = box.friction * box.mass * GRAVITY
    us = u_c + np.linspace(-config.push_window, config.push_window, config.pushes)
    start = time.perf_counter()
    _, g_gt, conv = config.push(us)
    T, n, slope = config.push_steps, us.size, push_slope(box, config.push_steps)
    out = {"u": us.tolist(), "u_c": u_c, "slope": slope, "gt": g_gt.tolist(),
           "unconverged": int((~conv).sum()), "bs": {}, "rs": {},
           "seconds_exact_all_pushes": time.perf_counter() - start}  # fmt: skip
    for mu in config.friction_mus:
        start = time.perf_counter()
        _, g, conv = config.push(us, Fixed(mu))
        seconds = time.perf_counter() - start
        out["unconverged"] += int((~conv).sum())
        err = np.abs(g - g_gt)[conv]
        out["bs"][f"{mu:g}"] = {
            "grad": [float(v) if c else None for v, c in zip(g, conv, strict=True)],
            "converged_pushes": int(conv.sum()),
            "pushes": int(n),
            "seconds_per_gradient": seconds / n,
            "steps_per_gradient": T,
            # over the pushes whose rollout converged (None when none did)
            "max_abs_error_vs_gt": float(err.max()) if err.size else None,
        }
        _tick(bar, f"friction, BS mu = {mu:g}")
    at = int(np.argmin(np.abs(us - u_c)))
    for N in config.push_samples:
        est, seconds = [], 0.0
        for _ in range(config.push_repeats):
            start = time.perf_counter()
            draw = randomized_smoothing(config.push, us, config.push_sigma, N, rng)
            seconds += time.perf_counter() - start
            out["unconverged"] += int((~draw.converged).sum())
            est.append(draw.first_order)
            _tick(bar, f"friction, RS N = {N}")
        est = np.array(est)
        out["rs"][str(N)] = {
            "first_draw": est[0].tolist(),
            "mean": est.mean(axis=0).tolist(),
            "std": est.std(axis=0).tolist(),
            "std_at_threshold": float(est[:, at].std()),
            "seconds_per_gradient": seconds / (config.push_repeats * n),
            "steps_per_gradient": N * T,
        }
    # the standard error follows c / sqrt(N); fit c at the threshold and give the N (and cost)
    # to bring it below tol * slope
    Ns = np.array(config.push_samples, float)
    stds = np.array([out["rs"][str(int(N))]["std_at_threshold"] for N in Ns])
    c = float(np.exp(np.mean(np.log(stds * np.sqrt(Ns)))))
    per_rollout = np.mean([out["rs"][str(int(N))]["seconds_per_gradient"] / N for N in Ns])
    needed = {f"{tol:g}": int(np.ceil((c / (tol * slope)) ** 2)) for tol in config.tolerances}
    out["rs_cost_for_tolerance"] = {
        tol: {"samples": N, "simulated_steps": N * T, "seconds_estimated": float(N * per_rollout)}
        for tol, N in needed.items()
    }
    out["rs_std_constant"] = c
    best_bs = min(out["bs"].values(), key=lambda b: b["seconds_per_gradient"])
    out["bs_seconds_per_gradient"] = best_bs["seconds_per_gradient"]
    return out


# ---------------------------------------------------------------------------- run, plot, report


def run(config: Config | None = None, out: str | Path | None = None) -> dict:
    """Run (a) and (b); write the figures, curves.json and summary.json to ``out`` (default
    results/smoothing-vs-rs); ``summary["files"]`` lists them (absolute paths)."""
    config = config or Config()
    out = results_dir(NAME, out)
    rng = np.random.default_rng(config.seed)
    start = time.perf_counter()
    draws = len(config.impact_samples) * config.impact_repeats
    draws += len(config.push_samples) * config.push_repeats
    work = len(config.impact_mus) + len(config.friction_mus) + draws
    bar = progress(total=work, desc=NAME)  # one unit per BS curve and per RS draw
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LCPConvergenceWarning)  # counted in "unconverged"
        warnings.simplefilter("ignore", UnconvergedStepWarning)  # and "converged_pushes"
        impact = impact_experiment(config, rng, bar)
        friction = friction_experiment(config, rng, bar)
    bar.close()
    keep = ("peak_y", "mass", "max_abs_error_away")
    summary = {
        "config": asdict(config),
        "impact": {
            **{k: impact[k] for k in ("y_c", "jump", "gt_mass", "unconverged")},
            "bs": {mu: {k: b[k] for k in keep} for mu, b in impact["bs"].items()},
            "rs_fo": _scalars(impact["rs_fo"]),
            "rs_zo": _scalars(impact["rs_zo"]),
        },
        "friction": {
            **{k: friction[k] for k in ("u_c", "slope", "unconverged")},
            "bs": {
                mu: {k: v for k, v in b.items() if k != "grad"} for mu, b in friction["bs"].items()
            },  # fmt: skip
            "rs": _scalars(friction["rs"]),
            "rs_cost_for_tolerance": friction["rs_cost_for_tolerance"],
            "bs_seconds_per_gradient": friction["bs_seconds_per_gradient"],
        },
        "seconds": time.perf_counter() - start,
    }
    summary["claims"] = _claims(summary)
    summary["folder"] = str(out)
    summary["files"] = file_list({
        "figure6": out / "figure6.png", "rs_cost": out / "rs_cost.png",
        "curves": out / "curves.json", "summary": out / "summary.json",
    })  # fmt: skip
    write_json(out / "curves.json", {"impact": impact, "friction": friction}, indent=None)
    write_json(out / "summary.json", summary)
    _plot(out, impact, friction)
    return summary


def _claims(summary: dict) -> dict:
    imp, fr = summary["impact"], summary["friction"]
    jump, sigma = imp["jump"], summary["config"]["impact_sigma"]
    smallest_mu = min(imp["bs"], key=float)
    b = imp["bs"][smallest_mu]
    smallest = min(imp["rs_fo"], key=int)
    zero = imp["rs_fo"][smallest]["fraction_zero_near_contact"]
    tol = min(fr["rs_cost_for_tolerance"], key=float)
    cost = fr["rs_cost_for_tolerance"][tol]
    ours = {
        "bs_approximates_impulse": (
            f"BS mu={smallest_mu}: peak {b['peak_y'] - imp['y_c']:+.4f} m from y_c, mass "
            f"{b['mass']:.3f} vs the jump {jump:.3f} m/s (larger mu: see the table)",
            abs(b["mass"] - jump) < 0.1 * abs(jump) and abs(b["peak_y"] - imp["y_c"]) < sigma,
        ),
        "rs_constant_biased": (
            f"first-order RS with N = {smallest}: {100 * zero:.0f}% of the estimates within one "
            "sigma of contact are the constant 0 (every sample missed the impulse); its "
            "expectation is the smoothed GT, so the bias is empirical (finite N)",
            zero > 0.5,
        ),
        "rs_noisy_costly": (
            f"RS needs N = {cost['samples']} rollouts ({cost['simulated_steps']} steps, "
            f"~{cost['seconds_estimated']:.3g} s) for a standard error of {tol} x slope at the "
            f"threshold; BS: 1 rollout ({summary['config']['push_steps']} steps, "
            f"{fr['bs_seconds_per_gradient']:.2g} s), deterministic",
            cost["samples"] > 10,
        ),
    }
    return {key: {"paper": PAPER_CLAIMS[key], "ours": text, "agree": bool(agree)}
            for key, (text, agree) in ours.items()}  # fmt: skip


def _plot(out: Path, impact: dict, friction: dict) -> None:
    fig, (ax, bx) = pyplot().subplots(1, 2, figsize=(13, 4.5))
    ax.plot(impact["y"], impact["gt"], "k", lw=2, label="exact (ground truth)")
    for mu, b in impact["bs"].items():
        ax.plot(impact["y"], b["grad"], label=f"barrier smoothing, mu = {mu}")
    for N, r in impact["rs_fo"].items():
        ax.plot(impact["y_rs"], r["first_draw"], "o:", ms=3,
                label=f"randomised smoothing (first order), N = {N}, one draw")  # fmt: skip
    ax.plot(impact["y_rs"], impact["rs_expected"], "--", color="gray",
            label="randomised smoothing, expectation")  # fmt: skip
    ax.set(xlabel="initial height y0 (m)", ylabel="d v_y(T) / d y0  (1/s)",
           title="(a) impact: derivative of the post-impact velocity")  # fmt: skip
    ax.set_yscale("symlog", linthresh=1.0)
    u = np.array(friction["u"])
    bx.plot(u, friction["gt"], "k", lw=2, label="exact (ground truth)")
    for mu, b in friction["bs"].items():
        g = np.array([np.nan if v is None else v for v in b["grad"]])  # gaps: unconverged
        bx.plot(u, g, label=f"barrier smoothing, mu = {mu} "
                f"({b['converged_pushes']}/{b['pushes']} pushes converged)")  # fmt: skip
    for N, r in friction["rs"].items():
        mean, std = np.array(r["first_draw"]), np.array(r["std"])
        (line,) = bx.plot(
            u, mean, ":", label=f"randomised smoothing, N = {N} (one draw, +-std band)"
        )
        bx.fill_between(u, mean - std, mean + std, color=line.get_color(), alpha=0.15)
    bx.set(xlabel="push force u (N)", ylabel="d p_x(T) / d u  (m/N)",
           title="(b) frictional box: gradient of the final position")  # fmt: skip
    ax.legend(fontsize=7)
    bx.legend(fontsize=7)
    save_figure(fig, out / "figure6.png")

    fig, ax = pyplot().subplots(figsize=(6, 4.2))
    Ns = [int(N) for N in friction["rs"]]
    for key, marker, what in (("std_at_threshold", "o-", "std at the threshold (m/N)"),
                              ("seconds_per_gradient", "s-", "seconds per gradient")):  # fmt: skip
        ax.loglog(Ns, [friction["rs"][str(N)][key] for N in Ns], marker,
                  label=f"randomised smoothing: {what}")  # fmt: skip
    ax.axhline(friction["bs_seconds_per_gradient"], color="C1", ls="--",
               label="barrier smoothing: seconds per gradient (std 0)")  # fmt: skip
    ax.set(xlabel="randomised-smoothing samples N",
           title="(b) sampling cost of randomised smoothing")  # fmt: skip
    ax.legend(fontsize=8)
    save_figure(fig, out / "rs_cost.png")


def report(summary: dict) -> str:
    imp, fr = summary["impact"], summary["friction"]
    lines = [
        f"Figure 6a (impact): contact height y_c = {imp['y_c']:.4f} m, jump {imp['jump']:.3f} "
        f"m/s, GT mass {imp['gt_mass']:.3f}; unconverged steps {imp['unconverged']}",
    ]
    for mu, b in imp["bs"].items():
        lines.append(f"  BS mu={mu:6s} peak at {b['peak_y']:.4f} m, mass {b['mass']:.3f}, "
                     f"max |err| > 5 cm from contact {b['max_abs_error_away']:.2e}")  # fmt: skip
    for key, name in (("rs_fo", "RS first-order"), ("rs_zo", "RS zeroth-order")):
        for N, r in imp[key].items():
            lines.append(
                f"  {name} N={N:5s} zero near contact {100 * r['fraction_zero_near_contact']:5.1f}%"
                f", max std {r['max_std']:.3g}, max |mean - expectation| "
                f"{r['max_abs_error_vs_expected']:.3g}"
            )
    lines.append(
        f"Figure 6b (friction): threshold {fr['u_c']:.3f} N, sliding slope {fr['slope']:.4f} m/N; "
        f"unconverged steps {fr['unconverged']}"
    )
    for mu, b in fr["bs"].items():
        lines.append(f"  BS mu={mu:6s} {b['seconds_per_gradient'] * 1e3:.3f} ms/gradient, "
                     f"{b['steps_per_gradient']} steps, "
                     f"max |err vs GT| {b['max_abs_error_vs_gt']:.3g}")  # fmt: skip
    for N, r in fr["rs"].items():
        lines.append(f"  RS N={N:4s} std at threshold {r['std_at_threshold']:.3g}, "
                     f"{r['seconds_per_gradient'] * 1e3:.3f} ms/gradient, "
                     f"{r['steps_per_gradient']} steps")  # fmt: skip
    for tol, c in fr["rs_cost_for_tolerance"].items():
        lines.append(f"  RS for std <= {tol} x slope: N = {c['samples']}, "
                     f"{c['simulated_steps']} steps, ~{c['seconds_estimated']:.3g} s")  # fmt: skip
    for c in summary["claims"].values():
        lines.append(f"  paper: {c['paper']} -> ours: {c['ours']} -> "
                     f"{'agree' if c['agree'] else 'DIFFERENT'}")  # fmt: skip
    return "\n".join(lines)
