"""Our scenes in the reference simulators (drake_abs/reference/scene_sources.py): the Drake twin's
and the MuJoCo models' coordinates are the scenes' (names, order, gears, effort limits), the
MuJoCo box is the SDF's box, the torque input is MuJoCo's ctrl times the gear, the contact probes
see the ground, and in free flight with MuJoCo stepping as we do (semi-implicit Euler, one 10 ms
step) our one-step prediction is MuJoCo's to rounding."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")
pytest.importorskip("gymnasium")

from drake_abs.engine import open_loop  # noqa: E402
from drake_abs.learning.transitions import Transitions, one_step_errors  # noqa: E402
from drake_abs.multibody import build_scene_model  # noqa: E402
from drake_abs.multibody.joint_limits import effort_limits  # noqa: E402
from drake_abs.policy.controls import episode_seed, uniform_inputs  # noqa: E402
from drake_abs.reference.drake_twin import make_drake_twin  # noqa: E402
from drake_abs.reference.scene_sources import (  # noqa: E402
    MUJOCO_MODELS,
    TorqueInput,
    check_drake_coordinates,
    check_mujoco_coordinates,
    drake_source,
    mujoco_source,
    whole_frame_skip,
)
from drake_abs.tasks.locomotion import TASKS  # noqa: E402

EXACT = 1e-9  # one-step agreement where both models integrate the same smooth dynamics
SCENES = tuple(MUJOCO_MODELS)


@pytest.fixture(scope="module")
def models():
    return {scene: build_scene_model(scene) for scene in SCENES}


def test_drake_twin_coordinates_are_ours(models):
    for scene, model in models.items():
        twin = make_drake_twin(model.scene, "sap")
        check_drake_coordinates(twin.plant, model.plant, scene)
    other = make_drake_twin(models["gym_hopper"].scene, "sap")
    with pytest.raises(AssertionError, match="Position"):
        check_drake_coordinates(other.plant, models["gym_half_cheetah"].plant, "cheetah")


def test_mujoco_coordinates_and_frame_skips(models):
    expected = {
        "box_push": ("mujoco:box_push", 1),
        "gym_hopper": ("mujoco-Hopper-v5:gym_hopper", 5),
        "gym_half_cheetah": ("mujoco-HalfCheetah-v5:gym_half_cheetah", 1),
    }
    for scene, model in models.items():
        source = mujoco_source(model)
        inner = source.stepper.stepper
        assert (source.name, inner.frame_skip) == expected[scene]
        assert source.time_step == pytest.approx(model.scene.time_step, rel=1e-12)
        effort = effort_limits(model.plant)
        gear = check_mujoco_coordinates(inner.model, model.plant, effort, scene)
        np.testing.assert_array_equal(source.stepper.gear, gear)
    np.testing.assert_array_equal(effort_limits(models["gym_hopper"].plant), [200.0] * 3)
    hopper = mujoco_source(models["gym_hopper"]).stepper.stepper.model
    with pytest.raises(AssertionError, match="joints"):
        check_mujoco_coordinates(hopper, models["gym_half_cheetah"].plant, np.ones(6))
    with pytest.raises(AssertionError, match="gear"):
        check_mujoco_coordinates(hopper, models["gym_hopper"].plant, np.full(3, 100.0))
    # the options change the timestep, and the frame skip follows
    fine = mujoco_source(models["gym_half_cheetah"], options={"timestep": 0.002})
    assert fine.stepper.stepper.frame_skip == 5
    assert whole_frame_skip(0.002, 0.01) == 5
    with pytest.raises(ValueError, match="whole multiple"):
        whole_frame_skip(0.003, 0.01)
    with pytest.raises(ValueError, match="scene_model"):
        mujoco_source(SimpleNamespace(scene=SimpleNamespace(name="ball")))


def test_box_mjcf_is_the_sdf_box(models):
    source = mujoco_source(models["box_push"])
    model = source.stepper.stepper.model
    assert model.opt.timestep == 0.01 and model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
    plant = models["box_push"].plant
    inertia = plant.GetBodyByName("box").default_spatial_inertia()
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "box")
    assert model.body_mass[body] == pytest.approx(inertia.get_mass(), rel=1e-12)
    assert model.body_mass.sum() == pytest.approx(inertia.get_mass(), rel=1e-12)
    assert np.allclose(model.body_ipos[body], inertia.get_com(), atol=1e-12)
    rot = inertia.CalcRotationalInertia().CopyToFullMatrix3()
    assert np.allclose(np.diag(model.body_inertia[body]), rot, rtol=1e-9, atol=1e-12)
    assert np.allclose(model.body_iquat[body], [1, 0, 0, 0])
    # the scene's contact points, friction, joint order and actuator
    scene = models["box_push"].scene
    points = np.array(scene.contacts[0].points, float)
    spheres = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"contact_{k}")
               for k in range(4)]  # fmt: skip
    assert np.allclose(model.geom_pos[spheres], points)
    assert np.allclose(model.geom_friction[spheres, 0], scene.contacts[0].friction)
    floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    assert model.geom_pos[floor, 2] == -model.geom_size[spheres[0], 0]  # touch at z = 0
    np.testing.assert_array_equal(source.stepper.gear, [1.0])


def test_torque_input_is_ctrl_times_gear(models):
    source = mujoco_source(models["gym_half_cheetah"], options={"integrator": "Euler"})
    torque, inner = source.stepper, source.stepper.stepper
    x = np.tile(models["gym_half_cheetah"].x0, (2, 1))
    u = np.array([[60.0, -45.0, 30.0, 0.0, 12.0, -3.0], [-120.0, 90.0, 0.0, 6.0, 0.0, 30.0]])
    by_torque = torque.step(x, u)
    by_ctrl = type(inner)(inner.model, frame_skip=inner.frame_skip).step(x, u / torque.gear)
    np.testing.assert_array_equal(by_torque.x_next, by_ctrl.x_next)
    np.testing.assert_allclose(by_torque.dx_du, by_ctrl.dx_du / torque.gear, rtol=1e-12)
    with pytest.raises(ValueError, match="gear"):
        TorqueInput(inner, np.zeros(6))


def test_contact_probes_see_the_ground(models):
    model = models["gym_hopper"]
    sunk, flying = model.x0.copy(), model.x0.copy()
    sunk[1] -= 0.05  # the foot 1 cm into the ground (its contact points start 4 cm above)
    flying[1] += 1.0
    states = np.array([sunk, flying])
    for source in (drake_source(model), mujoco_source(model)):
        np.testing.assert_array_equal(source.in_contact(states), [True, False], source.name)


@pytest.mark.parametrize("scene", ["gym_hopper", "gym_half_cheetah"])
def test_mujoco_coordinates_match_ours_in_free_flight(scene, models, record_property):
    """High above the ground (no contact) with MuJoCo stepping as we do (semi-implicit Euler,
    one 10 ms step; the half-cheetah's joint springs off on both sides: MuJoCo applies them
    explicitly, our step implicitly, tests/multibody/test_joint_springs.py compares the two),
    our one-step prediction is MuJoCo's to rounding wherever no joint is near a limit: qpos,
    qvel map to our x entry by entry. gymnasium's own Hopper (RK4, 5 x 2 ms) differs by its
    integration only."""
    model = models[scene]
    base = model.x0.copy()
    base[1] += 5.0
    if scene == "gym_hopper":  # thigh and leg mid-range (their upper limits are 0)
        base[3:5] = -0.6
    noise = next(t for t in TASKS.values() if t.scene == scene).reset_noise
    seeds = [episode_seed(4, e) for e in range(2)]
    x0 = np.array([noise.sample(np.random.default_rng(s), base, model.contact_model.nq, 1)[0]
                   for s in seeds])  # fmt: skip
    effort = effort_limits(model.plant)
    u = np.stack([uniform_inputs(40, -0.1 * effort, 0.1 * effort, seed=[4, s]) for s in seeds])
    options = {"integrator": "Euler", "timestep": 0.01, "springs": False}
    for what, source in (("euler", mujoco_source(model, options=options)),
                         ("gymnasium", mujoco_source(model))):  # fmt: skip
        stepper = model.stepper(springs=what != "euler")
        run = open_loop(source.stepper, x0, u, jacobians=False)
        data = Transitions.from_trajectory(run, source=source.name, time_step=source.time_step,
                                           in_contact=source.in_contact)  # fmt: skip
        assert not data.contact.any()
        e = one_step_errors(stepper, data)
        record_property(f"{scene}_{what}_free", {k: e[k] for k in ("all", "smooth")})
        assert e["smooth"]["n"] >= 60
        if what == "euler":
            assert e["smooth"]["q_max"] < EXACT and e["smooth"]["v_max"] < EXACT
        elif scene == "gym_hopper":  # gymnasium's integrator: RK4 at 2 ms, O(h^2) from ours
            assert 1e-5 < e["smooth"]["q_max"] < 2e-2
