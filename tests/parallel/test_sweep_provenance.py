"""What produced a sweep point, and when a point is reused (drake_abs.parallel.provenance, the
reuse rule of drake_abs.parallel.sweep, drake-abs sweep --check).

Every point.json records the point's whole resolved Config, the drake-abs version, the commit
and the versions of the libraries that compute the numbers. A point whose recorded Config,
package version or dependency version differs is recomputed, and the sweep says which field
differs; a point that differs only in its commit is reused (the package version is the release
key). ``drake-abs sweep --check`` runs nothing and lists every point as fresh, stale, missing or
unfinished, exit code 0 only when all are fresh. The experiment's own run is replaced by a quick
stand-in where only the records matter, so these tests need neither Ray nor minutes."""

from __future__ import annotations

import dataclasses
import importlib.metadata
import json
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

from drake_abs.experiments.cli import main
from drake_abs.experiments.sweep import ExperimentPoint
from drake_abs.parallel import provenance as prov
from drake_abs.parallel.sweep import FRESH, MISSING, STALE, check_sweep, run_sweep

# ------------------------------------------------------------------------------------ helpers


@dataclass(frozen=True)
class Toy:
    """A point function with a resolved configuration (``eps`` and the point's values), as
    ExperimentPoint has; every call appends the point's x to the file ``log``."""

    log: str
    eps: float = 0.25

    def __call__(self, values: dict, folder: Path) -> dict:
        with open(self.log, "a") as f:
            f.write(f"{values['x']}\n")
        return {"y": values["x"] * self.eps}

    def describe(self) -> dict:
        return {"toy": True}

    def resolved_config(self, values: dict) -> dict:
        return {"eps": self.eps, "solver": {"tol": 1e-8}, **values}


def calls(log: Path) -> list[int]:
    return [int(line) for line in log.read_text().split()] if log.exists() else []


def edit(folder: Path, change) -> None:
    """Apply ``change`` to the record dict in ``folder/point.json``."""
    path = folder / "point.json"
    record = json.loads(path.read_text())
    change(record)
    path.write_text(json.dumps(record, indent=2))


def quick_point(self, values: dict, folder: Path) -> dict:
    """Stands in for an experiment's run: records the call, returns the point's eps."""
    config = self.config(values)
    (folder / "ran.txt").write_text(f"seed {config.seed}\n")
    QUICK_CALLS.append(config.seed)
    return {"eps": config.eps, "seed": config.seed}


QUICK_CALLS: list[int] = []


@pytest.fixture
def quick(monkeypatch):
    """ExperimentPoint runs ``quick_point`` instead of its experiment (its describe() and
    resolved_config() are the real ones); returns the list of seeds run."""
    QUICK_CALLS.clear()
    monkeypatch.setattr(ExperimentPoint, "__call__", quick_point)
    return QUICK_CALLS


def sweep(out: Path, *extra: str) -> list[str]:
    return ["sweep", "implicit-learning", "--test-size", "--seeds", "0", "1", "--out", str(out),
            "--no-progress", *extra]  # fmt: skip


# --------------------------------------------------------------------------------- provenance


def test_provenance_records_the_version_the_commit_and_the_dependencies(monkeypatch):
    record = prov.provenance()
    json.dumps(record)  # JSON-able as it is
    assert record["drake_abs_version"] == importlib.metadata.version("drake-abs")
    deps = record["dependencies"]
    for name in ("drake", "numpy", "scipy", "numba", "osqp", "pin", "gymnasium", "mujoco",
                 "stable-baselines3", "torch"):  # fmt: skip
        assert name in deps
    assert deps["numpy"] == importlib.metadata.version("numpy")
    assert deps["scipy"] == importlib.metadata.version("scipy")
    monkeypatch.setattr(prov, "DEPENDENCIES", ("numpy", "no-such-distribution-here"))
    assert prov.dependency_versions(prov.DEPENDENCIES) == {
        "numpy": importlib.metadata.version("numpy"), "no-such-distribution-here": None,
    }  # fmt: skip
    head = subprocess.run(["git", "-C", str(prov.SOURCE_ROOT), "rev-parse", "HEAD"],
                          capture_output=True, text=True)  # fmt: skip
    if head.returncode != 0:
        pytest.skip("the package is not imported from a git checkout here")
    assert record["commit"] == head.stdout.strip() and isinstance(record["dirty"], bool)


def _git(folder: Path, *args: str) -> None:
    settings = ["-c", "user.name=t", "-c", "user.email=t@t", "-c", "commit.gpgsign=false"]
    subprocess.run(["git", "-C", str(folder), *settings, *args], check=True, capture_output=True)


def test_provenance_outside_a_git_checkout_records_no_commit(tmp_path, monkeypatch):
    # not a checkout: the versions are there, the commit and the dirty flag are None
    monkeypatch.setattr(prov, "SOURCE_ROOT", tmp_path)
    record = prov.provenance()
    assert record["commit"] is None and record["dirty"] is None
    assert record["drake_abs_version"] == importlib.metadata.version("drake-abs")
    assert record["dependencies"]["numpy"] == importlib.metadata.version("numpy")
    assert prov.source_commit(tmp_path / "no-such-folder") == {"commit": None, "dirty": None}

    # a checkout: its commit, clean, then dirty; a folder inside it is not its top
    repo = tmp_path / "a repo"  # a space in the path
    (repo / "pkg").mkdir(parents=True)
    (repo / "pkg" / "a.py").write_text("x = 1\n")
    _git(repo, "init", "-q")
    _git(repo, "add", "pkg/a.py")
    _git(repo, "commit", "-q", "-m", "one")
    head = subprocess.run(["git", "-C", str(repo), "rev-parse", "HEAD"], capture_output=True,
                          text=True, check=True).stdout.strip()  # fmt: skip
    assert prov.source_commit(repo) == {"commit": head, "dirty": False}
    (repo / "pkg" / "a.py").write_text("x = 2\n")
    assert prov.source_commit(repo) == {"commit": head, "dirty": True}
    assert prov.source_commit(repo / "pkg")["commit"] is None  # e.g. site-packages in a repo

    # git missing: no commit, and no error
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    assert prov.source_commit(repo) == {"commit": None, "dirty": None}


def test_only_the_version_and_the_dependencies_count_not_the_commit():
    now = prov.provenance()
    other = json.loads(json.dumps(now))
    other["commit"], other["dirty"] = "0" * 40, not now["dirty"]
    assert prov.differences(other, now) == []
    other["dependencies"]["numpy"] = "0.0.1"
    other["drake_abs_version"] = "0.0.0"
    assert prov.differences(other, now) == [
        f"drake-abs: 0.0.0 != {now['drake_abs_version']}",
        f"numpy: 0.0.1 != {now['dependencies']['numpy']}",
    ]
    assert prov.differences(None, now) == [
        "no provenance recorded (written before drake-abs recorded it)"
    ]


# --------------------------------------------------------------------------- the reuse rule


def test_a_point_whose_recorded_config_was_edited_is_recomputed_and_says_which_field(tmp_path):
    log, out = tmp_path / "calls", tmp_path / "sweep"
    fn, points = Toy(str(log)), [{"x": 1}, {"x": 2}]
    first = run_sweep(fn, points, out, progress=False)
    record = json.loads((out / "points" / "x=1" / "point.json").read_text())
    assert record["config"] == {"eps": 0.25, "solver": {"tol": 1e-8}, "x": 1}
    assert record["provenance"]["dependencies"] == first.provenance["dependencies"]
    gathered = json.loads((out / "sweep.json").read_text())
    assert gathered["provenance"] == first.provenance
    assert gathered["points"][0]["provenance"] == record["provenance"]

    edit(out / "points" / "x=1", lambda r: r["config"].update(eps=99))
    edit(out / "points" / "x=2", lambda r: r["config"]["solver"].update(tol=0.5))
    again = run_sweep(fn, points, out, progress=False)
    assert calls(log) == [1, 2, 1, 2] and not again.reused
    assert [p.recomputed_because for p in again.points] == [
        "stale: config.eps: 99 != 0.25", "stale: config.solver.tol: 0.5 != 1e-08",
    ]  # fmt: skip
    assert json.loads((out / "points" / "x=1" / "point.json").read_text())["config"]["eps"] == 0.25
    entries = json.loads((out / "sweep.json").read_text())["points"]
    assert entries[0]["recomputed_because"] == "stale: config.eps: 99 != 0.25"

    # recomputed, the records match again: reused, with nothing to say
    third = run_sweep(fn, points, out, progress=False)
    assert calls(log) == [1, 2, 1, 2] and len(third.reused) == 2 and not third.recomputed
    # a changed default of the function's configuration recomputes every point
    run_sweep(Toy(str(log), eps=0.5), points, out, progress=False)
    assert calls(log) == [1, 2, 1, 2, 1, 2]


def test_a_point_recorded_with_other_library_versions_is_recomputed(tmp_path):
    log, out = tmp_path / "calls", tmp_path / "sweep"
    fn, points = Toy(str(log)), [{"x": 1}, {"x": 2}, {"x": 3}]
    run_sweep(fn, points, out, progress=False)
    numpy = importlib.metadata.version("numpy")
    ours = importlib.metadata.version("drake-abs")
    edit(out / "points" / "x=1", lambda r: r["provenance"]["dependencies"].update(numpy="0.0.1"))
    edit(out / "points" / "x=2", lambda r: r["provenance"].update(drake_abs_version="0.0.0"))
    edit(out / "points" / "x=3", lambda r: r.pop("provenance"))  # an older drake-abs wrote it
    again = run_sweep(fn, points, out, progress=False)
    assert calls(log) == [1, 2, 3, 1, 2, 3]
    assert [p.recomputed_because for p in again.points] == [
        f"stale: numpy: 0.0.1 != {numpy}",
        f"stale: drake-abs: 0.0.0 != {ours}",
        "stale: no provenance recorded (written before drake-abs recorded it)",
    ]


def test_a_point_that_differs_only_in_its_commit_is_reused(tmp_path):
    log, out = tmp_path / "calls", tmp_path / "sweep"
    fn, points = Toy(str(log)), [{"x": 1}, {"x": 2}]
    run_sweep(fn, points, out, progress=False)
    edit(out / "points" / "x=1", lambda r: r["provenance"].update(commit="f" * 40, dirty=True))
    edit(out / "points" / "x=2", lambda r: r["provenance"].update(commit=None, dirty=None))
    again = run_sweep(fn, points, out, progress=False)
    assert calls(log) == [1, 2] and len(again.reused) == 2
    # the commit each point was computed at is kept, and shown
    assert again.points[0].provenance["commit"] == "f" * 40
    assert [s.state for s in check_sweep(fn, points, out)] == [FRESH, FRESH]


# ------------------------------------------------------------------------------ experiments


def test_an_experiment_point_records_its_whole_resolved_config(monkeypatch):
    """Every field of the point's Config is recorded, also the defaults its values do not
    override, so a changed default recomputes the point."""
    from drake_abs.experiments.catalog import experiment_module

    point = ExperimentPoint("implicit-learning", test_size=True)
    config = point.resolved_config({"seed": 3})
    small = experiment_module("implicit-learning").Config.test_size()
    assert config == json.loads(json.dumps(dataclasses.asdict(dataclasses.replace(small, seed=3))))
    assert config["seed"] == 3 and config["sizes"] == list(small.sizes)
    assert point.describe() == {"experiment": "implicit-learning", "test_size": True}
    module = experiment_module("implicit-learning")
    monkeypatch.setattr(module.Config, "test_size",
                        classmethod(lambda cls: dataclasses.replace(small, eps=0.5)))  # fmt: skip
    assert point.resolved_config({"seed": 3})["eps"] == 0.5


def test_the_command_line_says_why_it_recomputes_a_point(tmp_path, quick, capsys):
    out = tmp_path / "s"
    assert main(sweep(out)) == 0 and quick == [0, 1]
    capsys.readouterr()
    edit(out / "points" / "seed=1", lambda r: r["config"].update(eps=99))
    edit(out / "points" / "seed=0", lambda r: r["provenance"].update(commit="e" * 40, dirty=False))
    assert main(sweep(out)) == 0 and quick == [0, 1, 1]
    text = capsys.readouterr().out
    assert "2 done, 0 failed; 1 run now, 1 reused from an earlier run" in text
    assert "recomputed 1 point whose earlier record could not be reused:" in text
    assert "  seed=1: stale: config.eps: 99 != 0.25" in text
    assert "reused points computed at other commits: eeeeeee: 1 point" in text


# ---------------------------------------------------------------------------------- --check


def test_check_lists_a_stale_point_and_exits_1_and_0_when_all_are_fresh(tmp_path, quick, capsys):
    out = tmp_path / "s"
    assert main(sweep(out, "--check")) == 1 and quick == []  # nothing ran, nothing was written
    assert not out.exists()
    text = capsys.readouterr().out
    assert "  missing     seed=0" in text and "  missing     seed=1" in text
    assert "2 points: 0 fresh, 0 stale, 2 missing, 0 unfinished" in text

    assert main(sweep(out)) == 0 and quick == [0, 1]
    capsys.readouterr()
    assert main(sweep(out, "--check")) == 0
    text = capsys.readouterr().out
    assert "  fresh       seed=0" in text and "every point is fresh" in text

    edit(out / "points" / "seed=1", lambda r: r["config"].update(eps=99))
    edit(out / "points" / "seed=0", lambda r: r["provenance"].update(commit="e" * 40, dirty=False))
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*")}
    assert main(sweep(out, "--check")) == 1 and quick == [0, 1]
    text = capsys.readouterr().out
    assert "  stale       seed=1  config.eps: 99 != 0.25" in text
    assert "  fresh       seed=0  (recorded at commit eeeeeee)" in text
    assert "2 points: 1 fresh, 1 stale, 0 missing, 0 unfinished" in text
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*")} == before  # nothing written

    # a failed point and one whose record is gone are unfinished
    edit(out / "points" / "seed=1", lambda r: r.update(status="failed", error={
        "type": "ValueError", "message": "no good\nat all", "traceback": "..."}))  # fmt: skip
    (out / "points" / "seed=0" / "point.json").unlink()
    assert main(sweep(out, "--check")) == 1
    text = capsys.readouterr().out
    assert "  unfinished  seed=1  failed: ValueError: no good" in text
    assert "  unfinished  seed=0  no readable point.json" in text

    assert main(sweep(out)) == 0 and quick == [0, 1, 0, 1]
    capsys.readouterr()
    assert main(sweep(out, "--check")) == 0


def test_check_states_without_the_command_line(tmp_path):
    log, out = tmp_path / "calls", tmp_path / "sweep"
    fn, points = Toy(str(log)), [{"x": 1}, {"x": 2}, {"x": 3}]
    run_sweep(fn, points[:2], out, progress=False)
    edit(out / "points" / "x=2", lambda r: r["values"].update(x=5))
    states = check_sweep(fn, points, out)
    assert [s.state for s in states] == [FRESH, STALE, MISSING]
    assert states[1].reasons == ("values.x: 5 != 2",) and states[1].reason == "values.x: 5 != 2"
    assert states[2].record is None and not states[2].reasons
    assert calls(log) == [1, 2]  # nothing ran


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--fresh"], "argument --check: not allowed with argument --fresh"),
        (["--set", "eps=big"], "argument --set: 'eps=big': eps: expected a number"),
        (["--workers", "0"], "argument --workers:"),
    ],
)
def test_bad_check_arguments_are_argparse_errors(extra, message, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("drake_abs.parallel.sweep.check_sweep", lambda *a: pytest.fail("ran"))
    with pytest.raises(SystemExit) as exit_:
        main([*sweep(tmp_path / "s", *extra), "--check"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and f"error: {message}" in err, err
    assert "Traceback" not in err


def test_check_is_in_the_sweep_help(capsys):
    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--check" in text and "exits 0 when every point is fresh, 1 otherwise" in text
    assert "exit code 0 when all are fresh, 1 otherwise" in text
