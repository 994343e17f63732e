"""Sweeps (drake_abs.parallel.sweep, drake_abs.experiments.sweep, drake-abs sweep): a sweep of a
real experiment gathers into the same sweep.json and sweep.csv in this process and on a local
2-CPU Ray cluster; a resumed sweep recomputes nothing, and only what was deleted; a point that
raises is recorded with its traceback while the others complete; a point whose worker process
is killed is run again and the sweep is complete and equal to the local one; the command line
runs a sweep on Ray end to end and refuses bad arguments as argparse does, naming the option."""

from __future__ import annotations

import csv
import json
import os
import signal
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ray = pytest.importorskip("ray")

from ray import cloudpickle  # noqa: E402

from drake_abs.experiments import cli  # noqa: E402
from drake_abs.experiments.cli import main  # noqa: E402
from drake_abs.experiments.sweep import ExperimentPoint, GridError, build_grid  # noqa: E402
from drake_abs.parallel.cluster import connect, shutdown  # noqa: E402
from drake_abs.parallel.sweep import run_sweep  # noqa: E402
from drake_abs.parallel.sweep_points import point_name, point_names  # noqa: E402

# The functions and classes below go to the workers by value (they cannot import tests/).
cloudpickle.register_pickle_by_value(sys.modules[__name__])


def timing(key: str) -> bool:
    """Keys of wall times (seconds, seconds_per_estimate, variance_seconds): they differ
    between any two runs."""
    return "seconds" in key.rsplit(".", 1)[-1]


#: A small real experiment: the gradient variance at one short horizon, two sample sizes.
SETTINGS = ["horizons=[10]", "samples=8,16"]


@pytest.fixture(scope="module")
def cluster():
    connect(num_cpus=2)
    yield
    shutdown()


# ---------------------------------------------------------------------------- point functions


@dataclass(frozen=True)
class Counted:
    """Squares ``values["x"]``; every call appends the point's x to the file ``log``."""

    log: str

    def __call__(self, values: dict, folder: Path) -> dict:
        with open(self.log, "a") as f:
            f.write(f"{values['x']}\n")
        (folder / "note.txt").write_text(f"x = {values['x']}, folder {folder}\n")
        return {"x": values["x"], "square": values["x"] ** 2, "folder": str(folder)}


def calls(log: Path) -> list[int]:
    return [int(line) for line in log.read_text().split()] if log.exists() else []


def fragile(values: dict, folder: Path) -> dict:
    """Writes a file, then raises for x == 2."""
    (folder / "partial.txt").write_text("written before the error\n")
    if values["x"] == 2:
        raise ValueError(f"no good: {values['x']}")  # the raising line
    return {"square": values["x"] ** 2}


@dataclass(frozen=True)
class DieOnce:
    """For x == 1, the first attempt kills its own process (never the test's: ``driver_pid``);
    the marker files in ``markers`` record the attempts."""

    markers: str
    driver_pid: int

    def __call__(self, values: dict, folder: Path) -> dict:
        x = values["x"]
        first = Path(self.markers) / f"{x}.first"
        if x == 1 and not first.exists() and os.getpid() != self.driver_pid:
            first.write_text(str(os.getpid()))
            os.kill(os.getpid(), signal.SIGKILL)
        if first.exists():
            (Path(self.markers) / f"{x}.again").write_text(str(os.getpid()))
        return {"x": x, "cube": x**3}


# ---------------------------------------------------------------------------------- comparison


def _untimed(value, out: Path):
    """``value`` without wall times, with the sweep folder ``out`` written as OUT."""
    if isinstance(value, dict):
        return {k: _untimed(v, out) for k, v in value.items() if not timing(k)}
    if isinstance(value, list):
        return [_untimed(v, out) for v in value]
    if isinstance(value, str):
        return value.replace(str(out), "OUT")
    return value


def _csv(out: Path) -> list[dict]:
    with open(out / "sweep.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return [{k: v.replace(str(out), "OUT") for k, v in r.items() if not timing(k)} for r in rows]


def _points(out: Path) -> list[dict]:
    """The points of sweep.json without what differs between two runs of the same points: the
    reuse, and the provenance (a commit or an edit may come between them)."""
    doc = json.loads((out / "sweep.json").read_text())
    drop = ("reused", "provenance")
    return [_untimed({k: v for k, v in p.items() if k not in drop}, out) for p in doc["points"]]


def _files(out: Path) -> dict[str, list[str]]:
    return {p.name: sorted(f.name for f in p.iterdir()) for p in (out / "points").iterdir()}


# ------------------------------------------------------------------------------- names, checks


def test_point_names_are_readable_deterministic_and_distinct():
    assert point_name({"seed": 0, "horizon": 10}) == "seed=0,horizon=10"
    assert point_name({"mu": 1e-5, "abs": True, "h": (10, 50)}) == "mu=1e-05,abs=true,h=10+50"
    assert point_name({}) == "default"
    odd = point_name({"path": "a/b c"})
    assert odd.startswith("path=a_b_c~") and odd == point_name({"path": "a/b c"})
    assert point_name({"path": "a/b c"}) != point_name({"path": "a b/c"})
    assert len(point_name({"k": "x" * 500})) <= 120
    one, text = point_names([{"x": 1}, {"x": "1"}])  # the same readable name: both digested
    assert one != text and one.startswith("x=1~") and text.startswith("x=1~")


@pytest.mark.parametrize(
    "points, kwargs, match",
    [
        ([], {}, "points must hold at least one"),
        ({"x": 1}, {}, "points must be a list"),
        ([{"x": 1}, 2], {}, r"points\[1\] must be a dict"),
        ([{"x": 1}, {"x": 1}], {}, r"points\[1\] duplicates points\[0\]"),
        ([{"x": object()}], {}, r"points\[0\]\['x'\] must be a number"),
        ([{"": 1}], {}, "keys must be non-empty strings"),
        ([{"x": 1}], {"backend": "dask"}, "backend must be one of 'local', 'ray'"),
        ([{"x": 1}], {"num_cpus": 2}, "num_cpus are for backend='ray'"),
        ([{"x": 1}], {"max_retries": -1}, "max_retries must be a whole number >= 0"),
    ],
)
def test_bad_arguments_are_refused_by_name(tmp_path, points, kwargs, match):
    with pytest.raises(ValueError, match=match):
        run_sweep(Counted(str(tmp_path / "log")), points, tmp_path / "out", **kwargs)
    assert not (tmp_path / "log").exists()  # refused before anything ran
    with pytest.raises(TypeError, match="fn must be callable"):
        run_sweep("not a function", [{"x": 1}], tmp_path / "out")
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="out must be a folder"):
        run_sweep(Counted(str(tmp_path / "log")), [{"x": 1}], tmp_path / "file")


def test_overrides_are_checked_and_converted():
    point = ExperimentPoint("gradient-variance", test_size=True)
    config = point.config({"samples": 8.0, "sigma": 2, "horizons": [10], "contact_aware": [1, 2]})
    assert config.samples == 8 and type(config.samples) is int
    assert config.sigma == 2.0 and type(config.sigma) is float
    assert config.horizons == (10,) and config.contact_aware == (1.0, 2.0)
    assert point.config({"horizons": 25}).horizons == (25,)  # one item: a one-item tuple
    assert point.config({"gaussian_sigma": "1e-4"}).gaussian_sigma == 1e-4  # YAML's text
    for bad, match in [
        ({"sampels": 8}, "unknown setting 'sampels'; the settings are: horizons, fixed_mus"),
        ({"samples": 8.5}, "samples: expected a whole number, got 8.5"),
        ({"samples": True}, "samples: expected a whole number"),
        ({"sigma": "wide"}, "sigma: expected a number"),
        ({"contact_aware": [1, 2, 3]}, "contact_aware: expected a list of 2 items"),
    ]:
        with pytest.raises(ValueError, match=match):
            point.config(bad)


def test_the_grid_is_seeds_times_settings_split_on_top_level_commas():
    points = build_grid(
        "gradient-variance",
        seeds=[0, 1],
        settings=["horizons=[10,50],(100)", "fixed_mus=[1e-4, 0.1]", "samples=8,16"],
        test_size=True,
    )
    assert len(points) == 2 * 2 * 1 * 2
    assert points[0] == {"seed": 0, "horizons": (10, 50), "fixed_mus": (1e-4, 0.1), "samples": 8}
    assert points[3] == {"seed": 0, "horizons": (100,), "fixed_mus": (1e-4, 0.1), "samples": 16}
    assert [p["seed"] for p in points] == [0] * 4 + [1] * 4  # seed-major
    assert build_grid("gradient-variance", settings=["samples=8"]) == [{"samples": 8}]
    assert build_grid("box-convergence") == [{}]  # one point: the Config as it is
    with pytest.raises(GridError, match="no 'seed' setting") as err:
        build_grid("box-convergence", seeds=[0])
    assert err.value.argument == "--seeds"


def test_dotted_settings_reach_nested_groups():
    points = build_grid("gym-locomotion", settings=["settings.shac.window=8,16"], test_size=True)
    assert points == [{"settings.shac.window": 8}, {"settings.shac.window": 16}]
    config = ExperimentPoint("gym-locomotion", test_size=True).config(points[1])
    assert config.settings.shac.window == 16 and config.settings.shac.envs == 4
    with pytest.raises(GridError, match="unknown setting 'settings.shac.nope'"):
        build_grid("gym-locomotion", settings=["settings.shac.nope=1"], test_size=True)
    with pytest.raises(GridError, match="settings.shac.window"):
        build_grid("gym-locomotion", settings=["settings.shac.window=wide"], test_size=True)


# --------------------------------------------------------------------------- a real experiment


def test_an_experiment_sweep_gathers_the_same_here_and_on_ray(cluster, tmp_path):
    point = ExperimentPoint("gradient-variance", test_size=True)
    points = build_grid("gradient-variance", seeds=[0, 1], settings=SETTINGS, test_size=True)
    here = run_sweep(point, points, tmp_path / "local", progress=False)
    there = run_sweep(point, points, tmp_path / "ray", backend="ray", progress=False)
    for result in (here, there):
        assert not result.failures and len(result.computed) == 4
        assert set(result.files) == {"json", "csv", "png"}
        assert result.metric == "curves.exact.variance.0"
    assert _csv(tmp_path / "local") == _csv(tmp_path / "ray")
    assert _points(tmp_path / "local") == _points(tmp_path / "ray")
    assert [p.summary["curves"] for p in here.points] == [p.summary["curves"] for p in there.points]
    assert _files(tmp_path / "local") == _files(tmp_path / "ray")
    names = ["seed=0,horizons=10,samples=8", "seed=0,horizons=10,samples=16",
             "seed=1,horizons=10,samples=8", "seed=1,horizons=10,samples=16"]  # fmt: skip
    assert [p.name for p in there.points] == names
    folder = tmp_path / "ray" / "points" / names[0]
    assert sorted(_files(tmp_path / "ray")[names[0]]) == [
        "bias.png", "figure3_variance.png", "point.json", "summary.json",
    ]  # fmt: skip
    # the experiment's own paths name the point's folder, not the worker's temporary one
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["folder"] == str(folder)
    assert all(Path(p).parent == folder and Path(p).is_file() for p in summary["files"].values())
    record = json.loads((folder / "point.json").read_text())
    assert record["status"] == "done" and record["values"]["horizons"] == [10]
    assert record["summary"]["folder"] == str(folder)
    # different seeds and sample sizes, different variances: the plot has something to show
    variances = {p.summary["curves"]["exact"]["variance"][0] for p in here.points}
    assert len(variances) == 4
    # resumed here, the Ray sweep is reused whole and gathers into the same table
    before = (tmp_path / "ray" / "sweep.csv").read_bytes()
    again = run_sweep(point, points, tmp_path / "ray", progress=False)
    assert len(again.reused) == 4 and not again.computed
    assert (tmp_path / "ray" / "sweep.csv").read_bytes() == before


# ----------------------------------------------------------------------------- resume, faults


def test_a_resumed_sweep_recomputes_nothing_and_then_only_a_deleted_point(cluster, tmp_path):
    log = tmp_path / "calls"
    fn = Counted(str(log))
    points = [{"x": x} for x in range(4)]
    out = tmp_path / "sweep"
    first = run_sweep(fn, points, out, backend="ray", progress=False)
    assert sorted(calls(log)) == [0, 1, 2, 3] and not first.reused
    records = {p.name: (out / "points" / p.name / "point.json") for p in first.points}
    stamps = {name: path.stat().st_mtime_ns for name, path in records.items()}
    table = (out / "sweep.csv").read_bytes()

    second = run_sweep(fn, points, out, progress=False)  # resumed locally: nothing to do
    assert sorted(calls(log)) == [0, 1, 2, 3]
    assert len(second.reused) == 4 and not second.computed
    assert {name: path.stat().st_mtime_ns for name, path in records.items()} == stamps
    assert (out / "sweep.csv").read_bytes() == table  # nothing here depends on time

    import shutil

    shutil.rmtree(out / "points" / "x=2")
    third = run_sweep(fn, points, out, backend="ray", progress=False)
    assert sorted(calls(log)) == [0, 1, 2, 2, 3]
    assert [p.name for p in third.computed] == ["x=2"]
    assert (out / "points" / "x=2" / "note.txt").read_text().endswith(f"{out}/points/x=2\n")
    assert (out / "sweep.csv").read_bytes() == table

    run_sweep(fn, points, out, resume=False, progress=False)
    assert sorted(calls(log)) == [0, 0, 1, 1, 2, 2, 2, 3, 3]
    # a record of other values or of another function is not reused
    run_sweep(Counted(str(tmp_path / "other")), points, out, progress=False)
    assert sorted(calls(tmp_path / "other")) == [0, 1, 2, 3]


@pytest.mark.parametrize("backend", ["local", "ray"])
def test_a_failing_point_is_recorded_with_its_traceback(cluster, tmp_path, backend):
    out = tmp_path / "sweep"
    result = run_sweep(fragile, [{"x": x} for x in range(4)], out, backend=backend,
                       progress=False)  # fmt: skip
    assert [p.status for p in result.points] == ["done", "done", "failed", "done"]
    (failed,) = result.failures
    assert failed.name == "x=2" and failed.error["type"] == "ValueError"
    assert failed.error["message"] == "no good: 2"
    trace = failed.error["traceback"]
    assert "in fragile" in trace and "raise ValueError(f\"no good: {values['x']}\")" in trace
    record = json.loads((out / "points" / "x=2" / "point.json").read_text())
    assert record["status"] == "failed" and record["error"]["traceback"] == trace
    assert (out / "points" / "x=2" / "partial.txt").is_file()  # what it wrote is kept
    rows = list(csv.DictReader(open(out / "sweep.csv", newline="")))
    assert [r["status"] for r in rows] == ["done", "done", "failed", "done"]
    assert rows[2]["error"] == "ValueError: no good: 2" and rows[3]["square"] == "9"
    doc = json.loads((out / "sweep.json").read_text())
    assert doc["counts"] == {"done": 3, "failed": 1, "reused": 0}
    assert doc["points"][2]["error"]["traceback"] == trace
    assert result.files["png"].is_file() and result.metric == "square"
    again = run_sweep(fragile, [{"x": x} for x in range(4)], out, progress=False)
    assert [p.name for p in again.computed] == ["x=2"]  # a failed point is tried again


def test_a_killed_worker_is_retried_and_the_sweep_equals_the_local_one(cluster, tmp_path):
    markers = tmp_path / "markers"
    markers.mkdir()
    fn = DieOnce(str(markers), os.getpid())
    points = [{"x": x} for x in range(3)]
    there = run_sweep(fn, points, tmp_path / "ray", backend="ray", progress=False)
    assert not there.failures
    killed = int((markers / "1.first").read_text())
    assert killed != os.getpid() and (markers / "1.again").is_file()  # run again after its death
    here = run_sweep(fn, points, tmp_path / "local", progress=False)
    assert [p.summary for p in there.points] == [p.summary for p in here.points]
    assert _csv(tmp_path / "ray") == _csv(tmp_path / "local")
    assert _points(tmp_path / "ray") == _points(tmp_path / "local")


def test_a_worker_that_always_dies_fails_its_point_only(cluster, tmp_path):
    markers = tmp_path / "markers"
    markers.mkdir()
    fn = DieOnce(str(markers), os.getpid())
    result = run_sweep(fn, [{"x": x} for x in range(3)], tmp_path / "ray", backend="ray",
                       max_retries=0, progress=False)  # fmt: skip
    assert [p.status for p in result.points] == ["done", "failed", "done"]
    error = result.failures[0].error
    assert "died" in error["message"].lower() or "crash" in error["traceback"].lower(), error


# -------------------------------------------------------------------------------- command line


def test_the_command_line_runs_a_sweep_on_ray(cluster, tmp_path, capsys):
    argv = ["sweep", "gradient_variance", "--test-size", "--seeds", "0", "1",
            "--set", "horizons=[10]", "--set", "batches=6,1", "--ray", "--out",
            str(tmp_path / "s"), "--no-progress"]  # fmt: skip
    assert main(argv) == 1  # batches=1 is refused by the experiment: that point fails
    captured = capsys.readouterr()
    folder = (tmp_path / "s").resolve()
    assert f"results written to {folder}" in captured.out
    assert "4 points on ray: 2 done, 2 failed; 4 run now, 0 reused from an earlier run" in (
        captured.out
    )
    assert "FAILED seed=0,horizons=10,batches=1: ValueError: batches must be" in captured.out
    assert f"traceback in {folder}/points/seed=0,horizons=10,batches=1/point.json" in captured.out
    assert "2 of 4 points failed" in captured.err
    doc = json.loads((folder / "sweep.json").read_text())
    assert (
        doc["backend"] == "ray"
        and doc["fn"] == ExperimentPoint("gradient-variance", test_size=True).describe()
    )
    assert doc["fn"]["experiment"] == "gradient-variance" and doc["fn"]["test_size"] is True
    assert [p["status"] for p in doc["points"]] == ["done", "failed", "done", "failed"]
    assert (folder / "sweep.png").is_file() and (folder / "sweep.csv").is_file()
    # resumed: only the failed points run again (and fail again)
    assert main(argv[:-3] + ["--out", str(folder), "--no-progress"]) == 1
    assert "2 done, 2 failed; 2 run now, 2 reused from an earlier run" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["gradient-variance", "--set", "sampels=8"],
         "argument --set: 'sampels=8': unknown setting 'sampels'; the settings are: horizons"),
        (["gradient-variance", "--set", "samples=eight"],
         "argument --set: 'samples=eight': samples: expected a whole number, got 'eight'"),
        (["gradient-variance", "--set", "samples"], "argument --set: expected KEY=V1,V2"),
        (["gradient-variance", "--set", "samples=8", "--set", "samples=16"],
         "argument --set: samples is set twice"),
        (["box-convergence", "--seeds", "0", "1"],
         "argument --seeds: box-convergence has no 'seed' setting"),
        (["gradient-variance", "--seeds", "-1"], "argument --seeds: expected a whole number >= 0"),
        (["gradient-variance", "--address", "auto", "--workers", "2"], "argument --workers:"),
        (["gradient-variance", "--workers", "0"], "argument --workers:"),
        (["no-such-experiment"], "argument NAME: invalid choice"),
    ],
)  # fmt: skip
def test_bad_sweep_arguments_are_argparse_errors(argv, message, capsys, monkeypatch):
    monkeypatch.setattr("drake_abs.parallel.sweep.run_sweep", lambda *a, **k: pytest.fail("ran"))
    with pytest.raises(SystemExit) as exit_:
        main(["sweep", *argv])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: drake-abs sweep") and f"error: {message}" in err, err
    assert "Traceback" not in err


def test_sweep_help_is_plain_text(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["sweep", "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith("usage: drake-abs sweep") and "--seeds" in text and "--ray" in text
    assert not any(mark in text for mark in ("`", "**", ":func:", ":class:"))
    assert "sweep" in cli.__doc__
