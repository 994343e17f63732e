"""The frictional solver's convergence sweep on the box, at CI size (the full grid is
``drake-abs experiment box-convergence``; its figures are in the closing notes)."""

import pytest

from drake_abs.experiments.box_convergence import SweepConfig, report, run


def test_sweep_runs_the_extremes_without_nan_and_reports_failures():
    summary = run(SweepConfig.test_size())  # raises on any non-finite state or Jacobian
    assert summary["steps"] == 48 * 12
    text = report(summary)
    assert f"{summary['converged_steps']} of {summary['steps']} steps converged" in text
    for case in summary["failed_cases"]:  # every failure is listed, none hidden
        assert f"h {case['time_step']:g}" in text
    frictionless = [r for r in summary["rows"] if r["friction"] == 0.0]
    assert all(r["converged_steps"] == r["steps"] for r in frictionless)


@pytest.mark.parametrize("policy", ["abs", "exact"])
def test_the_measured_envelope_converges(policy):
    """Friction up to 1 at h = 1e-2 over extreme mass and mobility ratios: every step
    converges (the full sweep found no failure there for ABS, and for exact contact only at
    mobility ratio 1e3, which this grid leaves out)."""
    config = SweepConfig(
        frictions=(0.1, 0.5, 1.0),
        masses=(1e-3, 1e3),
        mobility_ratios=(1e-3, 2.4, 10.0),
        time_steps=(1e-2,),
        steps=12,
        policies=(policy,),
    )
    summary = run(config)
    assert summary["failed_cases"] == [], report(summary)
