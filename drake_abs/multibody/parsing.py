"""A scene's model files parsed into a MultibodyPlant: welds, actuators and floating bases.

:func:`add_model_specs` parses a scene's :class:`~drake_abs.multibody.scene_entries.ModelSpec`
entries (:func:`drake_abs.multibody.builder.add_scene_models` for a whole scene); a free root
body gets a floating base made of joints (:func:`add_floating_base_chains`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    ModelInstanceIndex,
    PrismaticJoint,
    QuaternionFloatingJoint,
    RevoluteJoint,
    SpatialInertia,
)

from drake_abs.multibody.model_files import add_models, apply_mjcf, read_mjcf
from drake_abs.multibody.packages import register_packages, resolve_package_file
from drake_abs.multibody.scene_entries import ModelSpec


def resolve_model_file(spec: ModelSpec, where: str = "") -> Path:
    """The model file a ModelSpec names (see
    :func:`~drake_abs.multibody.packages.resolve_package_file`); ``where`` (such as
    ``"scene 'box_push': models[0].file"``) prefixes the message of an unknown package."""
    return resolve_package_file(spec.file, where)


def _parse(
    parser: Parser, path: Path, collisions: bool, spec: ModelSpec, where: str, obj_meshes=False
):
    """Parse one model file: its model instances, with the bodies its URDF ``floating`` joints
    name given a quaternion floating joint of that name, at the joint's origin (see
    :func:`add_floating_base_chains`); an MJCF file (``.xml``) checked and completed by
    :func:`~drake_abs.multibody.model_files.read_mjcf` and
    :func:`~drake_abs.multibody.model_files.apply_mjcf` (``spec.ignore``, ``spec.keyframe``)."""
    mjcf = None
    if path.suffix.lower() == ".xml":
        try:
            mjcf = read_mjcf(path, spec.ignore)
        except ValueError as err:
            raise ValueError(f"{where} ({spec.file}): {err}") from err
    elif spec.ignore or spec.keyframe is not None:
        raise ValueError(
            f"{where}: ignore and keyframe apply to MuJoCo files (.xml) only; {spec.file!r} is "
            "not one"
        )
    instances, floating = add_models(
        parser, path, collisions=collisions, mjcf=mjcf, obj_meshes=obj_meshes
    )
    plant = parser.plant()
    if mjcf is not None:
        apply_mjcf(plant, instances[0], mjcf, spec.keyframe, where=f"{where} ({spec.file})")
    for joint in floating:
        body = plant.GetBodyByName(joint.link, instances[0])
        added = plant.AddJoint(
            QuaternionFloatingJoint(joint.name, plant.world_frame(), body.body_frame())
        )
        added.SetDefaultPose(RigidTransform(RollPitchYaw(joint.rpy), joint.xyz))
    return instances


def add_model_specs(
    plant: MultibodyPlant,
    models: Sequence[ModelSpec],
    where: str | Callable[[str], str],
    parser: Parser | None = None,
    *,
    collisions: bool = True,
    obj_meshes: bool = False,
) -> None:
    """Parse ``models`` (a scene's) into ``plant`` (not finalized), with welds, actuators and
    floating bases (a quaternion floating joint where a URDF declares a ``floating`` joint to
    the world, :func:`add_floating_base_chains` for the other free bodies); ``collisions=False``
    leaves the files' collision geometry out (and draws STL visuals through OBJ copies; see
    :mod:`drake_abs.multibody.model_files`); ``obj_meshes=True`` keeps it, with STL meshes
    replaced by OBJ copies, for a plant registered with a SceneGraph.

    ``where`` starts every error message: a text (``"scene 'box_push'"``), or a function of the
    scene key the error is about (``"models[0].file"``) such as
    :meth:`~drake_abs.multibody.scene.Scene.locate`, which names the scene file and the key's
    line. A missing model file, a ``weld`` frame or an ``actuate`` joint the file does not
    have is reported with its key."""
    locate = where if callable(where) else (lambda key: where)
    parser = parser or Parser(plant)
    register_packages(parser.package_map())  # the files' own package:// URIs (meshes)
    for i, spec in enumerate(models):
        entry = f"{locate(f'models[{i}]')}: models[{i}]"
        key = f"models[{i}].file"
        path = resolve_model_file(spec, where=f"{locate(key)}: {key}")
        instances = _parse(parser, path, collisions, spec, entry, obj_meshes)
        instance = instances[0]
        if spec.name:
            plant.RenameModelInstance(instance, spec.name)
        if spec.weld:
            if not plant.HasFrameNamed(spec.weld, instance):
                key = f"models[{i}].weld"
                frames = sorted(plant.get_frame(f).name() for f in plant.GetFrameIndices(instance))
                raise ValueError(
                    f"{locate(key)}: {key}: {spec.file} has no frame {spec.weld!r} to weld; its "
                    f"frames: {', '.join(frames)}"
                )
            plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(spec.weld, instance))
        for j, joint in enumerate(spec.actuate):
            if not plant.HasJointNamed(joint, instance):
                key = f"models[{i}].actuate[{j}]"
                joints = sorted(plant.get_joint(k).name() for k in plant.GetJointIndices(instance))
                raise ValueError(
                    f"{locate(key)}: {key}: {spec.file} has no joint {joint!r} to actuate; its "
                    f"joints: {', '.join(joints) or 'none'}"
                )
            plant.AddJointActuator(f"{joint}_actuator", plant.GetJointByName(joint, instance))
        if spec.floating_base == "quaternion":
            add_quaternion_floating_joints(plant, instances)
    add_floating_base_chains(plant)


def add_quaternion_floating_joints(plant: MultibodyPlant, instances) -> list[str]:
    """Give every free root body of the model ``instances`` of ``plant`` (not finalized) a
    quaternion floating joint to the world, named by the body, at the body's default pose from
    its model file (``ModelSpec.floating_base: quaternion``). Returns the bodies' names."""
    inboard = {int(plant.get_joint(i).child_body().index()) for i in plant.GetJointIndices()}
    world = int(plant.world_body().index())
    names = []
    for instance in instances:
        for i in plant.GetBodyIndices(instance):
            if int(i) == world or int(i) in inboard:
                continue
            body = plant.get_body(i)
            pose = plant.GetDefaultFloatingBaseBodyPose(body)
            joint = plant.AddJoint(
                QuaternionFloatingJoint(body.name(), plant.world_frame(), body.body_frame())
            )
            joint.SetDefaultPose(pose)
            names.append(body.name())
    return names


#: The joints of a floating base, parent to child, with q = (x, y, z, yaw, pitch, roll) and v their
#: rates, with the body's pose p = (x, y, z), R = Rz(yaw) Ry(pitch) Rx(roll).
FLOATING_BASE_JOINTS = (
    ("x", PrismaticJoint, (1.0, 0.0, 0.0)),
    ("y", PrismaticJoint, (0.0, 1.0, 0.0)),
    ("z", PrismaticJoint, (0.0, 0.0, 1.0)),
    ("yaw", RevoluteJoint, (0.0, 0.0, 1.0)),
    ("pitch", RevoluteJoint, (0.0, 1.0, 0.0)),
    ("roll", RevoluteJoint, (1.0, 0.0, 0.0)),
)


def add_floating_base_chains(plant: MultibodyPlant) -> list[str]:
    """Give every free root body of ``plant`` (not finalized) a floating base made of joints:
    three prismatic and three revolute joints (:data:`FLOATING_BASE_JOINTS`) through massless
    intermediate bodies, named ``<body>_x`` ... ``<body>_roll``. Its coordinates are positions
    and Euler angles with ``qdot = v`` (the velocities are the angle rates, not the angular
    velocity), so rigid-body libraries and the step's Jacobians need no quaternion or
    angular-velocity map; like any roll-pitch-yaw parametrisation it is singular at
    pitch = +-pi/2. Bodies that already have a joint from the world (such as the quaternion
    floating joint a URDF ``floating`` joint asks for: see :func:`add_model_specs`) keep it.
    Each chain's default positions place the body at its default pose from the model file (an
    SDF link's ``<pose>``, an MJCF body's ``pos``/``quat``): x, y, z and the yaw, pitch and roll
    of its orientation. Returns the names of the bodies given a floating base."""
    inboard = {int(plant.get_joint(i).child_body().index()) for i in plant.GetJointIndices()}
    roots = []
    for k in range(plant.num_model_instances()):
        instance = ModelInstanceIndex(k)
        for i in plant.GetBodyIndices(instance):
            body = plant.get_body(i)
            if int(i) != int(plant.world_body().index()) and int(i) not in inboard:
                roots.append(body)
    for body in roots:
        pose = plant.GetDefaultFloatingBaseBodyPose(body)
        rpy = RollPitchYaw(pose.rotation())
        default = (*pose.translation(), rpy.yaw_angle(), rpy.pitch_angle(), rpy.roll_angle())
        parent = plant.world_body()
        instance = body.model_instance()
        for j, (name, kind, axis) in enumerate(FLOATING_BASE_JOINTS):
            last = j == len(FLOATING_BASE_JOINTS) - 1
            child = (
                body
                if last
                else plant.AddRigidBody(f"{body.name()}_{name}", instance, SpatialInertia.Zero())
            )
            joint = plant.AddJoint(
                kind(f"{body.name()}_{name}", parent.body_frame(), child.body_frame(), axis)
            )
            joint.set_default_positions([float(default[j])])
            parent = child
    return [b.name() for b in roots]
