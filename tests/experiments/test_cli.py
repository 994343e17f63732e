"""The ``drake-abs`` command line and the one Python entry point every experiment shares:
``Config`` (with ``test_size()``), ``run(config=None, out=None) -> dict`` and
``report(summary) -> str``."""

from __future__ import annotations

import importlib
import importlib.metadata
import inspect
import json
from pathlib import Path

import numpy as np
import pytest

from drake_abs.experiments import cli, outputs
from drake_abs.experiments.catalog import EXPERIMENTS, STANDARD_EXPERIMENTS
from drake_abs.experiments.cli import build_parser, main
from drake_abs.multibody.scene import shipped_scenes
from drake_abs.policy.policy_files import PolicyFile

MARKUP = ("`", "**", ":func:", ":class:", ":mod:", ":data:", ":meth:")


def _modules():
    return {n: importlib.import_module(f"drake_abs.experiments.{m}") for n, m in
            STANDARD_EXPERIMENTS.items()}  # fmt: skip


# ------------------------------------------------------------------------------ entry points


def test_every_experiment_has_the_same_entry_point():
    modules = _modules()
    signatures = {name: inspect.signature(m.run) for name, m in modules.items()}
    first = signatures["bouncing-ball"]
    assert [p.name for p in first.parameters.values()] == ["config", "out"]
    assert all(p.default is None for p in first.parameters.values())
    for name, sig in signatures.items():
        assert sig == first, (name, str(sig), str(first))  # names, defaults, annotations, return
        module = modules[name]
        assert isinstance(module.Config.test_size(), module.Config), name
        assert callable(module.report), name
        assert getattr(module, "NAME", None) == name, name  # out=None -> results/<NAME>


def test_default_results_folder_is_the_same_everywhere(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name in EXPERIMENTS:
        assert outputs.default_out(name) == (tmp_path / "results" / name).resolve()
    from drake_abs.experiments.bouncing_ball import Config, run

    summary = run(Config(duration=0.1, meshcat=False))  # out=None
    folder = tmp_path / "results" / "bouncing-ball"
    assert summary["folder"] == str(folder.resolve())
    for path in summary["files"].values():
        assert Path(path).is_absolute() and Path(path).is_file(), path
        assert Path(path).parent == folder.resolve()
    saved = json.loads((folder / "summary.json").read_text())
    assert saved["files"] == summary["files"]


def test_progress_bars_can_be_turned_off(monkeypatch):
    monkeypatch.setattr(outputs, "_progress_enabled", True)  # restored afterwards
    with outputs.progress(total=3) as bar:
        assert not bar.disable
    outputs.set_progress(False)
    with outputs.progress(total=3) as bar:
        assert bar.disable
    assert not outputs.progress_enabled()


# ------------------------------------------------------------------------------------ --version


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == (
        f"drake-abs {importlib.metadata.version('drake-abs')}"
    )


# ------------------------------------------------------------------------- numeric arguments


@pytest.mark.parametrize("steps", ["-3", "0", "1.5", "ten", "nan"])
def test_bad_steps_is_an_argparse_error_naming_the_option(steps, capsys, monkeypatch):
    monkeypatch.setattr(cli, "_record", lambda *a: pytest.fail("must not record"))
    with pytest.raises(SystemExit) as exit_:
        main(["record", "box-push", "--steps", steps])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "error: argument --steps:" in err and "positive whole number" in err
    assert repr(steps) in err and "Traceback" not in err


@pytest.mark.parametrize("duration", ["-1", "0", "inf", "nan", "soon", "0.001"])
def test_bad_demo_duration_is_an_argparse_error(duration, capsys, monkeypatch):
    monkeypatch.setattr(cli, "_run_demo", lambda *a, **k: pytest.fail("must not run"))
    with pytest.raises(SystemExit) as exit_:
        main(["demo", "--duration", duration, "--no-meshcat"])
    assert exit_.value.code == 2
    assert "error: argument --duration:" in capsys.readouterr().err


def test_good_steps_are_parsed():
    args = build_parser().parse_args(["record", "box-push", "--steps", "7"])
    assert args.steps == 7 and args.scene == "box_push"


# --------------------------------------------------------------------------------------- names


@pytest.mark.parametrize(
    "spelling", ["gradient-variance", "gradient_variance", "Gradient_Variance"]
)
def test_experiment_names_in_either_spelling(spelling, monkeypatch, tmp_path):
    calls = []
    monkeypatch.setattr(cli, "_run_standard", lambda name, out, **k: calls.append((name, k)) or 0)
    assert main(["experiment", spelling, "--test-size", "--out", str(tmp_path)]) == 0
    assert calls == [
        (
            "gradient-variance",
            {"test_size": True, "ray": False, "address": None, "workers": None, "config": None},
        )
    ]


def test_experiment_settings_are_applied_and_bad_ones_named(monkeypatch, tmp_path, capsys):
    calls = []
    monkeypatch.setattr(cli, "_run_standard", lambda name, out, **k: calls.append((name, k)) or 0)
    args = ["experiment", "gym-locomotion", "--test-size", "--out", str(tmp_path)]
    sets = ["--set", "env_steps=320", "--set", "settings.shac.actor_lr=0.01",
            "--set", "methods=[ars]"]  # fmt: skip
    assert main(args + sets) == 0
    config = calls[0][1]["config"]
    assert config.env_steps == 320 and config.methods == ("ars",)
    assert config.settings.shac.actor_lr == 0.01
    assert config.settings.shac.envs == 4  # the rest of the test size kept
    for bad, says in (("settings.shac.nope=1", "unknown setting"),
                      ("env_steps=1,2", "one value per setting"),
                      ("env_steps=many", "env_steps")):  # fmt: skip
        with pytest.raises(SystemExit) as err:
            main(args + ["--set", bad])
        assert err.value.code == 2 and says in capsys.readouterr().err


@pytest.mark.parametrize("spelling", ["box_push", "box-push", "solo12-drop", "gym_half-cheetah"])
def test_scene_names_in_either_spelling(spelling):
    args = build_parser().parse_args(["record", spelling])
    assert args.scene == spelling.replace("-", "_") and args.scene in shipped_scenes()


def test_unknown_names_are_argparse_errors(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["experiment", "no-such-experiment"])
    assert exit_.value.code == 2
    assert "invalid choice" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        main(["record", "no_such_scene"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "no scene 'no_such_scene'" in err and "box-push" in err and "box_push" not in err


def test_out_must_be_a_folder(tmp_path, capsys):
    file = tmp_path / "a_file"
    file.write_text("")
    with pytest.raises(SystemExit) as exit_:
        main(["experiment", "bouncing-ball", "--out", str(file)])
    assert exit_.value.code == 2
    assert "argument --out" in capsys.readouterr().err


# -------------------------------------------------------------------------------- help, list


def _help(argv) -> None:
    with pytest.raises(SystemExit) as exit_:
        main([*argv, "--help"])
    assert exit_.value.code == 0


@pytest.mark.parametrize("argv", [[], ["demo"], ["experiment"], ["record"], ["list"],
                                  ["precompile"], ["evaluate"], ["replay"]])  # fmt: skip
def test_help_is_plain_text(argv, capsys):
    _help(argv)
    text = capsys.readouterr().out
    assert text.startswith("usage: drake-abs")
    for mark in MARKUP:
        assert mark not in text, (argv, mark)
    if argv in ([], ["experiment"]):  # names are shown with dashes only
        assert "gradient-variance" in text or "list" in text
        assert "gradient_variance" not in text


def test_list_shows_experiments_and_scenes(capsys):
    assert main(["list"]) == 0
    text = capsys.readouterr().out
    for name in EXPERIMENTS:
        (line,) = [ln for ln in text.splitlines() if ln.strip().startswith(name + " ")]
        description = line.strip()[len(name) :].strip()
        assert description and not any(mark in description for mark in MARKUP), line
    for scene in shipped_scenes():
        assert f"  {scene.replace('_', '-')}\n" in text + "\n"
    assert "_" not in text.split("shipped scenes")[1]  # one spelling: dashes
    assert main(["experiment", "--list"]) == 0
    assert capsys.readouterr().out == text


def test_cli_runs_an_experiment_and_prints_the_absolute_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(outputs, "_progress_enabled", True)  # restored afterwards
    assert (
        main(["experiment", "bouncing_ball", "--test-size", "--out", "rel", "--no-progress"]) == 0
    )
    out = capsys.readouterr().out
    folder = (tmp_path / "rel").resolve()
    assert out.strip().endswith(f"results written to {folder}")
    summary = json.loads((folder / "summary.json").read_text())
    assert all(Path(p).is_absolute() for p in summary["files"].values())
    assert not outputs.progress_enabled()  # --no-progress


# ------------------------------------------------------------------ policy files: evaluate, replay


def _policy_file(tmp_path, name: str = "hop.npz", scale: float = 0.2, **metadata) -> Path:
    W = scale * np.random.default_rng(5).standard_normal((3, 11))
    return PolicyFile.linear(W, np.zeros(3), **metadata).save(tmp_path / name)


def test_evaluate_scores_a_policy_file_in_mujoco_and_on_our_plant(tmp_path, capsys):
    pytest.importorskip("gymnasium")
    pytest.importorskip("mujoco")
    path = _policy_file(tmp_path, env_id="Hopper-v5", method="fopg_abs", seed=2)
    record = tmp_path / "out" / "eval.json"
    argv = ["evaluate", str(path), "--seeds", "2", "--max-steps", "15", "--json", str(record)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    for text in ("Hopper-v5 in MuJoCo", "reset seeds 0..1, at most 15 steps", "zero action",
                 "random action", "our plant (task hopper", "method fopg_abs, seed 2",
                 "episodes with an unconverged contact solve: 0 of 2"):  # fmt: skip
        assert text in out, text
    result = json.loads(record.read_text())
    mujoco = result["mujoco"]
    assert result["seeds"] == [0, 1] and result["env_id"] == "Hopper-v5"
    assert set(mujoco) == {"policy", "zero", "random"}
    assert all(len(mujoco[k]["returns"]) == 2 for k in mujoco)
    assert len(result["plant"]["returns"]) == 2 and result["plant"]["task"] == "hopper"
    # the printed rows are the record's
    rows = [ln.split() for ln in out.splitlines() if ln.startswith("  policy ")]
    assert [float(r[1]) for r in rows] == [round(mujoco["policy"]["mean"], 2),
                                           round(result["plant"]["mean"], 2)]  # fmt: skip


def test_evaluate_of_a_zero_file_prints_the_zero_floor(tmp_path, capsys):
    pytest.importorskip("gymnasium")
    path = _policy_file(tmp_path, "zero.npz", scale=0.0)
    record = tmp_path / "zero.json"
    argv = ["evaluate", str(path), "--env", "HalfCheetah-v5", "--seeds", "2", "--max-steps", "10",
            "--json", str(record), "--no-plant"]  # fmt: skip
    # an 11-observation file does not fit HalfCheetah-v5 (17): a usage error
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    assert "the policy maps 11 observations to 3 actions" in capsys.readouterr().err
    argv[3] = "Hopper-v5"
    assert main(argv) == 0
    result = json.loads(record.read_text())
    assert result["mujoco"]["policy"]["returns"] == result["mujoco"]["zero"]["returns"]
    assert result["plant"] is None
    assert "our plant: not scored (--no-plant)" in capsys.readouterr().out


def test_evaluate_refuses_bad_files_and_environments(tmp_path, capsys):
    pytest.importorskip("gymnasium")
    bare = _policy_file(tmp_path, "bare.npz")
    broken = tmp_path / "broken.npz"
    with broken.open("wb") as handle:
        np.savez(handle, W=np.zeros((3, 11)), b=np.zeros(3))  # no obs_mean, obs_std
    bad = [
        ([str(bare)], "argument --env: the policy file names no env_id"),
        ([str(broken), "--env", "Hopper-v5"], "argument POLICY:"),
        ([str(tmp_path / "missing.npz"), "--env", "Hopper-v5"], "argument POLICY: no policy file"),
        ([str(bare), "--env", "NoSuchEnv-v9"], "argument --env: 'NoSuchEnv-v9'"),
        ([str(bare), "--env", "Hopper-v5", "--seeds", "0"], "argument --seeds:"),
        ([str(bare), "--env", "Hopper-v5", "--json", str(tmp_path)], "argument --json:"),
    ]
    for argv, message in bad:
        with pytest.raises(SystemExit) as exit_:
            main(["evaluate", *argv])
        assert exit_.value.code == 2, argv
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, (argv, err)
    with pytest.raises(SystemExit):
        main(["evaluate", str(broken), "--env", "Hopper-v5"])
    assert "no 'obs_mean'" in capsys.readouterr().err


def test_evaluate_says_where_there_is_no_scene_on_our_plant(tmp_path, capsys):
    pytest.importorskip("gymnasium")
    path = PolicyFile.linear(np.zeros((1, 4)), np.zeros(1)).save(tmp_path / "pendulum.npz")
    assert main(["evaluate", str(path), "--env", "InvertedPendulum-v5", "--seeds", "1",
                 "--max-steps", "5"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "our plant: not scored: env_id 'InvertedPendulum-v5' has no scene on our plant" in out


def test_replay_draws_a_policy_file_on_our_plant(tmp_path, capsys):
    path = _policy_file(tmp_path, env_id="Hopper-v5")
    html = tmp_path / "hop.html"
    assert main(["replay", str(path), "--steps", "5", "--out", str(html)]) == 0
    out = capsys.readouterr().out
    assert "replayed hop (hopper, seed 0)" in out and "5 steps" in out
    assert html.is_file() and html.stat().st_size > 10_000
    bare = _policy_file(tmp_path, "bare.npz")
    bad = [([str(bare)], "argument POLICY: the policy file"),
           ([str(bare), "--env", "InvertedPendulum-v5"], "has no scene on our plant")]  # fmt: skip
    for argv, message in bad:
        with pytest.raises(SystemExit) as exit_:
            main(["replay", *argv, "--steps", "3", "--out", str(tmp_path / "x.html")])
        assert exit_.value.code == 2
        assert message in capsys.readouterr().err
    assert main(["replay", str(bare), "--env", "Hopper-v5", "--steps", "3", "--out",
                 str(tmp_path / "bare.html")]) == 0  # fmt: skip
