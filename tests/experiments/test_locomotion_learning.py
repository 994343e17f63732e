"""Figure 4 (learning locomotion) at CI size: every method trains on both tasks for every seed,
is scored on the true system (exact contact) from the same reset states, and its curve and final
policy are written; the samples counted are the steps that counted."""

from __future__ import annotations

import csv
import json
import logging
import math

import numpy as np

from drake_abs.experiments import locomotion as loc


def test_locomotion_test_size(tmp_path, caplog):
    config = loc.Config.test_size()
    summary = loc.run(config, tmp_path)
    # Drake's MJCF parser warnings: none printed as they come (430 lines before issue 35, item
    # 5), at most one summary per model file (none if this process reported it already)
    records = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert not [r for r in records if r.name == "drake"]
    reports = [r.getMessage() for r in records if r.name.endswith("parser_messages")]
    for model in ("hopper.xml", "half_cheetah.xml"):
        assert sum(f"{model} (" in text for text in reports) <= 1
    for name in config.tasks:
        assert (tmp_path / f"figure4_{name}.png").is_file()
        curves = summary["tasks"][name]
        assert set(curves) == set(config.methods) == set(loc.METHODS)
        starts = {m: c["initial_return"] for m, c in curves.items() if m != "ars"}
        # every method starts from zeros and is scored on the same true system and states
        assert len({round(v, 12) for v in starts.values()}) == 1, starts
        for method, c in curves.items():
            assert all(math.isfinite(v) for v in c["return_mean"]), (name, method)
            assert c["samples_mean"][0] == 0 and c["samples_mean"][-1] > 0
            budget = config.iterations * config.rollouts * config.horizon
            if method not in ("ars",):  # ARS runs whole iterations of 2 N rollouts
                assert c["samples_mean"][-1] <= budget, (name, method)
    saved = sorted((tmp_path / "policies").glob("*.json"))
    assert len(saved) == len(config.tasks) * len(config.methods) * len(config.seeds)
    # a saved policy reloads as the class it was trained as, with the same actions
    from drake_abs.policy.ars_v2 import NormalizedLinearPolicy
    from drake_abs.tasks.saved_policies import load_policy

    ars = load_policy(tmp_path / "policies" / "hopper_ars_seed0.json")
    assert isinstance(ars.policy, NormalizedLinearPolicy) and ars.acts_on == "state"
    abs_ = load_policy(tmp_path / "policies" / "hopper_fopg_abs_seed0.json")
    assert abs_.acts_on == "observation" and abs_.task_name == "hopper"
    x = abs_.task.initial_states(np.random.default_rng(0), 3)
    rebuilt = abs_.task.policy(loc.LinearPolicy(abs_.task.n_obs, abs_.task.nu))
    np.testing.assert_array_equal(abs_.policy.act(abs_.theta, x), rebuilt.act(abs_.theta, x))
    rows = list(csv.DictReader((tmp_path / "curves.csv").open()))
    assert {r["method"] for r in rows} == set(config.methods)
    assert json.loads((tmp_path / "summary.json").read_text())["config"]["seeds"] == [0, 1]
    assert "fopg_abs" in loc.report(summary)
