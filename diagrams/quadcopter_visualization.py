"""Meshcat playback of quadcopter flights, saved as a self-contained HTML page.

One hector quadrotor (example-robot-data ``hector_description``, visual geometry only) is drawn
per trajectory; each is posed from the 12-state x (position, and roll-pitch-yaw: Drake's
``RollPitchYaw(phi, theta, psi)`` is the Z-Y-X rotation of :mod:`drake_abs.tasks.quadcopter`) at
every control step, recorded as a Meshcat animation at ``1 / time_step`` frames per second, with
the flown path drawn as a line and the target as a sphere. Meshcat binds to localhost only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydrake.geometry import (
    Meshcat,
    MeshcatParams,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    Rgba,
    Role,
    Sphere,
)
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from drake_abs.multibody.model_files import add_models_without_collisions
from drake_abs.multibody.packages import example_robot_data_dir

HECTOR_URDF = "hector_description/robots/quadrotor_base.urdf"
PATH_COLORS = (
    Rgba(0.12, 0.47, 0.71, 1.0),
    Rgba(0.85, 0.37, 0.01, 1.0),
    Rgba(0.17, 0.63, 0.17, 1.0),
    Rgba(0.58, 0.40, 0.74, 1.0),
)
TARGET_RGBA = Rgba(0.85, 0.1, 0.1, 0.6)


def hector_urdf() -> Path:
    """The hector quadrotor URDF of the installed example-robot-data."""
    path = example_robot_data_dir() / "robots" / HECTOR_URDF
    if not path.is_file():
        raise FileNotFoundError(f"hector quadrotor model not found at {path}")
    return path


def record_quadcopter_html(
    trajectories: dict[str, np.ndarray],
    path: str | Path,
    *,
    time_step: float = 0.1,
    target=None,
    meshcat: Meshcat | None = None,
) -> Path:
    """Replay quadcopter trajectories in Meshcat and write the animation as an HTML page.

    Args:
        trajectories: name -> (T + 1, 12) states (at most four; drawn in distinct colours).
        path: the HTML file to write (its folder is created).
        time_step: seconds between states.
        target: (3,) position drawn as a sphere (optional).
        meshcat: the Meshcat to draw in (cleared first); default a new one on localhost.

    Returns:
        The path written.
    """
    if not trajectories or len(trajectories) > len(PATH_COLORS):
        raise ValueError(f"trajectories must hold 1 to {len(PATH_COLORS)} entries")
    states = {}
    for name, xs in trajectories.items():
        xs = np.asarray(xs, dtype=float)
        if xs.ndim != 2 or xs.shape[1] != 12 or len(xs) == 0:
            raise ValueError(f"trajectory {name!r} must have shape (T + 1, 12); got {xs.shape}")
        if not np.all(np.isfinite(xs)):
            raise ValueError(f"trajectory {name!r} must be finite")
        states[name] = xs
    if not (np.isfinite(time_step) and time_step > 0):
        raise ValueError(f"time_step must be a finite number > 0; got {time_step!r}")
    meshcat = meshcat or Meshcat(MeshcatParams(host="localhost"))
    meshcat.Delete()
    meshcat.DeleteRecording()

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    parser = Parser(plant)
    parser.SetAutoRenaming(True)
    parser.package_map().Add("example-robot-data", str(example_robot_data_dir()))
    bodies = []
    for _ in states:
        (instance,) = add_models_without_collisions(parser, hector_urdf())
        bodies.append(plant.GetBodyByName("base_link", instance))
    plant.Finalize()
    params = MeshcatVisualizerParams(role=Role.kIllustration, publish_period=time_step)
    visualizer = MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)

    steps = max(len(xs) for xs in states.values())
    visualizer.StartRecording(set_transforms_while_recording=True)
    for k in range(steps):
        context.SetTime(k * time_step)
        for body, xs in zip(bodies, states.values(), strict=True):
            x = xs[min(k, len(xs) - 1)]
            pose = RigidTransform(RollPitchYaw(x[6], x[7], x[8]), x[:3])
            plant.SetFreeBodyPose(plant_context, body, pose)
        diagram.ForcedPublish(context)
    visualizer.StopRecording()
    visualizer.PublishRecording()

    points = np.vstack([xs[:, :3] for xs in states.values()])
    for i, (name, xs) in enumerate(states.items()):
        meshcat.SetLine(f"paths/{name}", xs[:, :3].T.copy(), 2.0, PATH_COLORS[i])
    if target is not None:
        target = np.asarray(target, dtype=float)
        meshcat.SetObject("target", Sphere(0.08), TARGET_RGBA)
        meshcat.SetTransform("target", RigidTransform(target))
        points = np.vstack([points, target])
    lo, hi = points.min(axis=0), points.max(axis=0)
    center = 0.5 * (lo + hi)
    extent = float(max(np.max(hi - lo), 1.0))
    direction = np.array([0.3, -1.0, 0.8])
    meshcat.SetCameraPose(center + 1.3 * extent * direction / np.linalg.norm(direction), center)

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(meshcat.StaticHtml())
    return path
