"""How the gradient variance grows with the unroll length (Zhang et al. 2023, Figure 3): the
curves of a smoothing sweep (the rows of
:func:`drake_abs.policy.gradient_stats.variance_bias_sweep`), exponential and power-law fits of
each curve, whether the variance falls as the barrier smoothing's mu grows, and the curves' line
styles.

A row names its smoothing in ``row["policy"]``: ``"exact"``, ``"BS mu=<mu>"`` (barrier smoothing
at a fixed mu; larger mu is more smoothing) or an adaptive design (``"ABS ..."``), measured in
one or both gradient modes (``row["mode"]``, ``row["modes_coincide"]``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

import numpy as np

from drake_abs.contact.smoothing import ContactAware, Exact, Fixed, GaussianMatched, Smoothing

__all__ = [
    "curve_label",
    "curve_style",
    "fit_growth",
    "mu_ordering",
    "sweep_smoothings",
    "variance_curves",
]

BS_PREFIX = "BS mu="


def sweep_smoothings(
    fixed_mus: Iterable[float],
    contact_aware: tuple[float, float],
    gaussian_sigma: float | None = None,
) -> dict[str, Smoothing]:
    """The smoothings of a sweep under their curve names: ``"exact"``, ``"BS mu=<mu>"`` per
    fixed mu (larger is smoother), ``"ABS contact-aware"`` (``contact_aware`` = (mu_max, length
    in m)) and, with ``gaussian_sigma`` (m), ``"ABS Gaussian-matched"``."""
    out: dict[str, Smoothing] = {"exact": Exact()}
    out.update({f"{BS_PREFIX}{mu:g}": Fixed(mu) for mu in fixed_mus})
    out["ABS contact-aware"] = ContactAware(*contact_aware)
    if gaussian_sigma is not None:
        out["ABS Gaussian-matched"] = GaussianMatched(gaussian_sigma)
    return out


def curve_label(row: dict) -> str:
    """A row's curve: its smoothing, with the gradient mode where the modes differ."""
    return row["policy"] if row["modes_coincide"] else f"{row['policy']} ({row['mode']})"


def fit_growth(horizons: Sequence[float], variances: Sequence[float], time_step: float) -> dict:
    """Least-squares fits of log v against H (exponential: ``log v = a + r H``, r per step) and
    against log H (power law: ``log v = a + p log H``), with the RMS of each fit's log
    residuals and which is smaller. ``time_step`` (s) converts r to a rate per second. Fewer
    than 3 points: no fit (``rate_per_step`` and ``power`` None)."""
    H = np.asarray(horizons, float)
    lv = np.log(np.asarray(variances, float))
    if H.shape != lv.shape:
        raise ValueError(f"horizons and variances must have one entry each; got {H.shape}, "
                         f"{lv.shape}")  # fmt: skip
    if H.size < 3:
        return {"points": int(H.size), "rate_per_step": None, "power": None}
    rate, a = np.polyfit(H, lv, 1)
    power, b = np.polyfit(np.log(H), lv, 1)
    rms_exp = float(np.sqrt(np.mean((lv - (a + rate * H)) ** 2)))
    rms_pow = float(np.sqrt(np.mean((lv - (b + power * np.log(H))) ** 2)))
    return {
        "points": int(H.size),
        "rate_per_step": float(rate),
        "rate_per_second": float(rate / time_step),
        "rms_log_residual_exponential": rms_exp,
        "power": float(power),
        "rms_log_residual_power_law": rms_pow,
        "better_fit": "exponential" if rms_exp < rms_pow else "power law",
    }


def variance_curves(
    rows: Iterable[dict],
    *,
    fit_from: int,
    time_step: float,
    extra: Callable[[dict], dict] | None = None,
) -> dict[str, dict]:
    """The sweep's rows as one curve per :func:`curve_label`, in row order: ``horizon``,
    ``variance`` (the trace variance), ``variance_se``, the lists of ``extra(row)``'s entries,
    and ``fit`` (:func:`fit_growth` over the horizons >= ``fit_from``)."""
    curves: dict[str, dict] = {}
    for row in rows:
        c = curves.setdefault(curve_label(row), {"horizon": [], "variance": [], "variance_se": []})
        c["horizon"].append(row["horizon"])
        c["variance"].append(row["trace_variance"])
        c["variance_se"].append(row["trace_variance_se"])
        for key, value in (extra(row) if extra else {}).items():
            c.setdefault(key, []).append(value)
    for c in curves.values():
        keep = [i for i, h in enumerate(c["horizon"]) if h >= fit_from]
        c["fit"] = fit_growth([c["horizon"][i] for i in keep], [c["variance"][i] for i in keep],
                              time_step)  # fmt: skip
    return curves


def mu_ordering(rows: Iterable[dict], horizons: Iterable[int]) -> dict[str, dict]:
    """Per horizon: is the BS variance non-increasing in mu? ``significant_increases`` counts
    the adjacent pairs (in mu order) where the larger mu has the larger variance by more than 2
    standard errors; ``ratio_smallest_to_largest_mu`` the variances' ratio (None without a BS
    row)."""
    rows = list(rows)
    out = {}
    for H in horizons:
        series = [r for r in rows if r["horizon"] == H and r["policy"].startswith(BS_PREFIX)]
        series.sort(key=lambda r: float(r["policy"].removeprefix(BS_PREFIX)))
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


def curve_style(label: str, labels: Sequence[str], ramp: Callable[[float], object]) -> dict:
    """Line style of a curve among ``labels``: black for exact, ``ramp(f)`` (a colormap, f in
    [0, 1] in the order of ``labels``) over the BS mus, red for contact-aware ABS, orange for
    Gaussian-matched ABS; dashed for the total gradient mode."""
    bs = [name for name in labels if name.startswith(BS_PREFIX)]
    if label.startswith(BS_PREFIX):
        color = ramp(bs.index(label) / max(len(bs) - 1, 1))
    elif label.startswith("ABS contact-aware"):
        color = "tab:red"
    elif label.startswith("ABS Gaussian-matched"):
        color = "tab:orange"
    else:
        color = "black"
    return {"color": color, "linestyle": "--" if "(total)" in label else "-"}
