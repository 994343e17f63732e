"""Figure 3 on the locomotion tasks (gymnasium's Hopper and HalfCheetah on our plant) at CI size:
it runs, writes its files, measures a positive finite variance for every design and horizon,
and the variance grows with the unroll length under exact contact."""

from __future__ import annotations

import json
import math

from drake_abs.experiments import locomotion_variance as lv


def test_locomotion_variance_test_size(tmp_path):
    config = lv.Config.test_size()
    summary = lv.run(config, tmp_path)
    assert (tmp_path / "figure3_locomotion.png").is_file()
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert set(saved["tasks"]) == set(config.tasks) == {"hopper", "half_cheetah"}
    for name, res in summary["tasks"].items():
        curves = res["curves"]
        # exact, each fixed mu, contact-aware in two gradient modes
        assert len(curves) == 1 + len(config.fixed_mus) + 2, name
        for c in curves.values():
            assert c["horizon"] == list(config.horizons)
            assert all(math.isfinite(v) and v > 0 for v in c["variance"]), (name, c)
        exact = curves["exact"]["variance"]
        assert exact[-1] > exact[0], (name, exact)  # longer unrolls, larger variance
    text = lv.report(summary)
    assert "hopper" in text and "half_cheetah" in text
