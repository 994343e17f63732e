"""The pinocchio provider of step quantities against the Drake one (MultibodyPlant, AutoDiffXd):
the same numbers, derivatives included, on every shipped scene; the floating base made of
joints; and the choice of provider, with a clear error or a fallback for joints pinocchio's
conversion does not cover."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BallRpyJoint, SpatialInertia, UnitInertia

from drake_abs.multibody.builder import build_scene_model
from drake_abs.multibody.drake_dynamics import (
    GroundPlane,
    MultibodyContactModel,
    PointContact,
)
from drake_abs.multibody.packages import PACKAGE_DIR
from drake_abs.multibody.pinocchio_dynamics import PinocchioContactModel
from drake_abs.multibody.scene import ModelSpec, Scene

# the shipped scenes pinocchio can evaluate (not those that name the Drake dynamics)
SCENES = sorted(
    p.stem
    for p in (PACKAGE_DIR / "scenes").glob("*.yaml")
    if Scene.from_yaml(p).dynamics != "drake"
)

NARROW = ("dphi", "dJn", "dJt", "dN")


def _field(quant, name: str):
    """A quantity, derivatives with all P columns (providers may give narrow ones)."""
    value = getattr(quant, name)
    return quant.full(name) if value is not None and name in NARROW else value


FIELDS = ("W", "v_free", "phi", "Jn", "Jt", "N", "dv_free", "dphi", "dJn", "dJt", "dN")


@pytest.mark.parametrize("name", SCENES)
def test_quantities_and_derivatives_match_drake(name, rng):
    sm = build_scene_model(Scene.from_yaml(PACKAGE_DIR / "scenes" / f"{name}.yaml"))
    ours = sm.contact_model
    assert isinstance(ours, PinocchioContactModel)  # "auto" picks pinocchio for every scene
    drake = MultibodyContactModel(ours.plant, ours.contacts, ours.ground, ours.h, 4)
    ours = PinocchioContactModel(ours.plant, ours.contacts, ours.ground, ours.h, 4)
    B = 3  # random states around the initial one: joints bent, bases tilted, moving
    q = sm.q0 + 0.3 * rng.standard_normal((B, ours.nq))
    v = rng.standard_normal((B, ours.nv))
    u = rng.standard_normal((B, ours.nu))
    subset = np.arange(len(ours.contacts))[::2]  # a subset of the contacts, as after pruning
    for active in (None, subset):
        a = drake.quantities(q, v, u, active)
        b = ours.quantities(q, v, u, active)
        for field in FIELDS:
            x, y = _field(a, field), _field(b, field)
            assert x.shape == y.shape, field
            scale = 1.0 + np.abs(x).max(initial=0.0)
            assert np.abs(x - y).max(initial=0.0) <= 1e-11 * scale, field
        # pinocchio gives dW only applied to a vector (dW . f): check it on random vectors and
        # on every unit vector (the whole of dW)
        for f in [rng.standard_normal((B, ours.nv))] + list(np.eye(ours.nv)[:, None].repeat(B, 1)):
            x, y = a.dW_dot(f), b.dW_dot(f)
            assert x.shape == y.shape
            # as dW itself was compared, and W's rounding: on a free body dW f is a difference
            # of terms of size |W| |f| (zero on the ball, whose W does not change as it turns)
            scale = 1.0 + (np.abs(a.dW).max() + np.abs(a.W).max()) * np.abs(f).max()
            assert np.abs(x - y).max() <= 1e-11 * scale, "dW . f"
        c = ours.quantities(q, v, u, active, derivatives=False)
        for field in FIELDS[:6]:  # aba and its derivative routine round differently
            x = _field(b, field)
            np.testing.assert_allclose(_field(c, field), x, rtol=0, atol=1e-13 * (1 + abs(x).max()))
    np.testing.assert_allclose(ours.distances(q), drake.distances(q), rtol=0, atol=1e-12)


def test_floating_base_is_a_chain_of_joints_with_qdot_equal_to_v():
    """q = (x, y, z, yaw, pitch, roll): the body's pose is p = (x, y, z), R = Rz Ry Rx."""
    scene = Scene.from_yaml(PACKAGE_DIR / "scenes" / "ball_throw.yaml")  # with ball.sdf's ball
    euler = replace(scene, models=(ModelSpec("drake_abs:models/ball.sdf"),), initial_state={})
    sm = build_scene_model(euler)
    plant = sm.plant
    assert plant.IsVelocityEqualToQDot() and plant.num_positions() == 6
    q = np.array([0.3, -0.2, 0.7, 0.4, -0.5, 1.1])
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    X_WB = plant.EvalBodyPoseInWorld(context, plant.GetBodyByName("ball"))
    expected = RigidTransform(RollPitchYaw(q[5], q[4], q[3]), q[:3])
    assert X_WB.IsNearlyEqualTo(expected, 1e-14)
    # the intermediate bodies are massless: the mass matrix is the ball's alone
    assert plant.CalcTotalMass(context) == pytest.approx(0.2)


def _ball_joint_plant() -> MultibodyPlant:
    plant = MultibodyPlant(0.0)
    body = plant.AddRigidBody(
        "link", SpatialInertia(1.0, np.zeros(3), UnitInertia.SolidSphere(0.1))
    )
    plant.AddJoint(BallRpyJoint("shoulder", plant.world_frame(), body.body_frame(), damping=0.0))
    plant.Finalize()
    return plant


def test_unsupported_joint_raises_naming_the_joint():
    plant = _ball_joint_plant()
    contacts = [PointContact("link", (0.0, 0.0, -0.5))]
    with pytest.raises(NotImplementedError, match="shoulder.*BallRpyJoint"):
        PinocchioContactModel(plant, contacts, GroundPlane(height=-1.0), 0.01)
    # the Drake provider takes any joint
    MultibodyContactModel(plant, contacts, GroundPlane(height=-1.0), 0.01)


BALL_JOINT_SDF = """<?xml version="1.0"?>
<sdf version="1.7">
  <model name="pendulum">
    <link name="link">
      <inertial><mass>1.0</mass>
        <inertia><ixx>0.01</ixx><iyy>0.01</iyy><izz>0.01</izz>
          <ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia>
      </inertial>
    </link>
    <joint name="shoulder" type="ball">
      <parent>world</parent><child>link</child>
    </joint>
  </model>
</sdf>
"""


def test_scene_dynamics_choice_and_fallback(tmp_path):
    path = tmp_path / "pendulum.sdf"
    path.write_text(BALL_JOINT_SDF)
    data = {
        "name": "pendulum",
        "models": [{"file": str(path)}],
        "contacts": [{"body": "link", "points": [[0.0, 0.0, -0.5]]}],
        "ground_height": -1.0,
    }
    auto = build_scene_model(Scene.from_dict(data))
    assert type(auto.contact_model) is MultibodyContactModel  # auto: falls back to Drake
    with pytest.raises(NotImplementedError, match="shoulder"):
        build_scene_model(Scene.from_dict({**data, "dynamics": "pinocchio"}))
    box = Scene.from_yaml(PACKAGE_DIR / "scenes" / "box_push.yaml")
    forced = build_scene_model(Scene.from_dict({**box.to_dict(), "dynamics": "drake"}))
    assert type(forced.contact_model) is MultibodyContactModel
    with pytest.raises(ValueError, match="dynamics must be one of"):
        Scene.from_dict({**data, "dynamics": "mujoco"})


@pytest.mark.parametrize("name", ["box_push", "solo12_drop"])
def test_quantities_within_equals_distances_then_quantities(name, rng):
    """The one-state path shares the kinematics between pruning and the quantities."""
    sm = build_scene_model(Scene.from_yaml(PACKAGE_DIR / "scenes" / f"{name}.yaml"))
    model = sm.contact_model
    q = sm.q0[None] + 0.05 * rng.standard_normal((1, model.nq))
    v, u = rng.standard_normal((1, model.nv)), rng.standard_normal((1, model.nu))
    phi = model.distances(q)[0]
    distance = float(np.median(phi))  # some candidates in, some out
    active, got = model.quantities_within(q, v, u, distance)
    np.testing.assert_array_equal(active, np.flatnonzero(phi <= distance))
    assert 0 < active.size < phi.size
    want = model.quantities(q, v, u, active)
    # Two code paths (one shared kinematics pass against two separate ones) over the same
    # pinocchio algorithms: equal up to roundoff, not promised bit for bit across versions.
    for field in FIELDS:
        g, w = _field(got, field), _field(want, field)
        if w is None:
            assert g is None, field
            continue
        scale = 1.0 + np.abs(w).max(initial=0.0)
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-13 * scale, err_msg=field)


@pytest.mark.parametrize("name", ["gym_half_cheetah", "solo12_drop", "box_push"])
def test_batched_pass_equals_the_per_state_pass(name, rng):
    """A batch is evaluated in one pass (one pinocchio call per state, every contact row in one
    kernel); each state's quantities equal those of a one-state batch, for a subset of the
    contacts, with and without derivatives (rounding of the batched products only)."""
    sm = build_scene_model(name)
    model = sm.contact_model
    B = 6
    q = sm.q0 + 0.1 * rng.standard_normal((B, model.nq))
    v, u = rng.standard_normal((B, model.nv)), rng.standard_normal((B, model.nu))
    active = np.arange(len(model.contacts))[::2]
    for derivatives in (False, True):
        batch = model.quantities(q, v, u, active, derivatives=derivatives)
        one = [model.quantities(q[i : i + 1], v[i : i + 1], u[i : i + 1], active,
                                derivatives=derivatives) for i in range(B)]  # fmt: skip
        for field in FIELDS:
            x = _field(batch, field)
            if x is None:
                assert not derivatives
                continue
            y = np.concatenate([_field(o, field) for o in one])
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-14 * (1 + np.abs(y).max()))
    f = rng.standard_normal((B, model.nv))
    y = np.concatenate([o.dW_dot(f[i : i + 1]) for i, o in enumerate(one)])
    np.testing.assert_allclose(batch.dW_dot(f), y, rtol=0, atol=1e-13 * (1 + np.abs(y).max()))
    # the geometric derivatives are narrow: their q columns only
    assert batch.dJn.shape[-1] == model.nq and batch.dN.shape[-1] <= model.nq
    each = np.concatenate([model.distances(q[i : i + 1]) for i in range(B)])
    np.testing.assert_array_equal(model.distances(q), each)


@pytest.mark.parametrize("name", ["gym_half_cheetah", "gym_hopper"])
def test_damping_taken_in_the_batched_pass_equals_implicit_damping(name, rng):
    """The batched pass takes joint damping through the armature (M + h D) and the torque
    (tau - D v): the same W, free velocity and derivatives as implicit_damping of the undamped
    quantities, without a second inverse-dynamics derivative."""
    from drake_abs.contact.damping import implicit_damping
    from drake_abs.multibody.joint_limits import joint_damping

    sm = build_scene_model(name)
    model = sm.contact_model
    D = joint_damping(sm.plant)
    assert D.any()
    B = 5
    q = sm.q0 + 0.1 * rng.standard_normal((B, model.nq))
    v, u = rng.standard_normal((B, model.nv)), rng.standard_normal((B, model.nu))
    for derivatives in (False, True):
        ours = model.quantities(q, v, u, derivatives=derivatives, damping=D)
        want = implicit_damping(model.quantities(q, v, u, derivatives=derivatives), D, model.h)[0]
        for field in ("W", "v_free", "dv_free"):
            x, y = getattr(ours, field), getattr(want, field)
            if y is None:
                continue
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-12 * (1 + np.abs(y).max()))
    f = rng.standard_normal((B, model.nv))
    y = want.dW_dot(f)
    np.testing.assert_allclose(ours.dW_dot(f), y, rtol=0, atol=1e-12 * (1 + np.abs(y).max()))


def test_bad_damping_is_refused_by_name():
    sm = build_scene_model("gym_hopper")
    model = sm.contact_model
    q, v, u = sm.q0[None].repeat(2, 0), np.zeros((2, model.nv)), np.zeros((2, model.nu))
    for bad in (np.ones(model.nv + 1), np.full(model.nv, np.nan), -np.ones(model.nv)):
        with pytest.raises(ValueError, match="damping"):
            model.quantities(q, v, u, damping=bad)
