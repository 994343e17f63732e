"""``drake-abs experiment NAME --ray``: the experiment's estimators run their rollouts on Ray
actors (a local cluster on 127.0.0.1 that the command starts and stops), and every number of its
summary is the single-process one (timings aside)."""

from __future__ import annotations

import json
import math

import pytest

pytest.importorskip("ray")

from drake_abs.experiments.cli import main  # noqa: E402

TIMING = ("seconds", "files")


def _numbers(value, path=""):
    """(path, number) of every number in a summary, timings and file paths left out."""
    if isinstance(value, dict):
        for key, item in value.items():
            if not any(t in key for t in TIMING):
                yield from _numbers(item, f"{path}.{key}")
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from _numbers(item, f"{path}[{i}]")
    elif isinstance(value, int | float) and not isinstance(value, bool):
        yield path, value


def test_an_experiment_on_ray_gives_the_single_process_numbers(tmp_path, capsys):
    args = ["experiment", "gradient-variance", "--test-size", "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "local")]) == 0
    assert main([*args, "--ray", "--workers", "2", "--out", str(tmp_path / "ray")]) == 0
    assert "rollouts ran on 2 Ray worker(s)" in capsys.readouterr().out
    local = dict(_numbers(json.loads((tmp_path / "local" / "summary.json").read_text())))
    ray = dict(_numbers(json.loads((tmp_path / "ray" / "summary.json").read_text())))
    assert local.keys() == ray.keys() and len(local) > 20
    differ = [
        (k, local[k], ray[k]) for k in local
        if not (local[k] == ray[k] or (math.isnan(local[k]) and math.isnan(ray[k])))
        and not math.isclose(local[k], ray[k], rel_tol=1e-12, abs_tol=1e-300)
    ]  # fmt: skip
    assert not differ, differ[:5]


def test_ray_options_are_checked_by_name(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["experiment", "gradient-variance", "--workers", "0"])
    assert exit_.value.code == 2 and "--workers" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        main(["experiment", "gradient-variance", "--address", "auto", "--workers", "2"])
    assert exit_.value.code == 2 and "argument --workers" in capsys.readouterr().err
