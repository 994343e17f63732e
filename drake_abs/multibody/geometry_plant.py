"""A scene's geometry, registered with a SceneGraph: what Meshcat draws and what SceneGraph
queries see.

The dynamics plant of a scene has no SceneGraph (its contacts are the scene's declared points).
:func:`make_geometry_plant` parses the same model files again into a MultibodyPlant registered
with a given SceneGraph, with the files' *visual* geometry (STL meshes drawn through OBJ copies,
see :mod:`drake_abs.multibody.model_files`), a ground slab, and one sphere per declared contact
point, drawn and also registered for proximity queries (with the ground as a thick box whose
top face is the ground plane), so that ``QueryObject.ComputeSignedDistancePairwiseClosestPoints``
sees the contacts the step models. Its generalised positions are those of the scene's dynamics
plant (same files, same
floating bases), so a state x = (q, v) of the step poses it directly.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import (
    Box,
    GeometryId,
    ProximityProperties,
    Rgba,
    SceneGraph,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant

from drake_abs.multibody.builder import add_scene_models
from drake_abs.multibody.drake_dynamics import PointContact
from drake_abs.multibody.scene import Scene

GROUND_RGBA = Rgba(0.45, 0.52, 0.58, 1.0)
POINT_CONTACT_RGBA = Rgba(0.85, 0.1, 0.1, 1.0)  # zero-radius contact points
SPHERE_CONTACT_RGBA = Rgba(0.85, 0.1, 0.1, 0.35)  # contact spheres, see-through
GROUND_THICKNESS = 0.02  # m
GROUND_SIZE = 20.0  # m, the drawn slab's side


def ground_pose(normal, height: float, center) -> RigidTransform:
    """Pose of a ground slab: top face on the plane ``n . p = height``, under ``center`` (m)."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    center = np.asarray(center, float)
    R = RotationMatrix.MakeFromOneVector(n, 2)  # slab z along the plane normal
    on_plane = center - n * (n @ center - height)
    return RigidTransform(R, on_plane - 0.5 * GROUND_THICKNESS * n)


def make_geometry_plant(
    scene: Scene,
    scene_graph: SceneGraph,
    *,
    contact_radius: float = 0.012,
    ground: bool = True,
    ground_center=(0.0, 0.0, 0.0),
    ground_size: float = GROUND_SIZE,
) -> MultibodyPlant:
    """A finalized continuous MultibodyPlant of ``scene`` registered with ``scene_graph``.

    Args:
        scene: the scene.
        scene_graph: the SceneGraph to register the geometry with.
        contact_radius: radius (m) of the spheres drawn at zero-radius contact points (points
            with a radius are drawn at their own).
        ground: add the ground (a drawn slab and a proximity half-space).
        ground_center: a point (m) the drawn slab is centred under.
        ground_size: the drawn slab's side (m).
    """
    if not (np.isfinite(contact_radius) and contact_radius > 0):
        raise ValueError(f"contact_radius must be a finite number > 0 (m); got {contact_radius!r}")
    plant = MultibodyPlant(0.0)
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    add_scene_models(plant, scene, Parser(plant), collisions=False)
    proximity = ProximityProperties()
    for j, c in enumerate(scene.contacts):
        instance = plant.GetModelInstanceByName(c.model) if c.model else None
        body = plant.GetBodyByName(c.body, instance) if instance else plant.GetBodyByName(c.body)
        sphere = Sphere(c.radius if c.radius > 0 else contact_radius)
        rgba = (SPHERE_CONTACT_RGBA if c.radius > 0 else POINT_CONTACT_RGBA).rgba
        for i, p in enumerate(c.points):
            name = f"contact_{j}_{i}"
            plant.RegisterVisualGeometry(body, RigidTransform(p), sphere, name, rgba)
            plant.RegisterCollisionGeometry(
                body, RigidTransform(p), Sphere(max(c.radius, 1e-6)), name, proximity
            )
    if ground:
        n = np.asarray(scene.ground_normal, float)
        n /= np.linalg.norm(n)
        world = plant.world_body()
        slab = Box(ground_size, ground_size, GROUND_THICKNESS)
        pose = ground_pose(n, scene.ground_height, ground_center)
        plant.RegisterVisualGeometry(world, pose, slab, "ground", GROUND_RGBA.rgba)
        # for proximity a thick box whose top face is the ground plane (SceneGraph warns that
        # half-spaces have no deformable contact)
        depth = 1.0
        R = RotationMatrix.MakeFromOneVector(n, 2)
        X = RigidTransform(R, (scene.ground_height - 0.5 * depth) * n + np.asarray(ground_center))
        X = RigidTransform(R, X.translation() - n * (n @ np.asarray(ground_center, float)))
        thick = Box(ground_size, ground_size, depth)
        plant.RegisterCollisionGeometry(world, X, thick, "ground", proximity)
    plant.Finalize()
    return plant


def contact_geometry_ids(
    plant: MultibodyPlant, inspector, contacts
) -> list[tuple[GeometryId | None, GeometryId | None]]:
    """Per contact candidate (``stepper.model.contacts``), the SceneGraph ids of the proximity
    geometry :func:`make_geometry_plant` registered for it: ``(ground, contact sphere)`` for a
    point candidate against the ground (the sphere on its body at its point, drawn for a listed
    point), each None where there is none (the sphere of a candidate from collision shapes,
    the ground of a plant made with ``ground=False``, both of a body-body pair).

    Args:
        plant: a plant from :func:`make_geometry_plant`.
        inspector: its SceneGraph's ``model_inspector()``.
        contacts: the candidates.
    """
    ground = None
    for gid in plant.GetCollisionGeometriesForBody(plant.world_body()):
        if inspector.GetName(gid).split("::")[-1] == "ground":
            ground = gid
    out = []
    for c in contacts:
        if not isinstance(c, PointContact):
            out.append((None, None))
            continue
        instance = plant.GetModelInstanceByName(c.model_instance) if c.model_instance else None
        body = (plant.GetBodyByName(c.body, instance) if instance is not None
                else plant.GetBodyByName(c.body))  # fmt: skip
        sphere = None
        for gid in plant.GetCollisionGeometriesForBody(body):
            name = inspector.GetName(gid).split("::")[-1]
            at = inspector.GetPoseInFrame(gid).translation()
            if name.startswith("contact_") and np.allclose(at, c.p_BC, rtol=0, atol=1e-12):
                sphere = gid
                break
        out.append((ground, sphere))
    return out
