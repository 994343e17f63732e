"""Paper 000 Figure 6, BS against randomised smoothing (experiments/smoothing_vs_rs.py): the
experiment at a small size writes its files and reports against the paper. The probes and the
estimators it runs are tested in tests/tasks/test_contact_probes.py and
tests/policy/test_randomized_smoothing.py."""

from __future__ import annotations

import numpy as np

from drake_abs.contact.smoothing import Fixed
from drake_abs.experiments import smoothing_vs_rs as srs
from drake_abs.tasks.contact_probes import drop_response, push_response


def test_config_probes_are_the_library_probes():
    config = srs.Config.test_size()
    ys, us = np.array([0.1, 0.3]), np.array([4.0, 6.0])
    for a, b in zip(
        config.drop(ys, Fixed(1e-3)),
        drop_response(ys, drop_speed=2.0, steps=100, time_step=0.002, smoothing=Fixed(1e-3)),
        strict=True,
    ):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(config.push(us).derivative,
                                  push_response(config.box(), us, steps=50).derivative)  # fmt: skip


def test_experiment_writes_its_results(tmp_path):
    config = srs.Config(
        heights=41, rs_heights=9, fine_heights=801, impact_samples=(10,), impact_repeats=3,
        pushes=9, push_samples=(4, 16), push_repeats=4, impact_mus=(1e-4,), friction_mus=(1e-5,),
    )  # fmt: skip
    summary = srs.run(config, tmp_path)
    for name in ("figure6.png", "rs_cost.png", "summary.json", "curves.json"):
        assert (tmp_path / name).is_file()
    assert set(summary["claims"]) == set(srs.PAPER_CLAIMS)
    assert summary["friction"]["rs_cost_for_tolerance"]["0.01"]["samples"] > 100
    assert "paper:" in srs.report(summary)
