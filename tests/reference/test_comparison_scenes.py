"""The box and ball the comparison experiments share: each scene's start is its initial state,
the settings reach the scene (friction, speeds, step, activation distance), the rigid-body
slopes are the derivatives of their closed forms, and bad names are refused."""

import numpy as np
import pytest

from drake_abs.multibody import build_scene_model
from drake_abs.reference.comparison_scenes import BALL_RADIUS, GRAVITY, ComparisonScenes


@pytest.mark.parametrize("name", ["box", "ball"])
def test_start_is_the_scenes_initial_state(name):
    scenes = ComparisonScenes(friction=0.3, box_speed=0.7, ball_height=0.4, ball_speed=1.5)
    model = build_scene_model(scenes.scene(name, 0.005))
    x0, u, duration = scenes.start(name)
    np.testing.assert_array_equal(model.x0, x0)
    assert u.shape == (model.contact_model.nu,)
    assert duration == (scenes.box_duration if name == "box" else scenes.ball_duration)
    spec = model.scene
    assert spec.time_step == 0.005 and spec.smoothing_policy().is_exact
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
