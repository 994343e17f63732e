"""The README's main job at a reduced size: files written, plots not blank, physics sensible."""

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from drake_abs.experiments.bouncing_ball import (
    Config,
    abs_impulse_jump,
    contact_impulse_curves,
    figures,
    frame_camera,
    guide,
    report,
    run,
    simulate,
    step_jacobians,
)
from drake_abs.experiments.cli import main
from drake_abs.experiments.outputs import pyplot


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    return out, run(Config(duration=0.6), out)


def test_demo_writes_every_file(demo):
    out, summary = demo
    for name in ("vy_vs_x", "dvy_dx", "step_jacobian", "contact_impulse"):
        image = np.asarray(Image.open(out / f"{name}.png").convert("L"), dtype=float)
        assert image.std() > 10, f"{name}.png looks blank"
    html = (out / "bouncing_ball.html").read_text()
    assert len(html) > 100_000 and "meshcat" in html.lower()
    assert json.loads((out / "summary.json").read_text())["cases"].keys() == summary["cases"].keys()
    for path in summary["files"].values():  # absolute paths, in the results folder
        assert Path(path).is_absolute() and Path(path).parent == out.resolve()


def test_demo_says_what_to_look_at(demo):
    out, summary = demo
    text = report(summary)
    guide = text.split("What to look at")[1]
    for key in ("vy_vs_x", "dvy_dx", "step_jacobian", "contact_impulse", "meshcat_html"):
        assert summary["files"][key] in guide  # every file, by its absolute path
    assert "exact" in guide and "barrier smoothing" in guide and "ABS" in guide
    assert "-g / v_x = -9.81" in guide and "1/h = 100" in guide
    for mark in ("`", "**", ":func:", "Fixed(", "ContactAware("):
        assert mark not in text


def test_legends_are_readable_names():
    labels = Config().labels()
    assert labels["exact"] == "exact"
    assert labels["bs_mu=0.001"] == "barrier smoothing, mu = 0.001"
    assert labels["abs_contact_aware"] == "adaptive (ABS), contact-aware"
    assert set(labels) == set(Config().cases())
    for label in labels.values():
        assert "(" not in label.replace("(ABS)", "") and "_" not in label, label


def test_meshcat_camera_looks_at_the_balls():
    class FakeMeshcat:
        def SetCameraPose(self, camera, target):
            self.camera, self.target = np.asarray(camera), np.asarray(target)

    config = Config()
    meshcat = FakeMeshcat()
    frame_camera(meshcat, config)
    reach = config.speed * config.duration
    # the target is inside the region the balls fly through (x along the throw, z up)
    assert 0 < meshcat.target[0] < reach and 0 < meshcat.target[2] < config.height
    assert abs(meshcat.target[1]) < 0.1
    distance = np.linalg.norm(meshcat.camera - meshcat.target)
    assert 1.0 < distance < 4.0  # close enough to see the balls, far enough to see the throw
    assert meshcat.camera[1] < meshcat.target[1]  # from the front (the balls spread along y)


def test_demo_physics(demo):
    _, summary = demo
    cases = summary["cases"]
    h = summary["config"]["time_step"]
    exact = cases["exact"]
    # hard contact: the ball stops on the ground, no penetration, and the impact step is stiff
    assert exact["min_height_m"] > -1e-9
    assert abs(exact["final_vy_mps"]) < 1e-6
    assert exact["max_abs_dvy_plus_dy"] == pytest.approx(1 / h, rel=1e-3)
    # barrier smoothing: more smoothing (larger mu) means a less stiff impact step
    bs = [cases[f"bs_mu={mu:g}"]["max_abs_dvy_plus_dy"] for mu in (1e-4, 1e-3, 1e-2)]
    assert bs[0] > bs[1] > bs[2]


def test_cli_without_meshcat(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--duration", "0.2", "--no-meshcat"]) == 0
    text = capsys.readouterr().out
    assert f"results written to {tmp_path.resolve()}" in text
    assert "What to look at" in text and str(tmp_path.resolve() / "dvy_dx.png") in text
    assert (tmp_path / "vy_vs_x.png").exists() and not (tmp_path / "bouncing_ball.html").exists()


def test_demo_summary_splits_the_stiffness_where_abs_and_exact_differ(demo):
    """Over a whole rollout ABS's largest |dv_y+/dy| is exact contact's (1/h): in contact ABS
    is exact contact (mu = 0). The summary reports the approach (z > 0), where they differ,
    apart from the contact steps (issue 35, item 9)."""
    _, summary = demo
    cases = summary["cases"]
    h = summary["config"]["time_step"]
    exact, aware = cases["exact"], cases["abs_contact_aware"]
    for case in (exact, aware):
        assert case["max_abs_dvy_plus_dy_in_contact"] == pytest.approx(1 / h, rel=1e-9)
        assert case["max_abs_dvy_plus_dy"] == case["max_abs_dvy_plus_dy_in_contact"]
        assert case["steps_in_contact"] > 0
    assert exact["max_abs_dvy_plus_dy_approaching"] < 1e-9  # no force at a distance
    approach = aware["max_abs_dvy_plus_dy_approaching"]
    assert 0.1 < approach < 0.5 / h  # smoothing acts before contact, far below 1/h
    for mu in (1e-4, 1e-3, 1e-2):  # and less than barrier smoothing's, at any of its mu
        assert approach < cases[f"bs_mu={mu:g}"]["max_abs_dvy_plus_dy_approaching"]
    text = report(summary)
    assert "approaching" in text and "in contact" in text
    assert f"ABS's {approach:.3g} 1/s" in text and "is exact contact (mu = 0)" in text


def test_abs_impulse_jumps_at_contact_by_the_stated_amount(demo):
    """The contact-aware ABS impulse tends to sqrt(mu_max m / h) as z -> 0+ and is exact
    contact's 0 at z = 0: the step the guide explains."""
    _, summary = demo
    config = Config(meshcat=False)
    impulse = contact_impulse_curves(config, np.array([-1e-9, 0.0, 1e-9]))["abs_contact_aware"]
    jump = abs_impulse_jump(config)
    assert jump == pytest.approx(1.0)  # 1 N s with the defaults
    assert impulse[2] == pytest.approx(jump, rel=1e-6)
    assert impulse[1] < 1e-9 and impulse[0] == pytest.approx(1e-9 * config.mass / config.time_step)
    assert "sqrt(mu_max m / h) = 1 N s" in guide(summary)


def test_dvy_dx_symlog_axis_labels_negative_ticks():
    config = Config(duration=0.6, meshcat=False)
    trajectories = simulate(config)
    jac = {
        name: step_jacobians(config, trajectories[name], s) for name, s in config.cases().items()
    }
    figs = figures(config, trajectories, jac)
    try:
        ax = figs["dvy_dx"].axes[0]
        assert ax.get_yscale() == "symlog"
        figs["dvy_dx"].canvas.draw()
        low, high = ax.get_ylim()
        labels = {t.get_position()[1]: t.get_text() for t in ax.get_yticklabels()
                  if low <= t.get_position()[1] <= high}  # fmt: skip
        negative = {v: s for v, s in labels.items() if v < 0}
        assert negative and all(s.startswith("\u2212") for s in negative.values()), labels
        assert labels[-10.0] == "\u221210" and labels[0.0] == "0"  # -g / v_x = -9.81 is readable
        assert any(v >= 100 and "10^{2}" in s for v, s in labels.items())  # the impact spike
        assert all(labels.values())  # every tick labelled
    finally:
        for fig in figs.values():
            pyplot().close(fig)
