"""A scene's twin in Drake's own contact models: the same model files in a discrete
MultibodyPlant (SAP, Similar or Lagged; point contact) with a collision sphere at each of the
scene's contact points (listed, or expanded from a body's collision shapes as
:func:`~drake_abs.multibody.builder.scene_contacts` does), the collision shapes of each
body-body pair, and a ground box, so that Drake and this project simulate the same contacts side
by side. Collision filters leave only the scene's contacts active: point contacts against the
ground, and each pair's shapes against each other."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import (
    AddContactMaterial,
    Box,
    Capsule,
    CollisionFilterDeclaration,
    GeometrySet,
    ProximityProperties,
    Role,
    SceneGraph,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    ContactModel,
    CoulombFriction,
    DiscreteContactApproximation,
    MultibodyPlant,
)
from pydrake.systems.framework import Diagram, DiagramBuilder

from drake_abs.multibody.builder import add_scene_models, scene_contacts
from drake_abs.multibody.geometry_contacts import PairContact, Shape
from drake_abs.multibody.scene import Scene

APPROXIMATIONS = {
    "sap": DiscreteContactApproximation.kSap,
    "similar": DiscreteContactApproximation.kSimilar,
    "lagged": DiscreteContactApproximation.kLagged,
}

#: Radius (m) of the collision sphere standing in for a point contact (radius 0).
POINT_RADIUS = 1e-3


@dataclass(frozen=True)
class DrakeTwin:
    diagram: Diagram
    plant: MultibodyPlant
    scene_graph: SceneGraph


def _properties(mu: float, material: dict | None) -> ProximityProperties:
    props = ProximityProperties()
    material = material or {}
    AddContactMaterial(
        dissipation=material.get("hunt_crossley_dissipation"),
        point_stiffness=material.get("point_stiffness"),
        friction=CoulombFriction(mu, mu),
        properties=props,
    )
    if "relaxation_time" in material:
        props.AddProperty("material", "relaxation_time", material["relaxation_time"])
    return props


def _body(plant: MultibodyPlant, name: str, model: str | None):
    if model:
        return plant.GetBodyByName(name, plant.GetModelInstanceByName(model))
    return plant.GetBodyByName(name)


def _register_shape(plant, body: str, model: str | None, shape: Shape, name: str, props):
    """Register ``shape`` (a sphere, box or capsule in the body frame) on ``body``."""
    size = shape.size
    geometry = {"sphere": lambda: Sphere(size[0]), "box": lambda: Box(*size),
                "capsule": lambda: Capsule(*size)}[shape.kind]()  # fmt: skip
    X_BG = RigidTransform(RotationMatrix(np.asarray(shape.R_BG, float)), np.asarray(shape.p_BG))
    return plant.RegisterCollisionGeometry(_body(plant, body, model), X_BG, geometry, name, props)


def make_drake_twin(
    scene: Scene,
    approximation: str = "sap",
    *,
    time_step: float | None = None,
    sampled_outputs: bool = True,
    material: dict | None = None,
) -> DrakeTwin:
    """The scene as a discrete Drake MultibodyPlant with ``approximation`` in sap, similar,
    lagged. Coordinates match :func:`~drake_abs.multibody.builder.build_scene_model`
    (floating bases as joint chains), so states can be compared entry by entry.

    ``material``: optional point-contact parameters ``point_stiffness`` (N/m),
    ``hunt_crossley_dissipation`` (s/m) and ``relaxation_time`` (s, SAP); Drake's defaults
    otherwise."""
    if approximation not in APPROXIMATIONS:
        raise ValueError(f"approximation must be one of {sorted(APPROXIMATIONS)}")
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step or scene.time_step)
    add_scene_models(plant, scene, Parser(plant, scene_graph), collisions=False)
    n = np.asarray(scene.ground_normal, float)
    if not np.allclose(n, [0, 0, 1]):
        raise ValueError("the Drake twin supports a horizontal ground (normal +z) only")
    contacts = scene_contacts(scene)
    points = [c for c in contacts if not isinstance(c, PairContact)]
    # Drake combines friction as 2 mu1 mu2 / (mu1 + mu2): the ground carries the scene's largest
    # coefficient and each point the value that combines with it to the point's own
    mu_ground = max((c.friction or 0.0) for c in points) if points else 0.0
    ground = plant.RegisterCollisionGeometry(
        plant.world_body(),
        RigidTransform([0.0, 0.0, scene.ground_height - 0.5]),
        Box(50.0, 50.0, 1.0),
        "ground",
        _properties(mu_ground, material),
    )
    on_ground, pairs = [], []
    for k, contact in enumerate(contacts):
        if isinstance(contact, PairContact):
            # the pair's own copies of its two shapes, both with the pair's coefficient
            mu = contact.friction or 0.0
            pairs.append([
                _register_shape(plant, contact.body_a, contact.model_a, contact.shape_a,
                                f"pair_{k}_a", _properties(mu, material)),
                _register_shape(plant, contact.body_b, contact.model_b, contact.shape_b,
                                f"pair_{k}_b", _properties(mu, material)),
            ])  # fmt: skip
            continue
        mu = contact.friction or 0.0
        if 0.0 < mu < mu_ground:
            mu = mu * mu_ground / (2.0 * mu_ground - mu)
        on_ground.append(plant.RegisterCollisionGeometry(
            _body(plant, contact.body, contact.model_instance),
            RigidTransform(np.asarray(contact.p_BC, float)),
            Sphere(contact.radius or POINT_RADIUS),
            f"contact_{k}",
            _properties(mu, material),
        ))  # fmt: skip
    # only the scene's contacts: points against the ground, each pair's shapes against each
    # other. Every proximity geometry is excluded first, the model files' own collision shapes
    # included (an MJCF's capsules and floor plane would otherwise touch the ground and the
    # contact spheres: contacts the scene does not declare)
    everything = GeometrySet(scene_graph.model_inspector().GetAllGeometryIds(Role.kProximity))
    declaration = CollisionFilterDeclaration().ExcludeWithin(everything)
    declaration.AllowBetween(GeometrySet([ground]), GeometrySet(on_ground))
    for g_a, g_b in pairs:
        declaration.AllowBetween(GeometrySet([g_a]), GeometrySet([g_b]))
    scene_graph.collision_filter_manager().Apply(declaration)
    plant.set_contact_model(ContactModel.kPoint)
    plant.set_discrete_contact_approximation(APPROXIMATIONS[approximation])
    plant.SetUseSampledOutputPorts(sampled_outputs)
    plant.Finalize()
    if plant.num_actuators():
        builder.ExportInput(plant.get_actuation_input_port(), "actuation")
    builder.ExportOutput(plant.get_state_output_port(), "state")
    diagram = builder.Build()
    return DrakeTwin(diagram, plant, scene_graph)
