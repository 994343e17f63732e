"""A scene's twin in Drake's own contact models: the same model files in a discrete
MultibodyPlant (SAP, Similar or Lagged; point contact) with a collision sphere at each of the
scene's contact points (listed, or expanded from a body's collision shapes as
:func:`~drake_abs.multibody.builder.scene_contacts` does), the collision shapes of each
body-body pair, and a ground box, so that Drake and this project simulate the same contacts side
by side. Collision filters leave only the scene's contacts active: point contacts against the
ground, and each pair's shapes against each other. The models are parsed as the step's plant is
(:func:`~drake_abs.multibody.builder.add_scene_models`), so the twin has the same joint damping,
limits, motors and joint springs (an MJCF joint's ``stiffness`` as a ``RevoluteSpring`` or
``PrismaticSpring`` force element, which Drake's discrete update applies).

With ``hydroelastic`` settings the twin uses Drake's hydroelastic contact instead: each body
that carries the scene's ground contacts collides through its drawn (visual) shapes, made
compliant hydroelastic, against a rigid hydroelastic ground box."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import (
    AddCompliantHydroelasticProperties,
    AddContactMaterial,
    AddRigidHydroelasticProperties,
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

#: Display names of the approximations in tables and plots ("SAP" as in "Drake SAP").
APPROXIMATION_LABELS = {"sap": "SAP", "similar": "Similar", "lagged": "Lagged"}

#: Radius (m) of the collision sphere standing in for a point contact (radius 0).
POINT_RADIUS = 1e-3

#: Hydroelastic settings and their defaults, namely the compliant shapes' hydroelastic modulus
#: (Pa, required), the meshes' resolution hint (m) and the rigid ground box's thickness (m).
HYDROELASTIC_DEFAULTS = {"modulus": None, "resolution_hint": 0.05, "ground_thickness": 0.1}
#: Width (m) of the rigid hydroelastic ground box (square).
HYDROELASTIC_GROUND_WIDTH = 20.0


@dataclass(frozen=True)
class DrakeTwin:
    """The twin's diagram (plant + SceneGraph), its plant and SceneGraph, and which of the
    scene's ``num_candidates`` contact candidates each registered collision geometry stands for
    (``candidates``: geometry id -> candidate index; a pair's two shapes map to the same index;
    empty, with no candidates, under hydroelastic contact)."""

    diagram: Diagram
    plant: MultibodyPlant
    scene_graph: SceneGraph
    candidates: dict = field(default_factory=dict)
    num_candidates: int = 0


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


def hydroelastic_settings(hydroelastic: dict | None) -> dict | None:
    """``hydroelastic`` with its defaults filled in (:data:`HYDROELASTIC_DEFAULTS`), checked:
    ``ValueError`` names an unknown key or a value that is not a finite number > 0."""
    if hydroelastic is None:
        return None
    if not isinstance(hydroelastic, dict) or set(hydroelastic) - set(HYDROELASTIC_DEFAULTS):
        raise ValueError(
            f"hydroelastic must be a dict with keys among {sorted(HYDROELASTIC_DEFAULTS)}; "
            f"got {hydroelastic!r}"
        )
    out = {**HYDROELASTIC_DEFAULTS, **hydroelastic}
    for key, value in out.items():
        number = isinstance(value, int | float) and not isinstance(value, bool)
        if not (number and np.isfinite(value) and value > 0):
            raise ValueError(f"hydroelastic[{key!r}] must be a finite number > 0; got {value!r}")
    return out


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
    hydroelastic: dict | None = None,
) -> DrakeTwin:
    """The scene as a discrete Drake MultibodyPlant with ``approximation`` in sap, similar,
    lagged. Coordinates match :func:`~drake_abs.multibody.builder.build_scene_model`
    (floating bases as joint chains), so states can be compared entry by entry.

    ``material``: optional point-contact parameters ``point_stiffness`` (N/m),
    ``hunt_crossley_dissipation`` (s/m) and ``relaxation_time`` (s, SAP); Drake's defaults
    otherwise.

    ``hydroelastic``: None (point contact, above), or hydroelastic contact with settings
    ``modulus`` (Pa), ``resolution_hint`` (m, default 0.05) and ``ground_thickness`` (m, default
    0.1): each body with ground contacts in the scene collides through its visual shapes (as its
    model file draws them), compliant with that modulus, and the ground is a rigid box
    :data:`HYDROELASTIC_GROUND_WIDTH` m square and ``ground_thickness`` thick, its top at the
    ground height. The material applies to both; a body's friction is its contacts' largest
    coefficient. Scenes with body-body pairs are refused (``ValueError``), as are bodies with
    no visual shape."""
    if approximation not in APPROXIMATIONS:
        raise ValueError(f"approximation must be one of {sorted(APPROXIMATIONS)}")
    hydro = hydroelastic_settings(hydroelastic)
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
    if hydro is not None:
        ground, on_ground = _hydroelastic_contacts(plant, scene_graph, scene, points, mu_ground,
                                                   material, hydro)  # fmt: skip
    else:
        ground = plant.RegisterCollisionGeometry(
            plant.world_body(),
            RigidTransform([0.0, 0.0, scene.ground_height - 0.5]),
            Box(50.0, 50.0, 1.0),
            "ground",
            _properties(mu_ground, material),
        )
        on_ground = []
    pairs, candidates = [], {}
    for k, contact in enumerate(contacts if hydro is None else ()):
        if isinstance(contact, PairContact):
            # the pair's own copies of its two shapes, both with the pair's coefficient
            mu = contact.friction or 0.0
            pairs.append([
                _register_shape(plant, contact.body_a, contact.model_a, contact.shape_a,
                                f"pair_{k}_a", _properties(mu, material)),
                _register_shape(plant, contact.body_b, contact.model_b, contact.shape_b,
                                f"pair_{k}_b", _properties(mu, material)),
            ])  # fmt: skip
            candidates.update(dict.fromkeys(pairs[-1], k))
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
        candidates[on_ground[-1]] = k
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
    plant.set_contact_model(ContactModel.kPoint if hydro is None else ContactModel.kHydroelastic)
    plant.set_discrete_contact_approximation(APPROXIMATIONS[approximation])
    plant.SetUseSampledOutputPorts(sampled_outputs)
    plant.Finalize()
    if plant.num_actuators():
        builder.ExportInput(plant.get_actuation_input_port(), "actuation")
    builder.ExportOutput(plant.get_state_output_port(), "state")
    diagram = builder.Build()
    n = len(contacts) if hydro is None else 0
    return DrakeTwin(diagram, plant, scene_graph, candidates, n)


def _hydroelastic_contacts(plant, scene_graph, scene, points, mu_ground, material, hydro):
    """The rigid ground box and each contact body's visual shapes as compliant hydroelastic
    collision geometry (``hydroelastic_<body>_<j>``); returns (ground id, the shapes' ids)."""
    if scene.pairs:
        raise ValueError("hydroelastic: the twin supports ground contacts only (no pairs)")
    t, hint = hydro["ground_thickness"], hydro["resolution_hint"]
    props = _properties(mu_ground, material)
    AddRigidHydroelasticProperties(hint, props)
    ground = plant.RegisterCollisionGeometry(
        plant.world_body(),
        RigidTransform([0.0, 0.0, scene.ground_height - t / 2]),
        Box(HYDROELASTIC_GROUND_WIDTH, HYDROELASTIC_GROUND_WIDTH, t),
        "ground",
        props,
    )
    bodies: dict[tuple[str, str | None], float] = {}
    for c in points:  # a body's friction: its contacts' largest
        key = (c.body, c.model_instance)
        bodies[key] = max(bodies.get(key, 0.0), c.friction or 0.0)
    inspector = scene_graph.model_inspector()
    shapes = []
    for (name, model), mu in bodies.items():
        body = _body(plant, name, model)
        visuals = plant.GetVisualGeometriesForBody(body)
        if not visuals:
            raise ValueError(f"hydroelastic: body {name!r} has no visual shape to collide with")
        if 0.0 < mu < mu_ground:  # combines with the ground's to the body's own (see above)
            mu = mu * mu_ground / (2.0 * mu_ground - mu)
        for j, g in enumerate(visuals):
            props = _properties(mu, material)
            AddCompliantHydroelasticProperties(hint, hydro["modulus"], props)
            shapes.append(plant.RegisterCollisionGeometry(
                body, inspector.GetPoseInFrame(g), inspector.GetShape(g),
                f"hydroelastic_{name}_{j}", props,
            ))  # fmt: skip
    return ground, shapes
