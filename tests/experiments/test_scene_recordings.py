"""The scene recordings' rollouts (issue 14, item 4) do what the physics says (the pages are
written to a temporary folder; they are checked in a browser in
tests/diagrams/test_meshcat_render.py):
the robots land and stand on their feet, Solo12's stepping moves its feet, and the pushed box
behaves as quasi-static pushing predicts (a push through the centre line translates it, a push
to one side turns it away from that side, and the mirrored push mirrors the motion)."""

from pathlib import Path

import numpy as np
import pytest

from drake_abs.experiments.scene_recordings import Config, report, rollout, run


@pytest.fixture(scope="module")
def legged(tmp_path_factory):
    names = ("solo12_standing", "solo12_stepping", "go1_standing")
    out = tmp_path_factory.mktemp("recordings")
    summary = run(Config(duration=1.0, recordings=names), out)
    assert set(summary["files"]) == {*names, "summary"}
    for path in summary["files"].values():  # absolute paths of written files
        assert Path(path).is_absolute() and Path(path).is_file()
    return {r["recording"]: r for r in summary["rows"]}


def test_quadrupeds_land_and_stand(legged):
    for name in ("solo12_standing", "go1_standing"):
        r = legged[name]
        assert r["unconverged_steps"] == 0 and r["deepest_penetration_m"] < 1e-6
        assert 0.2 < r["base_height_end_m"] < r["base_height_start_m"], r  # landed, upright
        sm, xs, _ = rollout(name, 1.0)
        nq = sm.contact_model.nq
        feet = sm.contact_model.distances(xs[-1:, :nq])[0, :4]  # (solo12's base corners follow)
        assert np.abs(feet).max() < 1e-3, feet  # all four feet on the ground
        assert np.abs(xs[-1, nq:]).max() < 0.05  # at rest (rad/s, m/s)
    assert legged["solo12_stepping"]["unconverged_steps"] == 0


def test_stepping_moves_the_feet_where_standing_holds_them():
    _, standing, _ = rollout("solo12_standing", 1.0)
    sm, stepping, _ = rollout("solo12_stepping", 1.0)
    nq = sm.contact_model.nq
    spread = [np.ptp(sm.contact_model.distances(xs[100:, :nq]), axis=0).max()
              for xs in (standing, stepping)]  # fmt: skip
    assert spread[0] < 5e-3 < spread[1], spread  # feet lift (m) only when stepping


def test_pushed_box_follows_quasi_static_pushing(tmp_path):
    rows = {}
    for offset in (0.0, 0.05, -0.05):
        config = Config(duration=1.5, recordings=("pusher_box",), push_offset=offset)
        summary = run(config, tmp_path / f"offset_{offset:g}")
        rows[offset] = summary["rows"][0]
        assert rows[offset]["unconverged_steps"] == 0
    centre, left, right = rows[0.0], rows[0.05], rows[-0.05]
    assert centre["box_displacement_m"][0] > 0.05  # pushed along +x
    assert abs(centre["box_yaw_rad"]) < 1e-6 and abs(centre["box_displacement_m"][1]) < 1e-6
    assert left["box_yaw_rad"] < -0.05  # pushed on its +y side: turns clockwise
    np.testing.assert_allclose(right["box_yaw_rad"], -left["box_yaw_rad"], rtol=1e-6)
    np.testing.assert_allclose(
        right["box_displacement_m"], left["box_displacement_m"] * np.array([1, -1]), atol=1e-6
    )
    assert "pusher_box" in report({"duration_s": 1.5, "rows": [left]})


@pytest.mark.parametrize(
    "config, match",
    [
        (Config(duration=0.0), "duration"),
        (Config(duration=float("nan")), "duration"),
        (Config(push_offset=float("inf")), "push_offset"),
        (Config(recordings=("hopper_x",)), "recordings"),
    ],
)
def test_bad_configs_are_refused_by_name(config, match, tmp_path):
    with pytest.raises(ValueError, match=match):
        run(config, tmp_path / "out")
    assert not (tmp_path / "out").exists()  # refused before anything is written
