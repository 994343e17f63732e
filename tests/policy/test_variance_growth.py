"""The variance-against-horizon curves of a smoothing sweep (drake_abs.policy.variance_growth):
the growth fit tells an exponential from a power law, the curves gather the sweep's rows, the
mu ordering counts significant increases only, the line styles follow the smoothing."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.policy.variance_growth import (
    curve_label,
    curve_style,
    fit_growth,
    mu_ordering,
    sweep_smoothings,
    variance_curves,
)


def test_growth_fit_tells_exponential_from_power_law():
    H = np.array([50, 100, 200, 400, 800])
    exp_fit = fit_growth(H, 1e-6 * np.exp(0.02 * H), time_step=0.01)
    assert exp_fit["rate_per_step"] == pytest.approx(0.02, rel=1e-9)
    assert exp_fit["rate_per_second"] == pytest.approx(2.0, rel=1e-9)
    assert exp_fit["better_fit"] == "exponential"
    pow_fit = fit_growth(H, 1e-6 * H**2.5, time_step=0.01)
    assert pow_fit["power"] == pytest.approx(2.5, rel=1e-9)
    assert pow_fit["better_fit"] == "power law"
    assert fit_growth(H[:2], [1.0, 2.0], time_step=0.01)["rate_per_step"] is None
    with pytest.raises(ValueError, match="one entry each"):
        fit_growth(H, [1.0, 2.0], time_step=0.01)


def _row(policy, mode, H, v, se=0.0, coincide=True):
    return {"policy": policy, "mode": mode, "modes_coincide": coincide, "horizon": H,
            "trace_variance": v, "trace_variance_se": se}  # fmt: skip


def test_curves_gather_rows_by_smoothing_and_mode():
    rows = [_row("exact", "frozen", H, np.exp(0.1 * H)) for H in (10, 20, 30, 40)]
    rows += [_row("ABS contact-aware", m, 10, 1.0, coincide=False) for m in ("frozen", "total")]
    curves = variance_curves(rows, fit_from=20, time_step=0.5,
                             extra=lambda r: {"share": r["horizon"] / 10})  # fmt: skip
    assert list(curves) == ["exact", "ABS contact-aware (frozen)", "ABS contact-aware (total)"]
    exact = curves["exact"]
    assert exact["horizon"] == [10, 20, 30, 40] and exact["share"] == [1, 2, 3, 4]
    assert exact["fit"]["points"] == 3  # the horizons >= fit_from
    assert exact["fit"]["rate_per_second"] == pytest.approx(0.2, rel=1e-9)
    assert curve_label(rows[-1]) == "ABS contact-aware (total)"


def test_mu_ordering_counts_significant_increases():
    rows = [
        _row("BS mu=1e-10", "frozen", 5, 10.0, 1.0),
        _row("BS mu=0.01", "frozen", 5, 1.0, 0.1),
        _row("BS mu=1e-06", "frozen", 5, 14.0, 1.0),
        _row("exact", "frozen", 5, 99.0),
    ]
    out = mu_ordering(rows, (5, 6))["5"]
    # in mu order 1e-10 (10), 1e-6 (14: up by more than 2 se), 1e-2 (1)
    assert out == {"pairs": 2, "significant_increases": 1, "ratio_smallest_to_largest_mu": 10.0}
    assert mu_ordering(rows, (6,))["6"]["ratio_smallest_to_largest_mu"] is None


def test_curve_styles():
    labels = ["exact", "BS mu=1e-10", "BS mu=0.01", "ABS contact-aware (total)"]
    ramp = {0.0: "first", 1.0: "last"}.__getitem__
    assert curve_style("exact", labels, ramp) == {"color": "black", "linestyle": "-"}
    assert curve_style("BS mu=0.01", labels, ramp)["color"] == "last"
    assert curve_style("ABS contact-aware (total)", labels, ramp) == {
        "color": "tab:red",
        "linestyle": "--",
    }


def test_sweep_smoothings_are_named_as_the_curves():
    from drake_abs.contact.smoothing import ContactAware, Exact, Fixed, GaussianMatched

    designs = sweep_smoothings((1e-10, 0.01), (1e-2, 0.05), gaussian_sigma=0.02)
    assert list(designs) == ["exact", "BS mu=1e-10", "BS mu=0.01", "ABS contact-aware",
                             "ABS Gaussian-matched"]  # fmt: skip
    assert designs["exact"] == Exact() and designs["BS mu=0.01"] == Fixed(0.01)
    assert designs["ABS contact-aware"] == ContactAware(1e-2, 0.05)
    assert designs["ABS Gaussian-matched"] == GaussianMatched(0.02)
    assert "ABS Gaussian-matched" not in sweep_smoothings((), (1e-2, 0.05))
