"""A scene's contact compliance (``compliance: {kind: mujoco, ...}``): MuJoCo's soft contact on
a scene's step. Hard contact stays the default; the MJCF files' values are MuJoCo's own; a box
resting on the ground settles where MuJoCo's does; the step's Jacobians (state, input and model
parameters) match central differences with soft contacts active; a soft stepper pickles."""

import dataclasses
import pickle

import numpy as np
import pytest

from drake_abs.multibody import build_scene_model
from drake_abs.multibody.scene import Scene
from drake_abs.multibody.scene_compliance import body_inverse_weights
from drake_abs.multibody.scene_entries import HardCompliance

BOX_XML = "package://drake_abs/models/box_planar.xml"


def box_scene(compliance=None, friction_model="stewart_trinkle") -> Scene:
    """The planar box of box_planar.xml (MuJoCo's twin of box_push: qpos = (x, z, pitch)) on its
    four corner points, resting at z = 0.1 (its bottom corners on the ground)."""
    data = {
        "name": "box_soft",
        "time_step": 0.01,
        "models": [{"file": BOX_XML}],
        "contacts": [
            {
                "body": "box",
                "friction": 0.5,
                "points": [[-0.2, 0, -0.1], [0.2, 0, -0.1], [-0.2, 0, 0.1], [0.2, 0, 0.1]],
            }
        ],  # fmt: skip
        "friction_directions": 2,
        "friction_model": friction_model,
        "initial_state": {"q": [0.0, 0.1, 0.0]},
    }
    if compliance is not None:
        data["compliance"] = compliance
    return Scene.from_dict(data)


def soft(name: str, friction_model: str | None = None) -> Scene:
    scene = dataclasses.replace(Scene.load(name), compliance={"kind": "mujoco", "from_model": True})
    if friction_model is not None:
        scene = dataclasses.replace(scene, friction_model=friction_model)
    return scene


def test_hard_contact_is_the_default():
    scene = Scene.load("gym_hopper")
    assert scene.compliance == HardCompliance()
    assert build_scene_model(scene).stepper().compliance is None


def test_from_model_reads_mujocos_own_values():
    mujoco = pytest.importorskip("mujoco")
    pytest.importorskip("gymnasium")
    from drake_abs.multibody.packages import resolve_package_file

    for name, margin, solimp in (
        ("gym_hopper", 0.002, (0.8, 0.8, 0.01, 0.5, 2.0)),  # margins 0.001 + 0.001
        ("gym_half_cheetah", 0.0, (0.0, 0.8, 0.01, 0.5, 2.0)),
    ):
        sm = build_scene_model(soft(name))
        comp = sm.stepper().compliance
        assert np.allclose(comp.solref, [0.02, 1.0]) and np.allclose(comp.solimp, solimp)
        assert np.allclose(comp.margin, margin) and np.all(comp.condim == 3)
        # A_hat: MuJoCo's compiled body_invweight0 (translation) of each candidate's body
        path = resolve_package_file(sm.scene.models[0].file)
        model = mujoco.MjModel.from_xml_path(str(path))
        for c, weight in zip(sm.contact_model.contacts, comp.inverse_weight, strict=True):
            body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, c.body)
            assert weight == pytest.approx(model.body_invweight0[body, 0], rel=1e-10), c.body
    # a body welded to the world has no inverse weight
    plant = build_scene_model("gym_hopper").plant
    assert body_inverse_weights(plant, [plant.world_body()])[0] == 0.0


def test_box_rests_where_mujocos_does():
    pytest.importorskip("mujoco")
    from drake_abs.engine import open_loop
    from drake_abs.multibody.packages import resolve_package_file
    from drake_abs.reference.mujoco_plant import MujocoStepper

    sm = build_scene_model(box_scene({"kind": "mujoco", "from_model": True}))
    ours = sm.stepper()
    mj = MujocoStepper(
        str(resolve_package_file(BOX_XML)), options={"integrator": "Euler", "timestep": 0.01}
    )
    T = 150
    a = open_loop(ours, sm.x0, np.zeros((T, 1)), jacobians=False)
    b = open_loop(mj, sm.x0, np.zeros((T, 1)), jacobians=False)
    assert a.converged.all()
    # the box starts exactly at the margin (no contact: MuJoCo's contacts need distance < margin),
    # falls a step, sinks and springs back: the same trajectory, and the same rest depth
    # (22.8 um: MuJoCo's default solref and solimp, A_hat = 2/3 kg^-1 for a planar body)
    assert np.abs(a.x[0, :, :3] - b.x[0, :, :3]).max() < 1e-9
    depth = 0.1 - a.x[0, -1, 1]
    assert 2e-5 < depth < 3e-5
    assert depth == pytest.approx(0.1 - b.x[0, -1, 1], rel=1e-8)
    # hard contact rests on the ground
    hard = open_loop(build_scene_model(box_scene()).stepper(), sm.x0, np.zeros((T, 1)))
    assert abs(hard.x[0, -1, 1] - 0.1) < 1e-9
    # pushed below the friction limit: the normal direction still agrees; MuJoCo's soft
    # friction creeps (1.5 mm over 1.5 s) where our hard friction rows creep less
    u = np.full((T, 1), 2.0)
    a = open_loop(ours, sm.x0, u, jacobians=False)
    b = open_loop(mj, sm.x0, u, jacobians=False)
    assert np.abs(a.x[0, :, 1:3] - b.x[0, :, 1:3]).max() < 1e-6
    assert abs(a.x[0, -1, 0]) < abs(b.x[0, -1, 0]) < 3e-3


def _fd_check(stepper, x, u, eps=1e-7) -> float:
    r = stepper.step(x[None], u[None])
    n, nx = x.size + u.size, x.size
    z0 = np.concatenate([x, u])
    cols = []
    for i in range(n):
        e = np.zeros(n)
        e[i] = eps
        plus = stepper.step((z0 + e)[None, :nx], (z0 + e)[None, nx:], jacobians=False).x_next
        minus = stepper.step((z0 - e)[None, :nx], (z0 - e)[None, nx:], jacobians=False).x_next
        cols.append((plus - minus)[0] / (2 * eps))
    fd = np.stack(cols, axis=1)
    J = np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1)
    return float(np.abs(J - fd).max() / max(1.0, np.abs(fd).max()))


@pytest.mark.parametrize("friction_model", ["stewart_trinkle", "anitescu"])
def test_soft_step_jacobians_match_finite_differences(friction_model):
    from drake_abs.engine import open_loop

    sm = build_scene_model(soft("gym_hopper", friction_model))
    stepper = sm.stepper()
    # the drop's landing: the foot's contacts within their margins, compressing and sliding
    traj = open_loop(stepper, sm.x0, np.zeros((45, 3)), jacobians=False)
    for t in (30, 44):
        x = traj.x[0, t]
        phi = sm.contact_model.distances(x[None, :6])[0]
        assert (phi < stepper.compliance.margin).sum() >= 1
        u = np.array([20.0, -15.0, 10.0])
        assert _fd_check(stepper, x, u) < 1e-6, (friction_model, t)


@pytest.mark.parametrize("friction_model", ["stewart_trinkle", "anitescu"])
def test_soft_step_model_parameter_columns_match_finite_differences(friction_model):
    # friction[0] moves the pyramid's regulariser R (2 mu^2 (1 + mu^2)) besides the cone
    sm = build_scene_model(soft("gym_hopper", friction_model))
    stepper = sm.stepper()
    from drake_abs.engine import open_loop

    x = open_loop(stepper, sm.x0, np.zeros((40, 3)), jacobians=False).x[0, -1]
    u = np.array([5.0, -5.0, 2.0])
    names = ["ground_height", "friction[0]", "radius[0]", "offset[0].x", "mass[foot]"]
    r = stepper.step(x[None], u[None], parameters=names)
    assert r.impulse.max() > 0 and r.converged.all()
    values = dict(zip(stepper.parameter_names, stepper.parameter_values(), strict=True))
    for j, name in enumerate(names):
        eps = 1e-7
        plus = stepper.with_parameters({name: values[name] + eps}).step(x, u, jacobians=False)
        minus = stepper.with_parameters({name: values[name] - eps}).step(x, u, jacobians=False)
        fd = (plus.x_next - minus.x_next)[0] / (2 * eps)
        err = np.abs(r.dx_dtheta[0, :, j] - fd).max() / max(1.0, np.abs(fd).max())
        assert err < 1e-6, (name, err)


def test_a_soft_stepper_pickles():
    stepper = build_scene_model(soft("gym_hopper")).stepper()
    other = pickle.loads(pickle.dumps(stepper))
    x = build_scene_model("gym_hopper").x0.copy()
    x[1] -= 0.203  # the foot's contacts 3 mm below their margin
    u = np.array([10.0, 0.0, -5.0])
    a, b = stepper.step(x, u), other.step(x, u)
    assert np.array_equal(a.x_next, b.x_next) and np.array_equal(a.dx_dx, b.dx_dx)
    assert a.impulse[0].max() > 0


def test_from_model_needs_an_mjcf_file():
    scene = dataclasses.replace(
        Scene.load("box_push"), compliance={"kind": "mujoco", "from_model": True}
    )
    with pytest.raises(ValueError, match="MJCF"):
        build_scene_model(scene).stepper()
    # stated values need no file: MuJoCo's defaults, margin 0
    scene = dataclasses.replace(Scene.load("box_push"), compliance={"kind": "mujoco"})
    comp = build_scene_model(scene).stepper().compliance
    assert np.allclose(comp.solref, [0.02, 1.0]) and np.all(comp.margin == 0)
