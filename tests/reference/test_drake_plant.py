"""Drake's discrete plant as a stepper: the same numbers as Drake's Simulator stepped by hand, in
the engine; Jacobians against central differences and against AutoDiffXd through a whole
simulated horizon; the twin collides only the scene's contacts; clear errors."""

import pickle

import numpy as np
import pytest
from numdiff import central_difference
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, InitializeAutoDiff
from pydrake.geometry import Role
from pydrake.systems.analysis import Simulator, Simulator_

from drake_abs.engine import open_loop, rollout
from drake_abs.multibody import build_scene_model
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.reference.drake_plant import DrakePlantStepper
from drake_abs.reference.drake_twin import make_drake_twin

STEPS = 40


def by_hand(scene, approximation, x0, inputs):
    """States (N + 1, nx) of Drake's Simulator advanced one period at a time, the actuation
    fixed before each period."""
    twin = make_drake_twin(scene, approximation)
    simulator = Simulator(twin.diagram)
    context = simulator.get_mutable_context()
    plant_context = twin.plant.GetMyMutableContextFromRoot(context)
    twin.plant.SetPositionsAndVelocities(plant_context, x0)
    port = twin.plant.get_actuation_input_port()
    if twin.plant.num_actuators():
        port.FixValue(plant_context, inputs[0])
    simulator.Initialize()
    xs = [np.array(x0, float)]
    for k, u in enumerate(inputs):
        if twin.plant.num_actuators():
            port.FixValue(plant_context, u)
        simulator.AdvanceTo((k + 1) * scene.time_step)
        xs.append(twin.plant.GetPositionsAndVelocities(plant_context).copy())
    return np.array(xs)


@pytest.fixture(scope="module")
def models():
    return {name: build_scene_model(name) for name in ("box_push", "gym_hopper")}


@pytest.mark.parametrize("approximation", ["sap", "similar", "lagged"])
@pytest.mark.parametrize("name", ["box_push", "gym_hopper"])
def test_engine_rollout_equals_drake_simulator_by_hand(models, name, approximation):
    sm = models[name]
    stepper = DrakePlantStepper(sm.scene, approximation)
    inputs = np.random.default_rng(0).uniform(-1.0, 1.0, (STEPS, stepper.nu))
    traj = open_loop(stepper, sm.x0, inputs, jacobians=False)
    expected = by_hand(sm.scene, approximation, sm.x0, inputs)
    np.testing.assert_array_equal(traj.x[0], expected)
    assert traj.converged.all()


def test_impulses_carry_the_resting_box(models):
    """The box resting on its two bottom corners (the top two free): the normal impulses of a
    step sum to m g h, shared equally."""
    sm = models["box_push"]
    stepper = DrakePlantStepper(sm.scene, "sap")
    x = np.r_[0.0, 0.1, 0.0, 0.0, 0.0, 0.0]  # at rest on the ground
    for _ in range(50):  # let the compliant contact settle
        step = stepper.step(x, np.zeros(stepper.nu), jacobians=False)
        x = step.x_next
    assert step.impulse.shape == (len(sm.contact_model.contacts),)
    assert step.impulse.sum() == pytest.approx(1.0 * 9.81 * sm.scene.time_step, rel=1e-3)
    bottom = step.impulse > 0
    assert bottom.sum() == 2 and (step.impulse >= 0).all()
    assert step.impulse[bottom][0] == pytest.approx(step.impulse[bottom][1], rel=1e-6)


@pytest.mark.parametrize("name", ["box_push", "gym_hopper"])
def test_step_jacobians_match_central_differences(models, name):
    sm = models[name]
    stepper = DrakePlantStepper(sm.scene, "sap")
    rng = np.random.default_rng(1)
    traj = open_loop(stepper, sm.x0, rng.uniform(-1, 1, (25, stepper.nu)), jacobians=False)
    x, u = traj.x[0, -1], rng.uniform(-1, 1, stepper.nu)  # in contact by now
    assert np.abs(stepper.step(x, u, jacobians=False).impulse).sum() > 0
    step = stepper.step(x, u)
    nx = stepper.nx

    def f(z):
        return stepper.step(z[:nx], z[nx:], jacobians=False).x_next

    fd = central_difference(f, np.r_[x, u])
    scale = 1.0 + np.abs(fd).max()
    np.testing.assert_allclose(step.dx_dx, fd[:, :nx], atol=1e-4 * scale)
    np.testing.assert_allclose(step.dx_du, fd[:, nx:], atol=1e-4 * scale)


def test_open_loop_gradient_equals_autodiff_through_drakes_simulator(models):
    """The engine's reverse pass over the stepper's one-step Jacobians, against Drake's
    Simulator_[AutoDiffXd] over the whole horizon (an independent path), u held constant."""
    sm = models["box_push"]
    stepper = DrakePlantStepper(sm.scene, "sap")
    u = np.array([2.0])
    traj = open_loop(stepper, sm.x0, np.repeat(u[None], STEPS, axis=0))
    twin = make_drake_twin(sm.scene, "sap", sampled_outputs=False)
    diagram = twin.diagram.ToAutoDiffXd()
    plant = diagram.GetSubsystemByName(twin.plant.get_name())
    simulator = Simulator_[AutoDiffXd](diagram)
    context = simulator.get_mutable_context()
    pc = plant.GetMyMutableContextFromRoot(context)
    seeds = InitializeAutoDiff(np.r_[sm.x0, u].reshape(-1, 1)).ravel()
    plant.SetPositionsAndVelocities(pc, seeds[: sm.x0.size])
    plant.get_actuation_input_port().FixValue(pc, seeds[sm.x0.size :])
    simulator.Initialize()
    simulator.AdvanceTo(STEPS * sm.scene.time_step)
    grad = ExtractGradient(plant.GetPositionsAndVelocities(pc))
    np.testing.assert_allclose(traj.dxH_dx0[0], grad[:, :6], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(traj.dxH_du[0].sum(axis=0), grad[:, 6:], rtol=1e-9, atol=1e-9)


def test_closed_loop_rollout_and_gradient_run_on_drakes_plant(models):
    sm = models["box_push"]
    stepper = DrakePlantStepper(sm.scene, "sap")
    policy = LinearPolicy(nx=6, nu=1)
    reward = QuadraticReward(Q=np.eye(6), R=np.eye(1), x_goal=np.r_[0.5, 0.1, 0, 0, 0, 0])
    theta = np.random.default_rng(2).normal(scale=0.1, size=policy.n_params)
    noise = np.zeros((2, 15, 1))
    traj = rollout(stepper, policy, theta, sm.x0, noise, reward)

    def J(th):
        return rollout(stepper, policy, th, sm.x0, noise[:1], reward, gradient=False).returns[0]

    fd = central_difference(J, theta)
    np.testing.assert_allclose(traj.grad[0], fd, atol=1e-4 * (1 + np.abs(fd).max()))


def test_the_twin_collides_only_the_scenes_contacts(models):
    """An MJCF's own collision shapes (the hopper's capsules, its floor plane) are filtered out:
    the only collision candidates are the scene's contact spheres against the ground."""
    sm = models["gym_hopper"]
    twin = make_drake_twin(sm.scene, "sap")
    inspector = twin.scene_graph.model_inspector()
    names = {
        frozenset(inspector.GetName(g).rsplit("::", 1)[-1] for g in pair)
        for pair in inspector.GetCollisionCandidates()
    }
    contacts = {f"contact_{k}" for k in range(len(sm.contact_model.contacts))}
    assert names == {frozenset({"ground", c}) for c in contacts}
    assert len(inspector.GetAllGeometryIds(Role.kProximity)) > len(contacts) + 1  # filtered out


def test_pickles_and_rebuilds(models):
    stepper = DrakePlantStepper(models["box_push"].scene, "similar", material={
        "point_stiffness": 2e5})  # fmt: skip
    copy = pickle.loads(pickle.dumps(stepper))
    x = models["box_push"].x0
    np.testing.assert_array_equal(copy.step(x, [1.0]).x_next, stepper.step(x, [1.0]).x_next)
    assert copy.material == {"point_stiffness": 2e5}


def test_unsupported_autodiff_geometry_is_named(models):
    """Drake has no AutoDiffXd penetration query for a capsule against a box. The twin never
    has such a pair (points are spheres, a pair has a sphere on one side); allowing the hopper
    file's capsules against the ground box in the derivative's context makes one, and the error
    names both geometries and their shapes while the double step still works."""
    from pydrake.geometry import CollisionFilterDeclaration, GeometrySet

    sm = models["gym_hopper"]
    stepper = DrakePlantStepper(sm.scene, "sap")
    traj = open_loop(stepper, sm.x0, np.zeros((60, stepper.nu)))  # makes the AutoDiffXd context
    diagram, _, context, _ = stepper._autodiff
    scene_graph = diagram.GetSubsystemByName(stepper.twin.scene_graph.get_name())
    inspector = stepper.twin.scene_graph.model_inspector()
    ids = {inspector.GetName(g): g for g in inspector.GetAllGeometryIds(Role.kProximity)}
    capsules = GeometrySet([g for n, g in ids.items() if n.endswith("_geom")])
    scene_graph.collision_filter_manager(scene_graph.GetMyMutableContextFromRoot(context)).Apply(
        CollisionFilterDeclaration().AllowBetween(capsules, GeometrySet([ids["ground"]]))
    )
    with pytest.raises(NotImplementedError, match=r"_geom \(Capsule\) against ground \(Box\)"):
        stepper.step(traj.x[0, -1], np.zeros(stepper.nu))
    stepper.step(traj.x[0, -1], np.zeros(stepper.nu), jacobians=False)


def test_bad_arguments_are_named(models):
    scene = models["box_push"].scene
    with pytest.raises(ValueError, match="approximation must be one of"):
        DrakePlantStepper(scene, "tamsi_typo")
    with pytest.raises(ValueError, match="time_step"):
        DrakePlantStepper(scene, time_step=-1.0)
    stepper = DrakePlantStepper(scene)
    with pytest.raises(ValueError, match=r"x must have shape \(B, nx\) = \(B, 6\)"):
        stepper.step(np.zeros(5), [0.0])
    with pytest.raises(ValueError, match=r"u must have shape"):
        stepper.step(np.zeros(6), [0.0, 1.0])
    with pytest.raises(ValueError, match="x must be finite"):
        stepper.step(np.full(6, np.nan), [0.0])
    with pytest.raises(ValueError, match="names no model parameters"):
        stepper.step(np.zeros(6), [0.0], parameters=True)


def test_hydroelastic_twin_rests_on_its_drawn_box_and_softer_sinks_deeper(models):
    """With hydroelastic settings the box collides through its drawn 0.4 x 0.2 x 0.2 box,
    compliant, against a rigid ground: it settles with its centre a little below 0.1 m, deeper
    for a softer modulus; no point candidates, so the impulse has no columns."""
    scene = models["box_push"].scene
    rest = np.r_[0.0, 0.1, 0.0, 0.0, 0.0, 0.0]
    sinks = []
    for modulus in (1e6, 1e7):
        stepper = DrakePlantStepper(scene, "sap", hydroelastic={"modulus": modulus})
        inspector = stepper.twin.scene_graph.model_inspector()
        names = {
            frozenset(inspector.GetName(g).rsplit("::", 1)[-1] for g in pair)
            for pair in inspector.GetCollisionCandidates()
        }
        assert names == {frozenset({"ground", "hydroelastic_box_0"})}
        traj = open_loop(stepper, rest, np.zeros((100, 1)), jacobians=False)
        assert traj.impulse.shape == (1, 100, 0) and stepper.nc == 0
        assert np.abs(traj.x[0, -1, 3:]).max() < 1e-3  # at rest
        sinks.append(0.1 - traj.x[0, -1, 1])
    assert 0 < sinks[1] < sinks[0] < 0.01
    copy = pickle.loads(pickle.dumps(stepper))
    assert copy.hydroelastic == {"modulus": 1e7, "resolution_hint": 0.05, "ground_thickness": 0.1}
    np.testing.assert_array_equal(
        copy.step(rest, [0.0], jacobians=False).x_next,
        stepper.step(rest, [0.0], jacobians=False).x_next,
    )


def test_bad_hydroelastic_settings_are_named(models):
    scene = models["box_push"].scene
    with pytest.raises(ValueError, match=r"hydroelastic\['modulus'\] must be a finite number"):
        DrakePlantStepper(scene, hydroelastic={})
    with pytest.raises(ValueError, match=r"keys among \['ground_thickness', 'modulus'"):
        DrakePlantStepper(scene, hydroelastic={"modulus": 1e7, "stiffness": 1.0})
    with pytest.raises(ValueError, match=r"hydroelastic\['ground_thickness'\]"):
        DrakePlantStepper(scene, hydroelastic={"modulus": 1e7, "ground_thickness": -0.1})
    with pytest.raises(ValueError, match="ground contacts only"):
        DrakePlantStepper("pusher_box", hydroelastic={"modulus": 1e7})


def test_record_keeps_the_steppers_jacobians(models):
    """engine.record over Drake's plant stores each step's AutoDiffXd Jacobians as they are."""
    from drake_abs.engine import record

    sm = models["box_push"]
    stepper = DrakePlantStepper(sm.scene, "lagged")
    policy = LinearPolicy(nx=6, nu=1)
    reward = QuadraticReward(Q=np.eye(6), R=np.eye(1), x_goal=np.zeros(6))
    theta = np.random.default_rng(3).normal(scale=0.1, size=policy.n_params)
    tape = record(stepper, policy, theta, sm.x0, np.zeros((1, 10, 1)), reward, sigma=0.0)
    for t in (0, 9):
        step = stepper.step(tape.x[0, t], tape.u[0, t])
        np.testing.assert_array_equal(tape.dx_dx[0, t], step.dx_dx)
        np.testing.assert_array_equal(tape.dx_du[0, t], step.dx_du)
