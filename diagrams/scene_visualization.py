"""Meshcat playback of a scene's rollout, saved as a self-contained HTML page.

The dynamics plant of :func:`drake_abs.multibody.builder.build_scene_model` has no SceneGraph
(contacts are the scene's declared points). To draw a rollout we parse the same model files
again, into a MultibodyPlant with a SceneGraph, keep their *visual* geometry only, add a ground
slab and one small sphere per declared contact point, and replay the states through a
:class:`~pydrake.geometry.MeshcatVisualizer` into a Meshcat animation (``1 / time_step`` frames
per second). ``meshcat.StaticHtml()`` then gives a page that plays the animation offline.

Collision geometry is dropped while parsing and STL visual meshes are drawn through OBJ copies
(``add_scene_models(..., collisions=False)``, see :mod:`drake_abs.multibody.model_files`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydrake.geometry import (
    Box,
    Meshcat,
    MeshcatParams,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    Role,
    SceneGraph,
)
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import DiagramBuilder

from drake_abs.multibody.builder import build_scene_model
from drake_abs.multibody.geometry_plant import (
    GROUND_RGBA,
    GROUND_THICKNESS,
    ground_pose,
    make_geometry_plant,
)
from drake_abs.multibody.scene import Scene


def record_rollout_html(
    scene: Scene,
    xs,
    path: str | Path,
    *,
    meshcat: Meshcat | None = None,
    contact_radius: float = 0.012,
) -> Path:
    """Replay a rollout of ``scene`` in Meshcat and write the animation as a self-contained HTML
    page.

    Args:
        scene: the scene the states belong to.
        xs: (T + 1, nq + nv) states (or (T + 1, nq) positions) of the scene's dynamics plant
            (:func:`build_scene_model`), one every ``scene.time_step`` s from t = 0.
        path: the HTML file to write (its folder is created).
        meshcat: the Meshcat to draw in; its ``/drake`` tree and recording are cleared first.
            Default: a new one bound to localhost only.
        contact_radius: radius (m) of the spheres drawn at zero-radius contact points (points
            with a radius are drawn at their own).

    Returns:
        The path written.
    """
    xs = np.asarray(xs, dtype=float)
    if xs.ndim != 2 or len(xs) == 0:
        raise ValueError(f"xs must have shape (T + 1, nq + nv); got {xs.shape}")
    if not np.all(np.isfinite(xs)):
        raise ValueError("xs must be finite")
    meshcat = meshcat or Meshcat(MeshcatParams(host="localhost"))
    meshcat.Delete()
    meshcat.DeleteRecording()

    builder = DiagramBuilder()
    scene_graph = builder.AddSystem(SceneGraph())
    plant = make_geometry_plant(scene, scene_graph, contact_radius=contact_radius, ground=False)
    builder.AddSystem(plant)
    builder.Connect(
        plant.get_geometry_pose_output_port(),
        scene_graph.get_source_pose_port(plant.get_source_id()),
    )
    nq, nv = plant.num_positions(), plant.num_velocities()
    if xs.shape[1] not in (nq, nq + nv):
        raise ValueError(
            f"scene {scene.name!r}: xs must have nq + nv = {nq + nv} (or nq = {nq}) columns; "
            f"got {xs.shape[1]}"
        )
    h = scene.time_step
    params = MeshcatVisualizerParams(role=Role.kIllustration, publish_period=h)
    visualizer = MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    bodies = [plant.get_body(BodyIndex(i)) for i in range(1, plant.num_bodies())]  # no world
    points = []
    visualizer.StartRecording(set_transforms_while_recording=True)
    for k, x in enumerate(xs):
        context.SetTime(k * h)
        plant.SetPositions(plant_context, x[:nq])
        diagram.ForcedPublish(context)
        points.extend(plant.EvalBodyPoseInWorld(plant_context, b).translation() for b in bodies)
    visualizer.StopRecording()
    visualizer.PublishRecording()

    points = np.asarray(points).reshape(-1, 3) if points else np.zeros((1, 3))
    lo, hi = points.min(axis=0), points.max(axis=0)
    center = 0.5 * (lo + hi)
    extent = float(max(np.max(hi - lo), 0.3))
    normal = np.asarray(scene.ground_normal, float)
    side = extent + 1.0
    meshcat.SetProperty("/Grid", "visible", False)  # the ground slab replaces it
    meshcat.SetProperty("/Axes", "visible", False)
    meshcat.SetObject("ground", Box(side, side, GROUND_THICKNESS), GROUND_RGBA)
    meshcat.SetTransform("ground", ground_pose(normal, scene.ground_height, center))
    direction = np.array([0.35, -1.0, 0.45])
    distance = max(1.2, 2.2 * extent)
    meshcat.SetCameraPose(center + distance * direction / np.linalg.norm(direction), center)

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(meshcat.StaticHtml())
    return path


def rollout_states(scene: Scene, steps: int, u=None) -> np.ndarray:
    """States (steps + 1, nq + nv) of ``scene`` from its initial state under a constant input
    ``u`` (nu,) (zero by default), stepped by
    :class:`~drake_abs.multibody.stepper.ComplementarityStepper` with the scene's smoothing and
    activation distance (no Jacobians)."""
    model = build_scene_model(scene)
    stepper = model.stepper()
    nu = model.plant.num_actuators()
    u = np.zeros(nu) if u is None else np.asarray(u, dtype=float)
    xs = np.empty((steps + 1, model.plant.num_positions() + model.plant.num_velocities()))
    xs[0] = np.concatenate([model.q0, model.v0])
    for k in range(steps):
        xs[k + 1] = stepper.step(xs[k][None], u[None], jacobians=False).x_next[0]
    return xs


def record_scene(
    scene: Scene | str | Path,
    steps: int,
    path: str | Path,
    *,
    meshcat: Meshcat | None = None,
) -> Path:
    """Roll ``scene`` (a Scene or a YAML file) out for ``steps`` steps from its initial state
    with zero actuation and write the Meshcat recording to ``path`` (HTML)."""
    if not isinstance(scene, Scene):
        scene = Scene.from_yaml(Path(scene))
    return record_rollout_html(scene, rollout_states(scene, steps), path, meshcat=meshcat)
