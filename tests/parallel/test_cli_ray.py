"""``drake-abs experiment NAME --ray``: the experiment's estimators run their rollouts on Ray
actors (a local cluster on 127.0.0.1 that the command starts and stops), and every number of its
summary is the single-process one (timings aside)."""

from __future__ import annotations

import json

import pytest
from summary_numbers import assert_same_numbers

pytest.importorskip("ray")

from drake_abs.experiments.cli import main  # noqa: E402

TIMING = ("seconds", "files")


def test_an_experiment_on_ray_gives_the_single_process_numbers(tmp_path, capsys):
    args = ["experiment", "gradient-variance", "--test-size", "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "local")]) == 0
    assert main([*args, "--ray", "--workers", "2", "--out", str(tmp_path / "ray")]) == 0
    assert "rollouts ran on 2 Ray worker(s)" in capsys.readouterr().out
    assert_same_numbers(
        json.loads((tmp_path / "local" / "summary.json").read_text()),
        json.loads((tmp_path / "ray" / "summary.json").read_text()),
        skip=TIMING, at_least=21,
    )  # fmt: skip


def test_ray_options_are_checked_by_name(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["experiment", "gradient-variance", "--workers", "0"])
    assert exit_.value.code == 2 and "--workers" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        main(["experiment", "gradient-variance", "--address", "auto", "--workers", "2"])
    assert exit_.value.code == 2 and "argument --workers" in capsys.readouterr().err
