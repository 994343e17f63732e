"""A scene with every model's floating base in one set of coordinates, its initial state carried
over: what ``AddComplementarityPlantSceneGraph(..., floating_base="quaternion")`` builds.

A scene's free root body floats on a chain of joints by default, q = (x, y, z, yaw, pitch,
roll) and v their rates (``ModelSpec.floating_base: euler``, singular at pitch = +-pi/2);
``floating_base: quaternion`` gives it Drake's ``QuaternionFloatingJoint``, q = (qw, qx, qy,
qz, x, y, z) and v = (angular, translational velocity in the world), the coordinates a
MultibodyPlant gives a free body by default. A URDF ``floating`` joint is a quaternion joint
either way. :func:`with_floating_base` sets one of them for every model of a scene; where the
scene gives an ``initial_state`` it is rewritten in the new coordinates so that every body
starts with the same pose and spatial velocity (checked).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, JacobianWrtVariable

from drake_abs.multibody.builder import add_scene_models
from drake_abs.multibody.parsing import FLOATING_BASE_JOINTS
from drake_abs.multibody.scene import InitialState, Scene
from drake_abs.multibody.scene_entries import FLOATING_BASES

#: how closely (m, rad; m/s, rad/s) the carried-over state must reproduce every body's pose and
#: spatial velocity
TOLERANCE = 1e-9


def with_floating_base(scene: Scene, floating_base: str) -> Scene:
    """``scene`` with ``floating_base`` (``"euler"`` or ``"quaternion"``) for every model
    (a welded model has no floating base: unchanged), and its ``initial_state`` (where given)
    rewritten in the new coordinates: the same pose and spatial velocity of every body, a
    joint of the files keeping its own q and v. ``scene`` itself when nothing changes.

    Raises:
        ValueError: for another ``floating_base``, or an initial state the new coordinates
            cannot hold (an angular velocity about the singular axis of roll-pitch-yaw at
            pitch = +-pi/2).
    """
    if floating_base not in FLOATING_BASES:
        raise ValueError(
            f"floating_base must be one of {list(FLOATING_BASES)}; got {floating_base!r}"
        )
    models = tuple(replace(m, floating_base=floating_base) for m in scene.models)
    if models == scene.models:
        return scene
    new = replace(scene, models=models)
    given = scene.initial_state
    if given.q is None and given.v is None:
        return new  # both start at the model files' default poses, at rest
    old_plant, new_plant = _plant(scene), _plant(new)
    if (old_plant.num_positions(), old_plant.num_velocities()) == (
        new_plant.num_positions(),
        new_plant.num_velocities(),
    ) and _same_joints(old_plant, new_plant):
        return new  # no free body changed coordinates
    old_ctx, new_ctx = old_plant.CreateDefaultContext(), new_plant.CreateDefaultContext()
    if given.q is not None:
        old_plant.SetPositions(old_ctx, np.asarray(given.q, float))
    if given.v is not None:
        old_plant.SetVelocities(old_ctx, np.asarray(given.v, float))
    _carry_positions(old_plant, old_ctx, new_plant, new_ctx, scene.name)
    _carry_velocities(old_plant, old_ctx, new_plant, new_ctx, scene.name)
    q = tuple(float(x) for x in new_plant.GetPositions(new_ctx))
    v = tuple(float(x) for x in new_plant.GetVelocities(new_ctx))
    return replace(
        new,
        initial_state=InitialState(
            q=q if given.q is not None else None, v=v if given.v is not None else None
        ),
    )


def _plant(scene: Scene) -> MultibodyPlant:
    plant = MultibodyPlant(0.0)
    add_scene_models(plant, scene)
    plant.Finalize()
    return plant


def _key(plant: MultibodyPlant, element) -> tuple[str, str]:
    return plant.GetModelInstanceName(element.model_instance()), element.name()


def _joints(plant: MultibodyPlant) -> dict[tuple[str, str], object]:
    return {_key(plant, plant.get_joint(i)): plant.get_joint(i) for i in plant.GetJointIndices()}


def _bodies(plant: MultibodyPlant) -> dict[tuple[str, str], object]:
    return {
        _key(plant, plant.get_body(BodyIndex(i))): plant.get_body(BodyIndex(i))
        for i in range(plant.num_bodies())
    }


def _same_joints(a: MultibodyPlant, b: MultibodyPlant) -> bool:
    ja, jb = _joints(a), _joints(b)
    return ja.keys() == jb.keys() and all(
        ja[k].type_name() == jb[k].type_name() and ja[k].position_start() == jb[k].position_start()
        for k in ja
    )


def _chain_body(name: str) -> tuple[str, int] | None:
    """``(body, j)`` for the j-th joint of a floating-base chain (``<body>_x`` ...)."""
    for j, (suffix, _, _) in enumerate(FLOATING_BASE_JOINTS):
        if name.endswith(f"_{suffix}"):
            return name[: -len(suffix) - 1], j
    return None


def _carry_positions(old, old_ctx, new, new_ctx, where: str) -> None:
    """Set q of ``new_ctx`` from ``old_ctx``: a joint both plants have (same name, model
    instance and type) keeps its q; a new quaternion floating joint or floating-base chain
    takes its body's world pose; then every shared body's pose is checked."""
    old_joints, old_bodies = _joints(old), _bodies(old)
    q = new.GetPositions(new_ctx).copy()
    for key, joint in _joints(new).items():
        n, start = joint.num_positions(), joint.position_start()
        if n == 0:
            continue
        match = old_joints.get(key)
        if match is not None and match.type_name() == joint.type_name():
            q[start : start + n] = old.GetPositions(old_ctx)[
                match.position_start() : match.position_start() + n
            ]
            continue
        if joint.type_name() == "quaternion_floating":
            body = old_bodies[_key(new, joint.child_body())]
            X = old.EvalBodyPoseInWorld(old_ctx, body)
            q[start : start + 4] = X.rotation().ToQuaternion().wxyz()
            q[start + 4 : start + 7] = X.translation()
            continue
        chain = _chain_body(key[1])
        body = old_bodies.get((key[0], chain[0])) if chain is not None else None
        if body is None:
            raise ValueError(
                f"scene {where!r}: joint {key[1]!r} of model {key[0]!r} has no counterpart to "
                "take its initial state from"
            )
        X = old.EvalBodyPoseInWorld(old_ctx, body)
        rpy = RollPitchYaw(X.rotation())
        values = (*X.translation(), rpy.yaw_angle(), rpy.pitch_angle(), rpy.roll_angle())
        q[start] = values[chain[1]]
    new.SetPositions(new_ctx, q)
    for key, body in _bodies(new).items():
        if key in old_bodies:
            X_old: RigidTransform = old.EvalBodyPoseInWorld(old_ctx, old_bodies[key])
            X_new: RigidTransform = new.EvalBodyPoseInWorld(new_ctx, body)
            if not X_new.IsNearlyEqualTo(X_old, TOLERANCE):
                raise ValueError(
                    f"scene {where!r}: the initial state does not carry over: body {key[1]!r} "
                    "is posed differently in the new coordinates"
                )


def _carry_velocities(old, old_ctx, new, new_ctx, where: str) -> None:
    """Set v of ``new_ctx`` (its q set) so that every body both plants have moves with its
    spatial velocity in ``old_ctx`` (least squares, checked to :data:`TOLERANCE`)."""
    old_bodies = _bodies(old)
    world = new.world_frame()
    rows, target = [], []
    for key, body in _bodies(new).items():
        if key not in old_bodies or body.index() == new.world_body().index():
            continue
        rows.append(
            new.CalcJacobianSpatialVelocity(
                new_ctx, JacobianWrtVariable.kV, body.body_frame(), np.zeros(3), world, world
            )
        )
        target.append(old.EvalBodySpatialVelocityInWorld(old_ctx, old_bodies[key]).get_coeffs())
    J, V = np.vstack(rows), np.concatenate(target)
    v = np.linalg.lstsq(J, V, rcond=None)[0]
    if not np.abs(J @ v - V).max() <= TOLERANCE * (1.0 + np.abs(V).max()):
        raise ValueError(
            f"scene {where!r}: the initial velocities do not carry over to the new coordinates "
            "(an angular velocity roll-pitch-yaw cannot hold at pitch = +-pi/2?)"
        )
    new.SetVelocities(new_ctx, v)
