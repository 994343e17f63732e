"""The README's main job at a reduced size: files written, plots not blank, physics sensible."""

import json

import numpy as np
import pytest
from PIL import Image

from drake_abs.experiments.bouncing_ball import Config, run
from drake_abs.experiments.cli import main


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
    assert "results written to" in capsys.readouterr().out
    assert (tmp_path / "vy_vs_x.png").exists() and not (tmp_path / "bouncing_ball.html").exists()
