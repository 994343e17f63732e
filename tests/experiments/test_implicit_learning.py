"""Bianchini et al.'s (2022) toy at CI size: Table 1 from our implementation (closed form and
measured agree; only L_lambda,theta^vimp differs from the printed table), the landscapes' minima
at the true height, the bounds ordered as the paper says (the fits themselves:
tests/learning/test_ground_height_fit.py)."""

from __future__ import annotations

import json

import numpy as np

from drake_abs.experiments import implicit_learning as il


def test_implicit_learning_test_size(tmp_path):
    config = il.Config.test_size()
    summary = il.run(config, tmp_path)
    for name in ("table1.csv", "figure1_landscapes.png", "figure3_bounds.png",
                 "generalization.png", "summary.json"):  # fmt: skip
        assert (tmp_path / name).is_file(), name
    saved = json.loads((tmp_path / "summary.json").read_text())
    differs = [row["constant"] for row in saved["table1"]
               if not np.isclose(row["ours_closed_form"], row["paper"], rtol=2e-3)]  # fmt: skip
    assert differs == ["L_lambda,theta^vimp"]
    for row in saved["table1"]:
        assert np.isclose(row["ours_measured"], row["ours_closed_form"], rtol=2e-3, atol=1e-12)
    # every landscape has its minimum within a grid step of the true height 0 (noise 0.05 m/s)
    step = 2 * config.landscape_range / (config.landscape_steps - 1)
    for label, argmin in summary["landscape_argmin"].items():
        assert abs(argmin) <= 3 * step, (label, argmin)
    b = summary["bounds_vs_n"]
    assert all(e > v for e, v in zip(b["exp"], b["vimp"], strict=True))
    assert summary["data_ratio_exp_over_vimp"]["ours"] > 100  # "two orders of magnitude"
    assert "differs" in il.report(summary)
