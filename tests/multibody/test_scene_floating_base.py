"""A scene's floating bases switched between roll-pitch-yaw chains and quaternion floating
joints, its initial state carried over (every body's pose and spatial velocity kept)."""

import numpy as np
import pytest
from floating_scenes import TOSSED
from pydrake.multibody.tree import BodyIndex

from drake_abs.multibody import Scene, build_scene_model
from drake_abs.multibody.scene_floating_base import with_floating_base


def _motion(scene: Scene) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every body's world pose (4 x 4) and spatial velocity (6,) in the scene's initial state."""
    model = build_scene_model(scene)
    plant = model.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, model.q0)
    plant.SetVelocities(context, model.v0)
    out = {}
    for i in range(1, plant.num_bodies()):
        body = plant.get_body(BodyIndex(i))
        out[body.name()] = (
            plant.EvalBodyPoseInWorld(context, body).GetAsMatrix4(),
            plant.EvalBodySpatialVelocityInWorld(context, body).get_coeffs(),
        )
    return out


def test_the_initial_state_is_carried_to_a_quaternion_base_and_back():
    scene = Scene.from_dict(TOSSED)
    quaternion = with_floating_base(scene, "quaternion")
    assert [m.floating_base for m in quaternion.models] == ["quaternion"]
    q = np.array(quaternion.initial_state.q)
    assert q.shape == (7,) and np.linalg.norm(q[:4]) == pytest.approx(1.0, abs=1e-15)
    before, after = _motion(scene), _motion(quaternion)
    X, V = before["box"]
    np.testing.assert_allclose(after["box"][0], X, atol=1e-14)
    np.testing.assert_allclose(after["box"][1], V, atol=1e-13)
    assert np.abs(V[:3]).max() > 1.0  # it does spin
    back = with_floating_base(quaternion, "euler")
    np.testing.assert_allclose(back.initial_state.q, TOSSED["initial_state"]["q"], atol=1e-14)
    np.testing.assert_allclose(back.initial_state.v, TOSSED["initial_state"]["v"], atol=1e-13)


def test_joints_of_the_files_keep_their_coordinates():
    scene = Scene.load("solo12_drop")
    quaternion = with_floating_base(scene, "quaternion")
    q_old, q_new = np.array(scene.initial_state.q), np.array(quaternion.initial_state.q)
    np.testing.assert_array_equal(q_new[7:], q_old[6:])  # the legs' joints, as given
    np.testing.assert_allclose(q_new[4:7], q_old[:3], atol=1e-15)  # the trunk's position
    before, after = _motion(scene), _motion(quaternion)
    for name in ("base_link", "FL_LOWER_LEG", "HR_FOOT"):
        np.testing.assert_allclose(after[name][0], before[name][0], atol=1e-14)


def test_unchanged_scenes_and_bad_names():
    box = Scene.load("box_push")  # planar joints: no free body
    assert with_floating_base(box, "euler") is box
    assert with_floating_base(box, "quaternion").initial_state == box.initial_state
    with pytest.raises(ValueError, match=r"floating_base must be one of \['euler', 'quaternion'\]"):
        with_floating_base(box, "rpy")


def test_a_velocity_roll_pitch_yaw_cannot_hold_is_refused():
    """At pitch = pi/2 roll-pitch-yaw rates cannot express every angular velocity."""
    data = dict(TOSSED)
    data["initial_state"] = {"q": [0.0, 0.0, 0.5, 1.0, 0.0, 0.0], "v": [0.0] * 6}
    quaternion = with_floating_base(Scene.from_dict(data), "quaternion")
    q = list(quaternion.initial_state.q)
    s = np.sqrt(0.5)
    q[:4] = [s, 0.0, s, 0.0]  # pitched up by pi/2
    v = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # spinning about world x: not a yaw-roll rate there
    data = quaternion.to_dict()
    data["initial_state"] = {"q": q, "v": v}
    with pytest.raises(ValueError, match="initial velocities do not carry over"):
        with_floating_base(Scene.from_dict(data), "euler")
