"""Quaternion floating joints in the pinocchio provider: every step quantity and derivative in
Drake's coordinates (q = (qw, qx, qy, qz, x, y, z), v = (w, v) in the parent frame) against the
Drake provider (MultibodyPlant, AutoDiffXd), on the shipped ball, on a URDF robot with a floating
base, and on free joints deeper in a tree with offset joint frames; at any orientation, with
quaternions off the unit sphere (extended as Drake extends them)."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    QuaternionFloatingJoint,
    RevoluteJoint,
    RotationalInertia,
    SpatialInertia,
)

from drake_abs.multibody.builder import build_scene_model
from drake_abs.multibody.drake_dynamics import GroundPlane, MultibodyContactModel, PointContact
from drake_abs.multibody.pinocchio_dynamics import PinocchioContactModel
from drake_abs.multibody.scene import Scene

NARROW = ("dphi", "dJn", "dJt", "dN")


def _field(quant, name: str):
    """A quantity, derivatives with all P columns (providers may give narrow ones)."""
    value = getattr(quant, name)
    return quant.full(name) if value is not None and name in NARROW else value


FIELDS = ("W", "v_free", "phi", "Jn", "Jt", "N", "dv_free", "dphi", "dJn", "dJt", "dN")
#: relative agreement of the two providers (measured: ~1e-13 and below)
RTOL = 1e-11


def _random_states(model, rng, B: int, nonunit: bool = True):
    """B states: random orientations (the quaternions of the first half unit, the others
    scaled by 0.5 to 2 when ``nonunit``), joints and positions, fast angular velocities."""
    q = rng.standard_normal((B, model.nq))
    for s in model.quaternion_starts:
        e = rng.standard_normal((B, 4))
        e /= np.linalg.norm(e, axis=1, keepdims=True)
        if nonunit:
            e[B // 2 :] *= rng.uniform(0.5, 2.0, (B - B // 2, 1))
        q[:, s : s + 4] = e
    v = 5.0 * rng.standard_normal((B, model.nv))
    u = rng.standard_normal((B, model.nu))
    return q, v, u


def _assert_match(drake, ours, q, v, u, rng, active=None) -> dict:
    """Every field, dW f and the distances of the two providers agree to RTOL (relative to
    each field's size); returns the largest relative difference per field."""
    a = drake.quantities(q, v, u, active)
    b = ours.quantities(q, v, u, active)
    worst = {}
    for field in FIELDS:
        x, y = _field(a, field), _field(b, field)
        assert x.shape == y.shape, field
        worst[field] = np.abs(x - y).max(initial=0.0) / (1.0 + np.abs(x).max(initial=0.0))
        assert worst[field] <= RTOL, (field, worst[field])
    for f in [rng.standard_normal(v.shape)] + list(np.eye(ours.nv)[:, None].repeat(len(q), 1)):
        # d(W f) is a difference of terms of size |W| |f| (rounding of W itself)
        scale = 1.0 + (np.abs(a.dW).max() + np.abs(a.W).max()) * np.abs(f).max()
        err = np.abs(a.dW_dot(f) - b.dW_dot(f)).max() / scale
        worst["dW f"] = max(worst.get("dW f", 0.0), err)
        assert err <= RTOL, ("dW f", err)
    c = ours.quantities(q, v, u, active, derivatives=False)
    for field in FIELDS[:6]:
        x = _field(b, field)
        np.testing.assert_allclose(
            _field(c, field), x, rtol=0, atol=1e-13 * (1 + np.abs(x).max(initial=0.0))
        )
    np.testing.assert_allclose(ours.distances(q), drake.distances(q), rtol=0, atol=1e-12)
    return worst


def _providers(model):
    args = (model.plant, model.contacts, model.ground, model.h, model.cone.directions)
    return MultibodyContactModel(*args), PinocchioContactModel(*args)


def test_the_ball_scene_uses_pinocchio_and_matches_drake(rng):
    sm = build_scene_model("ball_throw")
    assert type(sm.contact_model) is PinocchioContactModel  # dynamics: auto
    assert sm.contact_model.quaternion_starts == (0,)
    drake, ours = _providers(sm.contact_model)
    q, v, u = _random_states(ours, rng, 6)
    q[:, 6] = rng.uniform(0.0, 0.1, 6)  # near the ground
    _assert_match(drake, ours, q, v, u, rng)
    _assert_match(drake, ours, q, v, u, rng, active=np.array([], dtype=int))
    # the scene's own state: upright, thrown
    _assert_match(drake, ours, sm.q0[None], sm.v0[None], np.zeros((1, 0)), rng)


ARM_URDF = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base">
    <inertial>
      <origin xyz="0.05 -0.02 0.01" rpy="0.1 0.2 -0.3"/>
      <mass value="2.0"/>
      <inertia ixx="0.03" iyy="0.04" izz="0.05" ixy="0.002" ixz="-0.001" iyz="0.003"/>
    </inertial>
  </link>
  <link name="arm">
    <inertial>
      <origin xyz="0.0 0.1 -0.02" rpy="0 0 0"/>
      <mass value="0.7"/>
      <inertia ixx="0.01" iyy="0.004" izz="0.012" ixy="0.0005" ixz="0" iyz="-0.0007"/>
    </inertial>
  </link>
  <joint name="base_floating" type="floating">
    <parent link="world"/>
    <child link="base"/>
  </joint>
  <joint name="shoulder" type="revolute">
    <parent link="base"/>
    <child link="arm"/>
    <origin xyz="0.0 0.15 0.05" rpy="0.3 0.1 0.0"/>
    <axis xyz="0.2 0.9 -0.3"/>
    <limit lower="-10" upper="10" effort="100" velocity="100"/>
  </joint>
  <transmission type="SimpleTransmission" name="shoulder_trans">
    <actuator name="shoulder_motor"/>
    <joint name="shoulder"/>
    <mechanicalReduction>1</mechanicalReduction>
  </transmission>
</robot>
"""


def test_a_urdf_floating_base_with_an_actuated_child(tmp_path, rng):
    """A body on a URDF floating joint and an actuated revolute child (skewed axis, offset
    joint origin, off-centre inertias), contacts on both bodies, one frictionless."""
    path = tmp_path / "arm.urdf"
    path.write_text(ARM_URDF)
    scene = Scene.from_dict(
        {
            "name": "arm",
            "models": [{"file": str(path)}],
            "contacts": [
                {"body": "base", "points": [[0.1, 0.05, -0.1]], "radius": 0.02, "friction": 0.6},
                {"body": "arm", "points": [[0.0, 0.2, 0.0], [0.03, 0.25, -0.01]], "friction": 0.3},
                {"body": "arm", "points": [[0.0, 0.3, 0.02]]},
            ],
            "ground_normal": [0.1, -0.2, 1.0],
            "ground_height": -0.3,
        }
    )
    sm = build_scene_model(scene)
    model = sm.contact_model
    assert type(model) is PinocchioContactModel
    assert (model.nq, model.nv, model.nu) == (8, 7, 1) and model.quaternion_starts == (0,)
    drake, ours = _providers(model)
    q, v, u = _random_states(ours, rng, 4)
    _assert_match(drake, ours, q, v, u, rng)
    _assert_match(drake, ours, q, v, u, rng, active=np.array([3, 1]))


def test_model_instances_with_the_same_joint_names(tmp_path, rng):
    """Two balls and two arms (model instances of the same files: their joints share names),
    contacts on every body."""
    path = tmp_path / "arm.urdf"
    path.write_text(ARM_URDF)
    models = [{"file": "drake_abs:models/ball_floating.urdf", "name": n} for n in "ab"]
    models += [{"file": str(path), "name": n} for n in ("left", "right")]
    contacts = [{"body": "ball", "model": n, "points": [[0, 0, 0]], "radius": 0.05,
                 "friction": 0.5} for n in "ab"]  # fmt: skip
    contacts += [{"body": "arm", "model": n, "points": [[0.0, 0.2, 0.0]], "friction": 0.3}
                 for n in ("left", "right")]  # fmt: skip
    scene = Scene.from_dict({"name": "crowd", "models": models, "contacts": contacts})
    model = build_scene_model(scene).contact_model
    assert type(model) is PinocchioContactModel
    assert len(model.quaternion_starts) == 4 and (model.nq, model.nv) == (30, 26)
    drake, ours = _providers(model)
    q, v, u = _random_states(ours, rng, 3)
    _assert_match(drake, ours, q, v, u, rng)


def _tree_with_two_free_joints() -> MultibodyPlant:
    """world -(free, offset frame on the world)-> base -(revolute)-> link -(free, offset frames
    on both sides)-> tip: free joints at the root and deep in the tree."""

    def inertia(m, com, moments):
        return SpatialInertia.MakeFromCentralInertia(m, np.array(com), RotationalInertia(*moments))

    def frame(name, parent, rpy, xyz):
        X = RigidTransform(RollPitchYaw(*rpy), xyz)
        return plant.AddFrame(FixedOffsetFrame(name, parent, X))

    plant = MultibodyPlant(0.0)
    base = plant.AddRigidBody(
        "base", inertia(2.0, [0.05, -0.02, 0.01], [0.03, 0.04, 0.05, 0.002, -0.001, 0.003])
    )
    link = plant.AddRigidBody(
        "link", inertia(0.7, [0.0, 0.1, -0.02], [0.01, 0.004, 0.012, 0.0005, 0.0, -0.0007])
    )
    tip = plant.AddRigidBody(
        "tip", inertia(0.3, [0.01, 0.0, 0.03], [0.002, 0.003, 0.0025, 0.0001, 0.0002, 0.0])
    )
    world = frame("F0", plant.world_frame(), (0.1, -0.2, 0.3), [0.1, 0.0, 0.2])
    plant.AddJoint(QuaternionFloatingJoint("free0", world, base.body_frame()))
    hinge = frame("Fr", base.body_frame(), (0.3, 0.1, 0.0), [0.0, 0.15, 0.05])
    joint = plant.AddJoint(RevoluteJoint("hinge", hinge, link.body_frame(), [0.2, 0.9, -0.3]))
    plant.AddJointActuator("hinge_motor", joint)
    parent = frame("Fp", link.body_frame(), (-0.4, 0.2, 0.5), [0.05, 0.2, 0.0])
    child = frame("Fc", tip.body_frame(), (0.2, 0.0, -0.3), [0.01, -0.02, 0.03])
    plant.AddJoint(QuaternionFloatingJoint("free1", parent, child))
    plant.Finalize()
    return plant


def test_free_joints_deep_in_a_tree_with_offset_frames(rng):
    drake, ours = _tree_providers()
    assert ours.quaternion_starts == (0, 8) and (ours.nq, ours.nv) == (15, 13)
    q, v, u = _random_states(ours, rng, 4)
    worst = _assert_match(drake, ours, q, v, u, rng)
    assert max(worst.values()) < 1e-12  # measured ~4e-13: room below RTOL
    _assert_match(drake, ours, q, v, u, rng, active=np.array([2, 0]))


def test_the_quaternion_off_the_unit_sphere(rng):
    """Drake's extension, which ours follows: every quantity but N depends on e / |e| (a
    radial change of e changes nothing: zero derivative), N is linear in e (dN along e is N)."""
    _, ours = _providers(build_scene_model("ball_throw").contact_model)
    q, v, u = _random_states(ours, rng, 2)
    quant = ours.quantities(q, v, u)
    radial = np.zeros((2, ours.nq + ours.nv + ours.nu))
    radial[:, :4] = q[:, :4]
    for field in ("dv_free", "dphi", "dJn", "dJt"):
        d = _field(quant, field)
        assert np.abs(np.einsum("b...p,bp->b...", d, radial)).max() < 1e-12, field
    assert np.abs(np.einsum("bp,bnp->bn", radial, quant.dW_dot(v))).max() < 1e-9
    quaternion_rows = quant.N.copy()
    quaternion_rows[:, 4:] = 0.0
    dN_radial = np.einsum("bijp,bp->bij", _field(quant, "dN"), radial)
    np.testing.assert_allclose(dN_radial, quaternion_rows, rtol=0, atol=1e-15)
    # and the state itself: scaling e leaves W, v_free and the contacts as they are
    scaled = q.copy()
    scaled[:, :4] *= 1.7
    other = ours.quantities(scaled, v, u, derivatives=False)
    for field in ("W", "v_free", "phi", "Jn", "Jt"):
        x = getattr(quant, field)
        np.testing.assert_allclose(
            getattr(other, field), x, rtol=0, atol=1e-12 * (1 + abs(x).max())
        )
    np.testing.assert_allclose(other.N[:, :4], 1.7 * quant.N[:, :4], rtol=1e-14)


def test_quantities_within_on_the_ball(rng):
    """The one-state path (kinematics shared by pruning and the quantities) on the ball."""
    model = build_scene_model("ball_throw").contact_model
    q, v, u = _random_states(model, rng, 1)
    q[0, 6] = 0.07
    for distance, expected in ((0.1, [0]), (0.01, [])):
        active, got = model.quantities_within(q, v, u, distance)
        np.testing.assert_array_equal(active, expected)
        want = model.quantities(q, v, u, active)
        for field in FIELDS:
            g, w = _field(got, field), _field(want, field)
            np.testing.assert_allclose(g, w, rtol=0, atol=1e-13 * (1 + np.abs(w).max(initial=0)))


def _tree_providers():
    plant = _tree_with_two_free_joints()
    contacts = [
        PointContact("base", (0.1, 0.05, -0.1), 0.02, 0.6),
        PointContact("link", (0.0, 0.2, 0.0), 0.0, 0.3),
        PointContact("tip", (0.02, 0.01, -0.05), 0.01, None),
        PointContact("tip", (-0.03, 0.0, 0.0), 0.0, 0.8),
    ]
    args = (plant, contacts, GroundPlane((0.1, -0.2, 1.0), -0.3), 0.01, 4)
    return MultibodyContactModel(*args), PinocchioContactModel(*args)


@pytest.mark.parametrize("broken", ["angular", "radial", "frame"])
def test_the_comparison_catches_a_wrong_map(broken, rng, monkeypatch):
    """The checks above can fail: a wrong map (the angular increment's sign flipped, a radial
    term added to it, or the world-frame rotation where its transpose belongs) is caught. (Not
    on the ball alone: a uniform sphere's quantities do not depend on its orientation.)"""
    from drake_abs.multibody import pinocchio_free_joints as module

    maps = module._maps

    def wrong(q, q_starts, v_starts, *args):
        q_pin, T, D, N, G = maps(q, q_starts, v_starts, *args)
        D, T = D.copy(), T.copy()
        for f, (s, t) in enumerate(zip(q_starts, v_starts, strict=True)):
            if broken == "angular":
                G[f] = -G[f]
            elif broken == "radial":
                G[f] = G[f] + 0.1 * q[None, s : s + 4]
            else:
                T[t : t + 3, t + 3 : t + 6] = T[t : t + 3, t + 3 : t + 6].T
            D[t + 3 : t + 6, s : s + 4] = G[f]
        return q_pin, T, D, N, G

    drake, ours = _tree_providers()
    q, v, u = _random_states(ours, rng, 2)
    _assert_match(drake, ours, q, v, u, rng)  # as it is: the same numbers
    monkeypatch.setattr(module, "_maps", wrong)
    with pytest.raises(AssertionError):
        _assert_match(drake, ours, q, v, u, rng)
