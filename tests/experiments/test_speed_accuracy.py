"""The speed/accuracy experiment (experiments/speed_accuracy.py) at test size.

Checks: the reference is trustworthy (its slopes equal the analytic rigid-body slopes; its own
error at twice the step is below every coarse setting's); errors fall as the time step falls
for Exact; hard contact does not penetrate, Drake's compliant contact does; every number is
finite and every cost positive; the table's "cheapest" entries are the cheapest rows that reach
each accuracy; the files are written."""

from __future__ import annotations

import json
import math

import pytest

from drake_abs.experiments import speed_accuracy as sa


@pytest.fixture(scope="module")
def summary(tmp_path_factory):
    out = tmp_path_factory.mktemp("speed-accuracy")
    result = sa.run(sa.Config.test_size(), out)
    for name in ("summary.json", "speed_accuracy.md", "speed_accuracy.png"):
        assert (out / name).stat().st_size > 100, name
    assert json.loads((out / "summary.json").read_text())["scenes"].keys() == {
        "box",
        "ball",
        "hopper",
    }
    return result


def _row(rows, label):
    (row,) = [r for r in rows if r["label"] == label]
    return row


def test_the_reference_is_converged_and_has_the_rigid_body_slopes(summary):
    for scene, s in summary["scenes"].items():
        for name, pair in s["reference"]["G_entries_vs_analytic"].items():
            assert pair["reference"] == pytest.approx(pair["analytic_rigid"], rel=0.05), name
        self_error = s["reference"]["self_error_at_twice_the_step"]["trajectory_error_m"]
        coarse = [r["trajectory_error_m"] for r in s["rows"] if r["time_step"] == 0.02]
        assert self_error < min(coarse), scene


def test_exact_converges_with_the_time_step_and_does_not_penetrate(summary):
    for scene, s in summary["scenes"].items():
        e20 = _row(s["rows"], sa.Setting("exact", 0.02).label)
        e10 = _row(s["rows"], sa.Setting("exact", 0.01).label)
        assert e10["trajectory_error_m"] < e20["trajectory_error_m"], scene
        assert e10["penetration_m"] < 1e-9 and e20["penetration_m"] < 1e-9
        sap = _row(s["rows"], "Drake SAP, h=10 ms")
        assert sap["penetration_m"] > 1e-4, scene  # compliant point contact sinks in


def test_every_row_is_finite_and_the_table_picks_the_cheapest(summary):
    for s in summary["scenes"].values():
        for r in s["rows"]:
            for key in ("cost_s_per_s", "gradient_cost_s_per_s", "trajectory_error_m",
                        "gradient_error", "energy_error_J", "penetration_m"):  # fmt: skip
                assert math.isfinite(r[key]) and r[key] >= 0, (r["label"], key)
            assert r["cost_s_per_s"] > 0
        for key, best in s["cheapest"].items():
            who, tier = key.split("@")
            ours = who == "ours"
            ok = [
                r
                for r in s["rows"]
                if (r["family"] in ("exact", "bs", "abs", "gaussian")) == ours
                and r["trajectory_error_m"] <= float(tier)
                and r["unconverged_steps"] == 0
            ]
            if not ok:
                assert best is None
            else:
                assert best["cost_s_per_s"] == min(r["cost_s_per_s"] for r in ok)
                assert best["trajectory_error_m"] <= float(tier)
