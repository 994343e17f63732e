"""The ``drake-abs`` command line and the one Python entry point every experiment shares:
``Config`` (with ``test_size()``), ``run(config=None, out=None) -> dict`` and
``report(summary) -> str``."""

from __future__ import annotations

import importlib
import importlib.metadata
import inspect
import json
from pathlib import Path

import pytest

from drake_abs.experiments import cli, outputs
from drake_abs.experiments.catalog import EXPERIMENTS, STANDARD_EXPERIMENTS
from drake_abs.experiments.cli import build_parser, main
from drake_abs.multibody.scene import shipped_scenes

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
        ("gradient-variance", {"test_size": True, "ray": False, "address": None, "workers": None})
    ]


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
                                  ["precompile"]])  # fmt: skip
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
