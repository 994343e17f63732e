"""What a MultibodyPlant user reaches for first works on the complementarity plant (issue 35,
item 2): the sizes, Get/Set of q and v (checked by name), the defaults, the model's
MultibodyPlant, and a contact results port whose numbers are the step's own, drawn in Meshcat by
ContactForceVisualizer in a simulated diagram."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.geometry import Meshcat, MeshcatParams, MeshcatVisualizer
from pydrake.multibody.meshcat import ContactVisualizerParams
from pydrake.systems.analysis import Simulator, Simulator_
from pydrake.systems.framework import DiagramBuilder

from drake_abs.diagrams import AddComplementarityPlantSceneGraph
from drake_abs.multibody import build_scene_model
from drake_abs.multibody.contact_results import PointContactResults
from drake_abs.systems import ComplementarityPlant, ContactForceVisualizer


@pytest.fixture(scope="module")
def box():
    return build_scene_model("box_push")


@pytest.fixture(scope="module")
def meshcat():
    return Meshcat(MeshcatParams(host="localhost"))


def _scene(name: str = "box_push", **options):
    builder = DiagramBuilder()
    plant, scene_graph = AddComplementarityPlantSceneGraph(builder, name, **options)
    return builder, plant, scene_graph


def test_sizes_are_those_of_the_models_plant(box):
    plant = ComplementarityPlant(box.stepper(), initial_state=box.x0)
    mbp = box.plant
    assert (plant.num_positions(), plant.num_velocities()) == (3, 3)
    assert plant.num_positions() == mbp.num_positions()
    assert plant.num_velocities() == mbp.num_velocities()
    assert plant.num_multibody_states() == mbp.num_multibody_states() == 6
    assert plant.num_actuators() == mbp.num_actuators() == plant.actuation_port.size() == 1
    _, ball, _ = _scene("ball_throw")  # a quaternion floating joint, no actuator
    assert (ball.num_positions(), ball.num_velocities(), ball.num_actuators()) == (7, 6, 0)
    ad = plant.ToAutoDiffXd()
    assert (ad.num_positions(), ad.num_velocities(), ad.num_actuators()) == (3, 3, 1)


@pytest.mark.parametrize("scalar", ["double", "autodiff"])
def test_get_and_set_round_trip(box, scalar):
    plant = ComplementarityPlant(box.stepper(), initial_state=box.x0)
    if scalar == "autodiff":
        plant = plant.ToAutoDiffXd()
    context = plant.CreateDefaultContext()

    def value(a):
        return ExtractValue(a).ravel() if scalar == "autodiff" else np.asarray(a)

    q, v = np.array([0.1, 0.2, 0.3]), np.array([-1.0, 2.0, 0.5])
    plant.SetPositions(context, q)
    np.testing.assert_array_equal(value(plant.GetPositions(context)), q)
    np.testing.assert_array_equal(value(plant.GetVelocities(context)), box.v0)  # v kept
    plant.SetVelocities(context, v)
    np.testing.assert_array_equal(value(plant.GetVelocities(context)), v)
    np.testing.assert_array_equal(value(plant.GetPositions(context)), q)  # q kept
    np.testing.assert_array_equal(
        value(plant.GetPositionsAndVelocities(context)), np.concatenate([q, v])
    )
    x = np.arange(6.0)
    plant.SetPositionsAndVelocities(context, x)
    np.testing.assert_array_equal(value(context.get_discrete_state_vector().value()), x)
    got = plant.GetPositions(context)  # a copy: changing it leaves the Context as it is
    got[0] = 99.0
    assert value(plant.GetPositions(context))[0] == 0.0
    if scalar == "autodiff":  # derivatives pass through
        q_ad = InitializeAutoDiff(q.reshape(-1, 1), np.eye(3)).ravel()
        plant.SetPositions(context, q_ad)
        np.testing.assert_array_equal(ExtractGradient(plant.GetPositions(context)), np.eye(3))


@pytest.mark.parametrize(
    "method, name, size",
    [
        ("SetPositions", "q", 3),
        ("SetVelocities", "v", 3),
        ("SetPositionsAndVelocities", "q_v", 6),
    ],
)
def test_bad_arguments_are_refused_naming_the_argument(box, method, name, size):
    builder, plant, _ = _scene()
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    context = plant.GetMyMutableContextFromRoot(root)
    before = plant.GetPositionsAndVelocities(context)
    call = getattr(plant, method)
    with pytest.raises(
        ValueError,
        match=rf"^ComplementarityPlant 'plant': {method}: {name} must have shape \({size},\); "
        rf"got \({size + 1},\)$",
    ):
        call(context, np.zeros(size + 1))
    with pytest.raises(ValueError, match=rf"{method}: {name} must have shape \({size},\); got"):
        call(context, np.zeros((size, 1)))
    bad = np.zeros(size)
    bad[1] = np.nan
    with pytest.raises(ValueError, match=rf"{method}: {name} must be finite; {name}\[1\] is nan"):
        call(context, bad)
    with pytest.raises(ValueError, match=rf"{method}: {name} must hold {size} numbers"):
        call(context, ["a"] * size)
    derivs = InitializeAutoDiff(np.zeros((size, 1)), np.eye(size)).ravel()
    with pytest.raises(ValueError, match=rf"{method}: {name} must hold floats in a double"):
        call(context, derivs)
    with pytest.raises(RuntimeError, match="Context"):  # the diagram's, not the plant's
        call(root, np.zeros(size))
    with pytest.raises(RuntimeError, match="Context"):
        plant.GetPositions(root)
    np.testing.assert_array_equal(plant.GetPositionsAndVelocities(context), before)


def test_defaults_are_the_initial_state(box):
    _, plant, _ = _scene()
    np.testing.assert_array_equal(plant.GetDefaultPositions(), box.q0)
    np.testing.assert_array_equal(plant.GetDefaultVelocities(), box.v0)
    assert box.v0[0] == 1.0  # the scene's own initial velocity, not Drake's zero
    context = plant.CreateDefaultContext()
    np.testing.assert_array_equal(plant.GetPositionsAndVelocities(context), box.x0)
    plant.SetPositionsAndVelocities(context, np.ones(6))
    plant.SetDefaultContext(context)
    np.testing.assert_array_equal(plant.GetPositionsAndVelocities(context), box.x0)
    with pytest.raises(NotImplementedError, match=r"SetDefaultPositions.*initial_state"):
        plant.SetDefaultPositions(np.zeros(3))


def test_plant_is_the_scene_graphs_multibody_plant(box):
    builder, plant, scene_graph = _scene()
    mbp = plant.plant()
    assert mbp is plant.geometry_plant()
    assert mbp.get_source_id() == plant.get_source_id()
    names = [mbp.get_body(b).name() for b in mbp.GetBodyIndices(mbp.GetModelInstanceByName("box"))]
    dyn = box.plant
    assert names == [dyn.get_body(b).name() for b in dyn.GetBodyIndices(
        dyn.GetModelInstanceByName("box"))]  # fmt: skip
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    context = plant.GetMyMutableContextFromRoot(root)
    plant.SetPositions(context, np.array([0.3, 0.4, 0.2]))
    # the plant's kinematics with this system's q pose the body where the SceneGraph has it
    mbp_context = mbp.CreateDefaultContext()
    mbp.SetPositions(mbp_context, plant.GetPositions(context))
    body = mbp.GetBodyByName("box")
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(root))
    X_SG = query.GetPoseInWorld(mbp.GetBodyFrameIdOrThrow(body.index()))
    assert X_SG.IsNearlyEqualTo(mbp.EvalBodyPoseInWorld(mbp_context, body), 1e-14)
    assert X_SG.translation()[0] == pytest.approx(0.3)
    # without a SceneGraph: the stepper's own plant
    bare = ComplementarityPlant(box.stepper())
    assert bare.plant() is bare.stepper.model.plant
    assert bare.ToAutoDiffXd().plant() is bare.stepper.model.plant


def _point_velocity(mbp, context, body, p_W):
    """The velocity (m/s) of ``body``'s point at p_W (world), by shifting its spatial velocity."""
    X_WB = mbp.EvalBodyPoseInWorld(context, body)
    V = mbp.EvalBodySpatialVelocityInWorld(context, body)
    return V.Shift(p_W - X_WB.translation()).translational()


def test_contact_results_are_the_steps_own_impulses(box):
    """At the scene's start the box slides at 1 m/s on its two bottom corners, pushed: each
    listed contact's force is the step's normal and friction impulse over h (sliding: |f_t| =
    mu f_n), at the corner, between the ground's and the corner's geometry, with the speeds of
    the step's next velocity."""
    builder, plant, scene_graph = _scene()
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    context = plant.GetMyMutableContextFromRoot(root)
    u = np.array([3.0])
    plant.get_actuation_input_port().FixValue(context, u)
    results = plant.get_contact_results_output_port().Eval(context)
    assert isinstance(results, PointContactResults)
    step = plant.stepper.step(box.x0[None], u[None], jacobians=False)
    h = plant.time_step
    listed = np.flatnonzero(step.impulse[0] > 0)
    np.testing.assert_array_equal(listed, [0, 1])  # the bottom corners
    assert results.num_point_pair_contacts() == 2
    assert results.num_hydroelastic_contacts() == results.num_deformable_contacts() == 0
    assert results.plant() is plant.plant()
    mbp = plant.plant()
    box_body = mbp.GetBodyByName("box")
    n = np.array([0.0, 0.0, 1.0])
    inspector = scene_graph.model_inspector()
    mbp_context = mbp.CreateDefaultContext()
    v_next = step.x_next[0, 3:]
    mbp.SetPositionsAndVelocities(mbp_context, np.concatenate([box.q0, v_next]))
    for k, i in enumerate(listed):
        info = results.point_pair_contact_info(k)
        assert results.candidate(k) == i
        assert info.bodyA_index() == mbp.world_body().index()
        assert info.bodyB_index() == box_body.index()
        force = (step.impulse[0, i] * n + step.friction_impulse[0, i]) / h
        np.testing.assert_allclose(info.contact_force(), force, rtol=1e-12, atol=1e-12)
        f_t = np.linalg.norm(info.contact_force()[:2])
        assert f_t == pytest.approx(0.5 * info.contact_force()[2], rel=1e-6)  # sliding
        assert info.contact_force()[0] < 0  # against the sliding (+x)
        corner = mbp.CalcPointsPositions(
            mbp_context, box_body.body_frame(), np.array(plant.stepper.model.contacts[i].p_BC),
            mbp.world_frame(),
        ).ravel()  # fmt: skip
        np.testing.assert_allclose(info.contact_point(), corner, atol=1e-12)
        assert info.contact_point()[2] == pytest.approx(0.0, abs=1e-12)
        v = _point_velocity(mbp, mbp_context, box_body, corner)
        assert info.separation_speed() == pytest.approx(v @ n, abs=1e-12)
        assert info.slip_speed() == pytest.approx(np.linalg.norm(v[:2]), rel=1e-12)
        assert info.slip_speed() > 0.5  # still sliding at the step's end
        pair = info.point_pair()
        assert pair.depth == pytest.approx(0.0, abs=1e-12)
        np.testing.assert_array_equal(pair.nhat_BA_W, -n)
        assert inspector.GetName(pair.id_A) == "ground"
        assert inspector.GetName(pair.id_B) == f"box::contact_0_{i}"
    total = sum(results.point_pair_contact_info(k).contact_force() for k in range(2))
    assert total[2] == pytest.approx(step.impulse[0].sum() / h, rel=1e-12)
    assert total[2] == pytest.approx(box.contact_model.body_spatial_inertia(
        box_body.index()).get_mass() * 9.81, rel=1e-6)  # fmt: skip
    with pytest.raises(IndexError, match=r"\[0, 2\)"):
        results.point_pair_contact_info(2)


def test_contact_results_follow_the_contexts_model_parameters(box):
    """With the ground raised in the Context (and the box with it), the contacts are on the new
    ground, as the step that uses it."""
    plant = ComplementarityPlant(box.stepper(), initial_state=box.x0)
    context = plant.CreateDefaultContext()
    plant.get_actuation_input_port().FixValue(context, np.zeros(1))
    values = plant.stepper.parameter_values().copy()
    values[plant.stepper.parameter_names.index("ground_height")] = 0.05
    context.get_mutable_numeric_parameter(plant.model_parameter_index).SetFromVector(values)
    plant.SetPositions(context, box.q0 + np.array([0.0, 0.05, 0.0]))
    results = plant.get_contact_results_output_port().Eval(context)
    assert results.num_point_pair_contacts() == 2
    for k in range(2):
        assert results.point_pair_contact_info(k).contact_point()[2] == pytest.approx(
            0.05, abs=1e-12
        )
    weight = (
        plant.stepper.model.body_spatial_inertia(
            plant.plant().GetBodyByName("box").index()
        ).get_mass()
        * 9.81
    )
    total = sum(results.point_pair_contact_info(k).contact_force()[2] for k in range(2))
    assert total == pytest.approx(weight, rel=1e-6)  # the box rests on the raised ground


def test_a_pair_contacts_force_is_on_body_b_along_the_pairs_normal():
    """The pusher (body A) pushes the box (body B) along +x and slides along +y on its face:
    the force on the box is the pair's normal impulse along +x and a friction force along +y
    (the box is dragged with the pusher) that stays in the face's plane."""
    model = build_scene_model("pusher_box")
    stepper = model.stepper()
    plant = ComplementarityPlant(stepper, initial_state=model.x0)
    x = model.x0.copy()
    x[0] = 0.004  # 1 mm from the box's face
    x[8], x[9] = 1.0, 1.0  # the pusher moves along x and y
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, x)
    plant.get_actuation_input_port().FixValue(context, np.zeros(2))
    results = plant.get_contact_results_output_port().Eval(context)
    step = stepper.step(x[None], np.zeros((1, 2)), jacobians=False)
    pair = [k for k in range(results.num_point_pair_contacts()) if results.candidate(k) == 8]
    assert len(pair) == 1
    info = results.point_pair_contact_info(pair[0])
    mbp = plant.plant()
    assert info.bodyA_index() == mbp.GetBodyByName("pusher").index()
    assert info.bodyB_index() == mbp.GetBodyByName("box").index()
    f = info.contact_force()
    h = plant.time_step
    assert f[0] == pytest.approx(step.impulse[0, 8] / h, rel=1e-12)  # normal, on the box
    np.testing.assert_array_equal(info.point_pair().nhat_BA_W, [-1.0, 0.0, 0.0])
    assert f[1] > 0.1 and abs(f[2]) < 1e-9  # friction along the face, dragging the box
    f_t = np.linalg.norm(f[1:])
    assert f_t == pytest.approx(0.3 * f[0], rel=1e-6)  # sliding: mu = 0.3
    assert f_t == pytest.approx(np.linalg.norm(step.friction_impulse[0, 8]) / h, rel=1e-12)
    assert info.point_pair().depth == pytest.approx(-0.001, abs=1e-12)  # closed within the step
    # the speeds at the step's next velocity, by Drake's spatial velocities
    mbp_context = mbp.CreateDefaultContext()
    mbp.SetPositionsAndVelocities(mbp_context, np.concatenate([x[:8], step.x_next[0, 8:]]))
    pair_points = info.point_pair()
    relative = _point_velocity(
        mbp, mbp_context, mbp.GetBodyByName("pusher"), pair_points.p_WCa
    ) - _point_velocity(mbp, mbp_context, mbp.GetBodyByName("box"), pair_points.p_WCb)
    n = -np.asarray(pair_points.nhat_BA_W)  # from A (the pusher) into B: +x
    assert info.separation_speed() == pytest.approx(-(relative @ n), abs=1e-12)
    tangential = relative - (relative @ n) * n
    assert info.slip_speed() == pytest.approx(np.linalg.norm(tangential), rel=1e-12)
    assert info.slip_speed() > 0.1
    # the box's corners on the ground lift off (Anitescu's relaxation while sliding)
    for k in range(results.num_point_pair_contacts()):
        corner = results.point_pair_contact_info(k)
        if results.candidate(k) == 8:
            continue
        v = _point_velocity(mbp, mbp_context, mbp.GetBodyByName("box"), corner.point_pair().p_WCb)
        assert corner.separation_speed() == pytest.approx(v[2], abs=1e-12)
        assert corner.separation_speed() > 0.1


def test_a_pair_candidates_friction_impulse_is_along_its_own_tangents():
    """``Step.friction_impulse`` of a pair candidate is in the world, orthogonal to the pair's
    own normal (here x, for a box pushed sideways along y): before it was written in the
    ground's tangent basis and pointed along the pair's normal. Its size is the friction row
    coefficients' (beta), so the rows and the vector agree."""
    model = build_scene_model("pusher_box")
    x = model.x0.copy()
    x[0], x[8], x[9] = 0.004, 1.0, 1.0
    stepper = model.stepper()
    step = stepper.step(x[None], np.zeros((1, 2)), jacobians=False)
    friction = step.friction_impulse[0, 8]
    assert abs(friction[1]) > 1e-3 and abs(friction[0]) < 1e-12  # along y, not along x
    directions = stepper.model.tangent_directions(x[None, : model.contact_model.nq], [8])[0, 0]
    np.testing.assert_allclose(directions @ np.array([1.0, 0.0, 0.0]), 0.0, atol=1e-12)
    ground = stepper.model.tangent_directions(x[None, : model.contact_model.nq], [0])[0, 0]
    np.testing.assert_array_equal(ground, stepper.model.tangents)


def test_contact_force_visualizer_draws_the_contacts_in_a_simulation(meshcat):
    builder, plant, scene_graph = _scene()
    MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    params = ContactVisualizerParams()
    params.prefix = "test_contacts"
    visualizer = ContactForceVisualizer.AddToBuilder(
        builder, plant.get_contact_results_output_port(), meshcat, params
    )
    builder.ExportInput(plant.get_actuation_input_port(), "push")
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    diagram.get_input_port(0).FixValue(root, np.zeros(1))
    simulator = Simulator(diagram, root)
    simulator.AdvanceTo(0.1)
    context = plant.GetMyContextFromRoot(root)
    vis_context = visualizer.GetMyContextFromRoot(root)
    visualizer.ForcedPublish(vis_context)
    results = plant.get_contact_results_output_port().Eval(context)
    assert results.num_point_pair_contacts() == 2
    paths = [f"test_contacts/point/world+box/{results.candidate(k)}" for k in range(2)]
    assert sorted(visualizer.drawn) == paths
    for k, path in enumerate(paths):
        info = results.point_pair_contact_info(k)
        p_WC, f = visualizer.drawn[path]
        np.testing.assert_array_equal(p_WC, info.contact_point())
        np.testing.assert_array_equal(f, info.contact_force())
        assert meshcat.HasPath(f"/drake/{path}/cylinder")
    # above the threshold no arrow is shown
    params.force_threshold = 1e4
    quiet = ContactForceVisualizer(meshcat, params)
    quiet.Draw(results)
    assert quiet.drawn == {}
    # the diagram, visualizer included, converts to AutoDiffXd and simulates
    ad = diagram.ToAutoDiffXd()
    ad_context = ad.CreateDefaultContext()
    ad.get_input_port(0).FixValue(ad_context, np.zeros(1))
    Simulator_[AutoDiffXd](ad, ad_context).AdvanceTo(0.05)


def test_contact_force_visualizer_places_the_arrow_as_drake_does(meshcat):
    """The arrow's frame is at the contact point with z along the force, its cylinder scaled to
    |f| / newtons_per_meter (ContactVisualizer's drawing), hidden once the force is gone."""
    umsgpack = pytest.importorskip("umsgpack")
    _, plant, _ = _scene()
    context = plant.CreateDefaultContext()
    plant.get_actuation_input_port().FixValue(context, np.zeros(1))
    results = plant.get_contact_results_output_port().Eval(context)
    params = ContactVisualizerParams()
    params.prefix = "arrow_test"
    visualizer = ContactForceVisualizer(meshcat, params)
    visualizer.Draw(results)
    info = results.point_pair_contact_info(0)
    path = f"/drake/arrow_test/point/world+box/{results.candidate(0)}"

    def matrix(p):
        packed = umsgpack.unpackb(meshcat._GetPackedTransform(p))
        return np.array(packed["matrix"]).reshape(4, 4).T

    X = matrix(path)
    f = info.contact_force()
    np.testing.assert_allclose(X[:3, 3], info.contact_point(), atol=1e-12)
    np.testing.assert_allclose(X[:3, 2], f / np.linalg.norm(f), atol=1e-12)
    height = matrix(f"{path}/cylinder")[2, 2]
    assert height == pytest.approx(np.linalg.norm(f) / params.newtons_per_meter, rel=1e-12)
    visualizer.Draw(PointContactResults())
    visible = umsgpack.unpackb(meshcat._GetPackedProperty(path, "visible"))
    assert visible["value"] is False and visualizer.drawn == {}


def test_contact_force_visualizer_refuses_bad_arguments(meshcat):
    with pytest.raises(ValueError, match="meshcat must be a Meshcat"):
        ContactForceVisualizer(object())
    with pytest.raises(ValueError, match="params must be a ContactVisualizerParams"):
        ContactForceVisualizer(meshcat, {"publish_period": 0.1})
    params = ContactVisualizerParams()
    params.newtons_per_meter = 0.0
    with pytest.raises(ValueError, match="newtons_per_meter must be > 0"):
        ContactForceVisualizer(meshcat, params)
