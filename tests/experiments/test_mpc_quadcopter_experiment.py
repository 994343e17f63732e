"""The paper 003 reproduction at CI size: the CLI runs it and it writes its figures, summary and
Meshcat page; the report sets our numbers beside the paper's; seeded runs repeat exactly."""

import dataclasses
import json

import numpy as np
import pytest

from drake_abs.experiments.cli import main
from drake_abs.experiments.mpc_quadcopter import Config, report, run


def test_cli_runs_the_experiment_at_test_size_and_writes_its_files(tmp_path, capsys):
    assert main(["experiment", "mpc-quadcopter", "--test-size", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "1111.71" in printed and "1103.04" in printed
    for name in ("figure1_convergence.png", "figure2_trajectories.png", "summary.json"):
        assert (tmp_path / name).stat().st_size > 1000, name
    assert (tmp_path / "flights.html").stat().st_size > 100_000
    summary = json.loads((tmp_path / "summary.json").read_text())
    config = Config.test_size()
    labels = ["gamma=0.25", "gamma=0.5", "gamma=0.75", "model only (eta=1)",
              "zeroth order only (eta=0)", "exact model"]  # fmt: skip
    assert list(summary["methods"]) == labels
    for m in summary["methods"].values():
        assert len(m["total"]) == config.iterations + 1
        assert np.all(np.isfinite(m["total"])) and np.all(np.isfinite(m["violation"]))
        assert m["fallback_steps"] == 0 and m["rollouts"] >= config.iterations + 1
    ours = summary["comparison"]["ours"]
    assert ours["suboptimality"] == pytest.approx(ours["trained"] / ours["exact_model"] - 1)
    assert summary["comparison"]["paper"]["suboptimality"] == pytest.approx(1111.71 / 1103.04 - 1)
    assert summary["sysid"]["rank"] == 16
    record = json.loads((tmp_path / "provenance.json").read_text())
    assert record["command"] == "experiment mpc-quadcopter"
    assert record["config"]["iterations"] == config.iterations  # the whole test-size Config
    assert set(record["config"]) == {f.name for f in dataclasses.fields(Config)}
    assert record["dependencies"]["numpy"] == np.__version__


def test_seeded_runs_repeat_exactly(tmp_path):
    config = Config(iterations=2, steps=15, sysid_trajectories=4, sysid_length=8, gammas=(0.5,),
                    baselines=False, exact_model=False, meshcat=False)  # fmt: skip
    a = run(config, tmp_path / "a")
    b = run(config, tmp_path / "b")
    assert a["methods"]["gamma=0.5"]["total"] == b["methods"]["gamma=0.5"]["total"]
    assert a["methods"]["gamma=0.5"]["theta_final"] == b["methods"]["gamma=0.5"]["theta_final"]
    c = run(Config(**{**config.__dict__, "seed": 1}), tmp_path / "c")
    assert c["methods"]["gamma=0.5"]["theta_final"] != a["methods"]["gamma=0.5"]["theta_final"]
    assert "gamma=0.5" in report(a)


def test_config_is_checked():
    with pytest.raises(ValueError, match="trained_gamma"):
        Config(gammas=(0.25,), trained_gamma=0.5)
    with pytest.raises(ValueError, match="iterations"):
        Config(iterations=-1)
