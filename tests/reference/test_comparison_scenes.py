"""The box and ball the comparison experiments share: each scene's start is its initial state,
the settings reach the scene (friction, speeds, step, activation distance), the rigid-body
slopes are the derivatives of their closed forms, the Coulomb slide is the recursion's, the
trajectory measures read penetration, slide, hop, rebound and slip, and bad input is refused."""

import numpy as np
import pytest

from drake_abs.multibody import build_scene_model
from drake_abs.reference.comparison_scenes import (
    BALL_RADIUS,
    BOX_HALF,
    GRAVITY,
    ComparisonScenes,
    ball_metrics,
    box_metrics,
)


@pytest.mark.parametrize("name", ["box", "ball"])
def test_start_is_the_scenes_initial_state(name):
    scenes = ComparisonScenes(friction=0.3, box_speed=0.7, ball_height=0.4, ball_speed=1.5)
    model = build_scene_model(scenes.scene(name, 0.005))
    x0, u, duration = scenes.start(name)
    np.testing.assert_array_equal(model.x0, x0)
    assert u.shape == (model.contact_model.nu,)
    assert duration == (scenes.box_duration if name == "box" else scenes.ball_duration)
    spec = model.scene
    assert spec.time_step == 0.005 and spec.make_smoothing().is_exact
    assert spec.activation_distance == scenes.activation_distance[name == "ball"]
    assert {c.friction for c in spec.contacts} == {0.3}


def test_the_ball_has_one_sphere_and_no_actuator():
    spec = ComparisonScenes().scene("ball")
    assert spec.num_contacts == 1 and spec.contacts[0].radius == BALL_RADIUS
    assert build_scene_model(spec).contact_model.nu == 0
    assert spec.time_step == ComparisonScenes().time_step


def _derivative(f, x, eps=1e-6):
    return (f(x + eps) - f(x - eps)) / (2 * eps)


def test_rigid_slopes_are_the_closed_forms_derivatives():
    s = ComparisonScenes(box_push=1.0)  # stops before box_duration: a = mu g - u
    a = s.friction * GRAVITY - s.box_push
    slopes = s.rigid_slopes("box")
    assert s.box_speed / a < s.box_duration
    assert slopes["dx_T/dvx_0"] == pytest.approx(_derivative(lambda v: v**2 / (2 * a), s.box_speed))
    slide_of_u = lambda u: s.box_speed**2 / (2 * (s.friction * GRAVITY - u))  # noqa: E731
    assert slopes["dx_T/du"] == pytest.approx(_derivative(slide_of_u, s.box_push))
    moving = ComparisonScenes(box_duration=0.1).rigid_slopes("box")  # still sliding at T
    assert moving["dx_T/dvx_0"] == 0.1 and moving["dvx_T/dvx_0"] == 1.0

    def y_T(v0, z0):  # falls, lands inelastically, rolls at 5/7 v0
        t_land = np.sqrt(2 * (z0 - BALL_RADIUS) / GRAVITY)
        return v0 * t_land + 5 / 7 * v0 * (s.ball_duration - t_land)

    ball = s.rigid_slopes("ball")
    v0, z0 = s.ball_speed, s.ball_height
    assert ball["dy_T/dvy_0"] == pytest.approx(_derivative(lambda v: y_T(v, z0), v0))
    assert ball["dy_T/dz_0"] == pytest.approx(_derivative(lambda z: y_T(v0, z), z0), rel=1e-6)


def test_drake_material_is_the_settings():
    s = ComparisonScenes(point_stiffness=2e5, relaxation_time=0.05)
    assert s.drake_material() == {
        "point_stiffness": 2e5, "hunt_crossley_dissipation": 50.0, "relaxation_time": 0.05,
    }  # fmt: skip


@pytest.mark.parametrize("method", ["scene", "start", "rigid_slopes"])
def test_unknown_scene_is_refused(method):
    with pytest.raises(ValueError, match=r"scene must be one of \('box', 'ball'\); got 'cube'"):
        getattr(ComparisonScenes(), method)("cube")


@pytest.mark.parametrize("h", [0.01, 0.003])
def test_coulomb_slide_is_the_step_recursion_and_the_continuous_stop(h):
    s = ComparisonScenes(box_push=1.0, box_duration=1.0)
    a = s.friction * GRAVITY - s.box_push
    v, x = s.box_speed, 0.0
    for _ in range(int(round(s.box_duration / h))):  # semi-implicit Euler until it stops
        v = max(0.0, v - a * h)
        x += h * v
    slide = s.coulomb_slide(h)
    assert slide["discrete_m"] == pytest.approx(x, abs=1e-12)
    assert slide["continuous_m"] == pytest.approx(s.box_speed**2 / (2 * a), rel=1e-12)
    assert slide["deceleration_mps2"] == pytest.approx(a)
    assert ComparisonScenes(box_push=10.0).coulomb_slide(h) == {
        "continuous_m": None, "discrete_m": None,
    }  # fmt: skip
    with pytest.raises(ValueError, match="time_step"):
        s.coulomb_slide(0.0)


def test_box_metrics_read_penetration_slide_and_hop():
    n = 5
    xs = np.zeros((n, 6))
    xs[:, 0] = np.linspace(0.0, 0.2, n)  # slides 0.2 m
    xs[:, 1] = BOX_HALF[1]
    xs[0, 1] -= 1e-4  # starts 0.1 mm into the ground
    xs[2, 1] += 3e-3  # hops 3 mm
    xs[-1, 3] = 0.01
    m = box_metrics(xs, xs[0], {"continuous_m": 0.25, "discrete_m": None})
    assert m["slide_m"] == pytest.approx(0.2)
    assert m["max_penetration_m"] == pytest.approx(1e-4)
    assert m["rest_penetration_before_push_m"] == pytest.approx(1e-4)
    assert m["hop_m"] == pytest.approx(3e-3 + 1e-4)
    assert m["rel_err_vs_continuous"] == pytest.approx(-0.2) and m["rel_err_vs_discrete"] is None
    assert m["final"]["speed_mps"] == pytest.approx(0.01)
    tilted = xs.copy()
    tilted[:, 2] = 0.1  # the lower edge dips by a sin(pitch) + c (1 - cos(pitch))
    dip = BOX_HALF[0] * np.sin(0.1) - BOX_HALF[1] * (1 - np.cos(0.1))
    assert box_metrics(tilted, tilted[0])["max_penetration_m"] == pytest.approx(dip + 1e-4)
    with pytest.raises(ValueError, match="xs must be"):
        box_metrics(xs[:, :3], xs[0])


def test_ball_metrics_read_impact_rebound_rest_and_slip():
    xs = np.zeros((6, 12))
    xs[:, 2] = BALL_RADIUS + np.array([0.3, 0.1, -0.002, 0.01, 0.0, -1e-4])
    xs[:, 8] = [-1.0, -2.0, -2.2, 0.5, -0.1, 0.0]  # falls, turns up at step 3
    xs[-1, 7], xs[-1, 11] = 0.7, -10.0  # v_y, roll rate: slip 0.7 - 0.05 * 10 = 0.2 m/s
    m = ball_metrics(xs)
    assert m["impact_step"] == 3 and m["max_penetration_m"] == pytest.approx(0.002)
    assert m["rebound_height_m"] == pytest.approx(0.01)
    assert m["rest_height_m"] == pytest.approx(-1e-4)
    assert m["final"]["slip_mps"] == pytest.approx(0.7 - BALL_RADIUS * 10.0)
    with pytest.raises(ValueError, match="xs must be"):
        ball_metrics(xs[:, :6])
