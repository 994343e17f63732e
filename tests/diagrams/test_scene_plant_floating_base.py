"""AddComplementarityPlantSceneGraph(..., floating_base="quaternion"): Drake's quaternion floating
joint for every free body, end to end (initial state, geometry, simulation), against the default
roll-pitch-yaw chain."""

import numpy as np
import pytest
from floating_scenes import TOSSED
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_abs.diagrams import AddComplementarityPlantSceneGraph
from drake_abs.multibody import Scene


def _box_motion(floating_base: str, duration: float):
    builder = DiagramBuilder()
    plant, scene_graph = AddComplementarityPlantSceneGraph(
        builder, Scene.from_dict(TOSSED), floating_base=floating_base
    )
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    if duration > 0:  # (AdvanceTo(0) would take the step at t = 0)
        Simulator(diagram, root).AdvanceTo(duration)
    context = plant.GetMyContextFromRoot(root)
    mbp = plant.plant()
    mbp_context = mbp.CreateDefaultContext()
    mbp.SetPositionsAndVelocities(mbp_context, plant.GetPositionsAndVelocities(context))
    body = mbp.GetBodyByName("box")
    X = mbp.EvalBodyPoseInWorld(mbp_context, body)
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(root))
    X_SG = query.GetPoseInWorld(mbp.GetBodyFrameIdOrThrow(body.index()))
    assert X_SG.IsNearlyEqualTo(X, 1e-14)  # the drawn geometry follows the state
    V = mbp.EvalBodySpatialVelocityInWorld(mbp_context, body).get_coeffs()
    return plant, plant.GetPositions(context), X.GetAsMatrix4(), V


def test_a_quaternion_base_starts_where_the_chain_does_and_flies_alike():
    plant, q, X0, V0 = _box_motion("quaternion", 0.0)
    assert plant.num_positions() == 7 and plant.num_velocities() == 6
    joint = plant.plant().GetJointByName("box")
    assert joint.type_name() == "quaternion_floating"
    _, _, X0_euler, V0_euler = _box_motion("euler", 0.0)
    np.testing.assert_allclose(X0, X0_euler, atol=1e-13)
    np.testing.assert_allclose(V0, V0_euler, atol=1e-12)
    _, q, X, V = _box_motion("quaternion", 0.1)
    _, q_euler, X_euler, V_euler = _box_motion("euler", 0.1)
    assert np.linalg.norm(q[:4]) == pytest.approx(1.0, abs=1e-14)
    # the same free flight: the centre of mass exactly, the rotation to the integrators' error
    np.testing.assert_allclose(X[:3, 3], X_euler[:3, 3], atol=1e-12)
    np.testing.assert_allclose(V[3:], V_euler[3:], atol=1e-12)
    assert np.abs(X[:3, :3] - X_euler[:3, :3]).max() < 5e-3
    assert np.abs(X[:3, :3] - X0[:3, :3]).max() > 0.1  # it did turn


def test_the_default_keeps_each_scenes_own_choice():
    builder = DiagramBuilder()
    plant, _ = AddComplementarityPlantSceneGraph(builder, Scene.from_dict(TOSSED))
    assert plant.num_positions() == 6  # roll-pitch-yaw chain
    builder = DiagramBuilder()
    plant, _ = AddComplementarityPlantSceneGraph(builder, "box_push", floating_base="quaternion")
    assert plant.num_positions() == 3  # planar joints: nothing floats
    with pytest.raises(ValueError, match="floating_base must be one of"):
        AddComplementarityPlantSceneGraph(DiagramBuilder(), "box_push", floating_base="rpy")
