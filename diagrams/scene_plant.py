"""One call to put a scene's complementarity plant, with its geometry, into a diagram: the
counterpart of Drake's ``AddMultibodyPlantSceneGraph``.

    builder = DiagramBuilder()
    plant, scene_graph = AddComplementarityPlantSceneGraph(builder, "box_push")
    MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)

The plant's ``geometry_pose`` output is connected to the SceneGraph, so Drake's visualizers and
SceneGraph queries (the declared contact points and the ground are proximity geometry) work as
with a MultibodyPlant.
"""

from __future__ import annotations

from pathlib import Path

from pydrake.geometry import SceneGraph
from pydrake.systems.framework import DiagramBuilder

from drake_abs.contact.unconverged import OnUnconverged
from drake_abs.multibody.builder import build_scene_model, check_stepper_keywords
from drake_abs.multibody.scene import Scene
from drake_abs.multibody.scene_floating_base import with_floating_base
from drake_abs.systems import ComplementarityPlant


def AddComplementarityPlantSceneGraph(
    builder: DiagramBuilder,
    scene: Scene | str | Path,
    *,
    on_unconverged: OnUnconverged = "drop",
    floating_base: str | None = None,
    plant_name: str = "plant",
    scene_graph_name: str = "scene_graph",
    **stepper_options,
) -> tuple[ComplementarityPlant, SceneGraph]:
    """Add a scene's :class:`~drake_abs.systems.ComplementarityPlant` and a SceneGraph holding
    its geometry to ``builder``, connected; return ``(plant, scene_graph)``.

    Args:
        builder: the diagram builder.
        scene: a :class:`Scene`, a shipped scene's name (e.g. ``"box_push"``) or a YAML path.
        on_unconverged: see :class:`~drake_abs.systems.ComplementarityPlant`.
        floating_base: None (default): each model's free root body floats as its scene entry
            says (``ModelSpec.floating_base``, ``"euler"`` unless set: q = (x, y, z, yaw,
            pitch, roll), v their rates). ``"quaternion"``: every free root body on Drake's
            ``QuaternionFloatingJoint``, q = (qw, qx, qy, qz, x, y, z), v = (angular,
            translational velocity in the world), as a MultibodyPlant's default (``"euler"``:
            every one on the chain). The scene's ``initial_state`` is carried over to the new
            coordinates (same body poses and velocities:
            :func:`~drake_abs.multibody.scene_floating_base.with_floating_base`). A URDF
            ``floating`` joint is a quaternion joint either way; a welded model has none.
        plant_name, scene_graph_name: the systems' names in the diagram.
        stepper_options: passed to :meth:`~drake_abs.multibody.builder.SceneModel.stepper`
            (``smoothing``, ``gradient``, ``activation_distance``, ``friction``, ...), overriding
            the scene's settings. Any other name is refused here, before the plant is built
            (``ValueError``); a scene setting such as ``time_step`` is changed in the scene:
            ``Scene.from_dict({**Scene.load("box_push").to_dict(), "time_step": 0.001})``.

    The plant's initial state in a new Context is the scene's (``initial_state``, else the
    model files' default).
    """
    if not isinstance(builder, DiagramBuilder):
        raise ValueError(f"builder must be a DiagramBuilder; got {type(builder).__name__}")
    if not isinstance(scene, Scene):
        scene = Scene.load(scene)
    check_stepper_keywords(stepper_options, scene, "AddComplementarityPlantSceneGraph")
    if floating_base is not None:
        scene = with_floating_base(scene, floating_base)
    model = build_scene_model(scene)
    scene_graph = builder.AddNamedSystem(scene_graph_name, SceneGraph())
    plant = ComplementarityPlant(
        model.stepper(**stepper_options), on_unconverged, scene_graph, model.scene, model.x0
    )
    builder.AddNamedSystem(plant_name, plant)
    builder.Connect(
        plant.get_geometry_pose_output_port(),
        scene_graph.get_source_pose_port(plant.get_source_id()),
    )
    return plant, scene_graph
