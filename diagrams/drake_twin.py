"""A scene's twin in Drake's own contact models: the same model files in a discrete
MultibodyPlant (SAP, Similar or Lagged; point contact) with a collision sphere at each of the
scene's declared contact points and a ground box, so that Drake and this project simulate the
same contacts side by side."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import AddContactMaterial, Box, ProximityProperties, SceneGraph, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    ContactModel,
    CoulombFriction,
    DiscreteContactApproximation,
    MultibodyPlant,
)
from pydrake.systems.framework import Diagram, DiagramBuilder

from drake_abs.multibody.builder import add_scene_models
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
    for k, contact in enumerate(scene.contacts):
        instance = plant.GetModelInstanceByName(contact.model) if contact.model else None
        body = (
            plant.GetBodyByName(contact.body, instance)
            if instance is not None
            else plant.GetBodyByName(contact.body)
        )
        mu = contact.friction or 0.0
        for j, p in enumerate(contact.points):
            plant.RegisterCollisionGeometry(
                body,
                RigidTransform(np.asarray(p, float)),
                Sphere(contact.radius or POINT_RADIUS),
                f"contact_{k}_{j}",
                _properties(mu, material),
            )
    n = np.asarray(scene.ground_normal, float)
    if not np.allclose(n, [0, 0, 1]):
        raise ValueError("the Drake twin supports a horizontal ground (normal +z) only")
    # Drake combines friction as 2 mu1 mu2 / (mu1 + mu2): the ground carries the scene's largest
    # coefficient, so a single-coefficient scene keeps its value exactly
    mu_ground = max((c.friction or 0.0) for c in scene.contacts)
    plant.RegisterCollisionGeometry(
        plant.world_body(),
        RigidTransform([0.0, 0.0, scene.ground_height - 0.5]),
        Box(50.0, 50.0, 1.0),
        "ground",
        _properties(mu_ground, material),
    )
    plant.set_contact_model(ContactModel.kPoint)
    plant.set_discrete_contact_approximation(APPROXIMATIONS[approximation])
    plant.SetUseSampledOutputPorts(sampled_outputs)
    plant.Finalize()
    if plant.num_actuators():
        builder.ExportInput(plant.get_actuation_input_port(), "actuation")
    builder.ExportOutput(plant.get_state_output_port(), "state")
    diagram = builder.Build()
    return DrakeTwin(diagram, plant, scene_graph)
