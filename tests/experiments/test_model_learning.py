"""The model-learning experiments at CI size: learning our model's parameters from SAP and
MuJoCo data (every fit lowers its own loss, within the bounds; the file's parameters predict SAP
data better than the perturbed start), and Algorithm 2 in closed loop with MuJoCo (rounds run,
policies saved and reloadable, the model fit moves theta)."""

from __future__ import annotations

import json

import numpy as np

from drake_abs.experiments import model_based_fopg as mb
from drake_abs.experiments import model_learning as ml
from drake_abs.tasks.saved_policies import load_policy


def test_model_learning_test_size(tmp_path):
    config = ml.Config.test_size()
    summary = ml.run(config, tmp_path)
    for name in ("parameters.csv", "prediction_error.csv", "prediction_error.png",
                 "data_size.png", "summary.json"):  # fmt: skip
        assert (tmp_path / name).is_file(), name
    saved = json.loads((tmp_path / "summary.json").read_text())
    assert [(c["scene"], c["source"]) for c in saved["cases"]] == [
        (s, src) for s in config.scenes for src in config.sources
    ]
    for case in saved["cases"]:
        assert case["names"][:2] == ["ground_height", "friction[*]"]
        assert any(n.startswith("mass[") for n in case["names"])
        for row in case["sizes"]:
            assert set(row["errors"]) == {"file", "start", *config.fits, "nn"}
            for fit in config.fits:
                f = row["fits"][fit]
                assert f["loss"] <= f["start_loss"] + 1e-12, (case["scene"], fit)
                assert np.isfinite(f["theta"]).all()
            for errs in row["errors"].values():
                assert len(errs) == config.horizon
        if case["source"] == "sap":
            # the file's parameters are the SAP twin's own (masses, damping): it predicts the
            # data better than the start, whose masses are 15-30 % off and ground 2 cm up
            row = case["sizes"][0]
            assert np.mean(row["errors"]["file"]) < np.mean(row["errors"]["start"])
    assert "Model learning" in ml.report(summary)


def test_model_based_fopg_test_size(tmp_path):
    config = mb.Config.test_size()
    summary = mb.run(config, tmp_path)
    for name in ("rounds.csv", "closed_loop.png", "summary.json"):
        assert (tmp_path / name).is_file(), name
    rows = summary["rows"]
    assert {(r["round"], r["arm"]) for r in rows} == {
        (k, arm) for k in range(config.rounds + 1) for arm in mb.ARMS
    }
    assert all(np.isfinite(r["mujoco_return"]) and np.isfinite(r["our_return"]) for r in rows)
    assert summary["learned"] != summary["start"]  # the model update moved theta
    for arm, path in summary["policies"].items():
        saved = load_policy(path)
        assert saved.theta.shape == (saved.policy.n_params,), arm
    assert "MuJoCo return" in mb.report(summary)
