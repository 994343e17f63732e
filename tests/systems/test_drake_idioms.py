"""The plants behave like Drake's: one state vector, parameters in the Context that AutoDiffXd
differentiates (checked against central differences of double simulations with changed
parameters), one set of port names, one source for the time step, and a one-call scene plant with
geometry that MeshcatVisualizer and SceneGraph queries accept."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.geometry import Meshcat, MeshcatParams, MeshcatVisualizer
from pydrake.systems.analysis import Simulator, Simulator_
from pydrake.systems.framework import DiagramBuilder

from drake_abs import ContactAware, GaussianMatched, point_mass_lcs
from drake_abs.diagrams import AddComplementarityPlantSceneGraph
from drake_abs.multibody import build_scene_model
from drake_abs.systems import ComplementarityPlant, LcsPlant

H = 0.01
PORTS_IN = ["actuation"]
PORTS_OUT = ["state", "impulse", "mu", "converged"]


def _ports(system):
    ins = [system.get_input_port(i).get_name() for i in range(system.num_input_ports())]
    outs = [system.get_output_port(i).get_name() for i in range(system.num_output_ports())]
    return ins, outs


def test_both_plants_have_one_state_vector_and_the_same_port_names():
    lcs = point_mass_lcs(2, time_step=H)
    plant = LcsPlant(lcs, ContactAware(1e-2, 0.05))
    context = plant.CreateDefaultContext()
    context.SetDiscreteState(np.array([0.0, 0.3, 1.0, 0.0]))  # one group: Drake's usual call
    assert context.num_discrete_state_groups() == 1
    assert _ports(plant) == (PORTS_IN, PORTS_OUT)
    stepper = build_scene_model("box_push").stepper()
    box = ComplementarityPlant(stepper)
    # the shared ports, then the multibody plant's contact results (as a MultibodyPlant's)
    assert _ports(box) == (PORTS_IN, PORTS_OUT + ["contact_results"])
    box_context = box.CreateDefaultContext()
    assert box_context.num_discrete_state_groups() == 1
    assert box.time_step == stepper.model.h


def _simulate(plant, x0, duration, smoothing=None, model=None, u=None):
    context = plant.CreateDefaultContext()
    context.SetDiscreteState(x0)
    if smoothing is not None:
        context.get_mutable_numeric_parameter(plant.smoothing_parameter_index).SetFromVector(
            smoothing
        )
    if model is not None:
        context.get_mutable_numeric_parameter(plant.model_parameter_index).SetFromVector(model)
    plant.actuation_port.FixValue(
        context, np.zeros(plant.actuation_port.size()) if u is None else u
    )
    Simulator(plant, context).AdvanceTo(duration)
    return context.get_discrete_state_vector().value().copy()


@pytest.mark.parametrize(
    # GaussianMatched at c1 = c2 = 0 is clipped to mu = 0 far from contact: a kink in (c1, c2)
    "policy",
    [ContactAware(1e-2, 0.05, 1e-5), GaussianMatched(0.01, 0.0, 1e-5)],
    ids=["ABS", "Gaussian"],
)
def test_lcs_plant_autodiff_differentiates_the_context_parameters(policy):
    """d x(T) / d (smoothing parameters, the LCS's d[0] and F[0,0]) through Simulator_[AutoDiffXd]
    against central differences of double simulations with the parameters changed in the
    Context (which the plant uses)."""
    lcs = point_mass_lcs(2, time_step=H)
    plant = LcsPlant(lcs, policy)
    x0 = np.array([0.0, 0.25, 1.0, 0.3])  # thrown up, lands around 0.3 s
    T_end = 0.45
    s0, m0 = policy.parameter_values(), lcs.parameter_values()
    picks = [lcs.parameter_names.index("d[0]"), lcs.parameter_names.index("F[0,0]")]
    K = s0.size + len(picks)
    ad = plant.ToAutoDiffXd()
    context = ad.CreateDefaultContext()
    context.SetDiscreteState(InitializeAutoDiff(x0.reshape(-1, 1), np.zeros((4, K))).ravel())
    gs = np.hstack([np.eye(s0.size), np.zeros((s0.size, len(picks)))])
    gm = np.zeros((m0.size, K))
    for j, k in enumerate(picks):
        gm[k, s0.size + j] = 1.0
    params = context.get_mutable_numeric_parameter
    params(ad.smoothing_parameter_index).SetFromVector(
        InitializeAutoDiff(s0.reshape(-1, 1), gs).ravel()
    )
    params(ad.model_parameter_index).SetFromVector(
        InitializeAutoDiff(m0.reshape(-1, 1), gm).ravel()
    )
    ad.actuation_port.FixValue(
        context, InitializeAutoDiff(np.zeros((2, 1)), np.zeros((2, K))).ravel()
    )
    Simulator_[AutoDiffXd](ad, context).AdvanceTo(T_end)
    x_ad = context.get_discrete_state_vector().value()
    # the AutoDiffXd run solves with Jacobians, the double run without: same step, to rounding
    np.testing.assert_allclose(
        ExtractValue(x_ad).ravel(), _simulate(plant, x0, T_end), rtol=1e-12, atol=1e-14
    )
    grad = ExtractGradient(x_ad)
    fd = np.zeros_like(grad)
    for i in range(s0.size):
        e = np.zeros_like(s0)
        e[i] = 1e-6 * max(abs(s0[i]), 1e-3)
        fd[:, i] = (
            _simulate(plant, x0, T_end, smoothing=s0 + e)
            - _simulate(plant, x0, T_end, smoothing=s0 - e)
        ) / (2 * e[i])
    for j, k in enumerate(picks):
        e = np.zeros_like(m0)
        e[k] = 1e-7
        fd[:, s0.size + j] = (
            _simulate(plant, x0, T_end, model=m0 + e) - _simulate(plant, x0, T_end, model=m0 - e)
        ) / 2e-7
    assert np.abs(fd).max() > 1e-2  # the parameters do move the landing
    np.testing.assert_allclose(grad, fd, rtol=1e-4, atol=1e-5 * np.abs(fd).max())
    # a changed smoothing parameter in the Context changes the simulation
    changed = s0.copy()
    changed[0] *= 2
    assert not np.array_equal(
        _simulate(plant, x0, T_end, smoothing=changed), _simulate(plant, x0, T_end)
    )


def test_complementarity_plant_autodiff_differentiates_smoothing_and_ground_height():
    model = build_scene_model("box_push")
    policy = ContactAware(1e-3, 0.02, 1e-6)
    plant = ComplementarityPlant(model.stepper(smoothing=policy))
    x0 = model.x0 + np.array([0.0, 0.002, 0.0, 0.0, -0.2, 0.0])  # 2 mm up, falling
    T_end = 0.1
    s0, m0 = policy.parameter_values(), model.stepper().parameter_values()
    K = s0.size + 1
    ad = plant.ToAutoDiffXd()
    context = ad.CreateDefaultContext()
    context.SetDiscreteState(InitializeAutoDiff(x0.reshape(-1, 1), np.zeros((6, K))).ravel())
    params = context.get_mutable_numeric_parameter
    gs = np.hstack([np.eye(s0.size), np.zeros((s0.size, 1))])
    params(ad.smoothing_parameter_index).SetFromVector(
        InitializeAutoDiff(s0.reshape(-1, 1), gs).ravel()
    )
    gm = np.zeros((m0.size, K))
    gm[0, -1] = 1.0  # ground_height
    params(ad.model_parameter_index).SetFromVector(
        InitializeAutoDiff(m0.reshape(-1, 1), gm).ravel()
    )
    nu = ad.actuation_port.size()
    ad.actuation_port.FixValue(
        context, InitializeAutoDiff(np.zeros((nu, 1)), np.zeros((nu, K))).ravel()
    )
    Simulator_[AutoDiffXd](ad, context).AdvanceTo(T_end)
    grad = ExtractGradient(context.get_discrete_state_vector().value())
    fd = np.zeros_like(grad)
    for i in range(s0.size):
        e = np.zeros_like(s0)
        e[i] = 1e-6 * s0[i]
        fd[:, i] = (
            _simulate(plant, x0, T_end, smoothing=s0 + e)
            - _simulate(plant, x0, T_end, smoothing=s0 - e)
        ) / (2 * e[i])
    h = 1e-7  # the ground height: re-built scenes (the reference the Context's values must match)
    from dataclasses import replace

    from drake_abs.multibody.scene import Scene

    scene = Scene.load("box_push")
    ups = [
        ComplementarityPlant(
            build_scene_model(replace(scene, ground_height=scene.ground_height + s)).stepper(
                smoothing=policy
            )
        )
        for s in (h, -h)
    ]
    fd[:, -1] = (_simulate(ups[0], x0, T_end) - _simulate(ups[1], x0, T_end)) / (2 * h)
    assert np.abs(fd).max() > 1e-2
    np.testing.assert_allclose(grad, fd, rtol=1e-4, atol=1e-5 * np.abs(fd).max())
    # a changed ground height in a double Context is simulated, as the re-built scene's
    np.testing.assert_allclose(
        _simulate(plant, x0, T_end, model=m0 + np.eye(m0.size)[0] * h),
        _simulate(ups[0], x0, T_end), rtol=1e-12, atol=1e-15,
    )  # fmt: skip


def test_outputs_report_the_step_from_the_current_state():
    """impulse, mu and converged are those of the step that starts at the current state and
    input (the step the next update applies, solved once): the resting ball's impulse is m g h
    before any step is taken, and the update moves x to that step's x_next."""
    lcs = point_mass_lcs(1, time_step=H)
    plant = LcsPlant(lcs)
    assert plant.HasDirectFeedthrough(0, 1)  # actuation -> impulse
    assert not plant.HasDirectFeedthrough(0, 0)  # actuation -> state
    context = plant.CreateDefaultContext()
    x0 = np.array([0.0, 0.0])
    context.SetDiscreteState(x0)
    plant.actuation_port.FixValue(context, np.zeros(1))
    core = lcs.step(x0, np.zeros(1))
    assert plant.impulse_port.Eval(context)[0] == pytest.approx(core.impulse[0], rel=1e-12)
    assert plant.impulse_port.Eval(context)[0] == pytest.approx(9.81 * H, rel=1e-3)
    update = plant.EvalUniquePeriodicDiscreteUpdate(context)
    np.testing.assert_allclose(update.get_vector(0).value(), core.x_next, rtol=1e-12, atol=1e-15)


def test_one_call_scene_plant_with_geometry_for_meshcat_and_queries():
    builder = DiagramBuilder()
    plant, scene_graph = AddComplementarityPlantSceneGraph(builder, "box_push")
    meshcat = Meshcat(MeshcatParams(host="localhost"))
    MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    builder.ExportInput(plant.get_actuation_input_port(), "push")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    diagram.get_input_port(0).FixValue(context, np.zeros(plant.actuation_port.size()))
    plant_context = plant.GetMyContextFromRoot(context)
    model = build_scene_model("box_push")
    np.testing.assert_array_equal(plant_context.get_discrete_state_vector().value(), model.x0)
    Simulator(diagram, context).AdvanceTo(0.5)
    x = plant_context.get_discrete_state_vector().value()
    assert plant.converged_port.Eval(plant_context)[0] == 1.0
    # the box has landed and slid: SceneGraph sees its contact points on the ground
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
    distances = [p.distance for p in query.ComputeSignedDistancePairwiseClosestPoints(0.05)]
    assert distances and min(distances) == pytest.approx(0.0, abs=1e-4)
    inspector = query.inspector()
    assert inspector.num_geometries() > 4
    assert x[0] > model.x0[0]  # pushed forward by its initial speed
    # the whole diagram, visualizer included, converts to AutoDiffXd
    ad = diagram.ToAutoDiffXd()
    ad_context = ad.CreateDefaultContext()
    ad.get_input_port(0).FixValue(ad_context, np.zeros(plant.actuation_port.size()))
    Simulator_[AutoDiffXd](ad, ad_context).AdvanceTo(0.05)


def test_hostile_context_values_are_refused_by_name():
    """A NaN or out-of-range parameter in the Context, a NaN state, or a wrong stepper is an
    error that names what is wrong, never a silent step."""
    lcs = point_mass_lcs(2, time_step=H)
    plant = LcsPlant(lcs, ContactAware(1e-2, 0.05))
    x0 = np.array([0.0, 0.3, 1.0, 0.0])
    s0, m0 = ContactAware(1e-2, 0.05).parameter_values(), lcs.parameter_values()
    with pytest.raises(ValueError, match=r"ContactAware.length"):
        _simulate(plant, x0, 0.05, smoothing=s0 * np.array([1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match=r"ContactAware.mu_max"):
        _simulate(plant, x0, 0.05, smoothing=np.array([np.nan, 0.05, 0.0]))
    bad = m0.copy()
    bad[0] = np.nan
    with pytest.raises(ValueError, match=r"LCS.A"):
        _simulate(plant, x0, 0.05, model=bad)
    with pytest.raises(ValueError, match=r"\bx\b"):
        _simulate(plant, np.array([0.0, np.nan, 1.0, 0.0]), 0.05)
    with pytest.raises(ValueError, match=r"stepper must be a ComplementarityStepper"):
        ComplementarityPlant(lcs)
    with pytest.raises(ValueError, match=r"builder must be a DiagramBuilder"):
        AddComplementarityPlantSceneGraph(object(), "box_push")
    with pytest.raises(ValueError, match=r"initial_state must be 6 finite numbers"):
        ComplementarityPlant(build_scene_model("box_push").stepper(), initial_state=np.zeros(3))
