"""The gym scenes' contact candidates are MuJoCo's geometry against the ground: over random poses
(every hinge within its range, any orientation of the root), the lowest contact surface of a
scene (the smallest signed distance of its candidate spheres) is the lowest surface of the
MuJoCo model's capsules and spheres, to rounding. The Ant's radii include its file's contact
margin (0.01 m, :data:`MARGIN_IN_RADIUS`); the other scenes' are the geoms' own (the Hopper's
0.001 m margin is the soft-contact option's, ``compliance: {from_model: true}``).

A left-out capsule end fails this: before the HalfCheetah's knees were candidates, its lowest
point was up to 21 cm below ours in 4 % of the poses, and the Hopper's knee (the leg capsule's
0.04 m end standing in for the thigh's 0.05 m one) up to 1 cm in 10 %."""

from __future__ import annotations

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
mujoco = pytest.importorskip("mujoco")

from drake_abs.multibody.builder import build_scene_model  # noqa: E402
from drake_abs.tasks.free_body import FreeBodyCoordinates  # noqa: E402

SCENES = [("gym_hopper", "Hopper-v5"), ("gym_half_cheetah", "HalfCheetah-v5"),
          ("gym_walker2d", "Walker2d-v5"), ("gym_ant", "Ant-v5")]  # fmt: skip
#: the contact margin (m) a scene's candidate radii include (the scene files say so)
MARGIN_IN_RADIUS = {"gym_ant": 0.01}


def _random_qpos(model, rng) -> np.ndarray:
    """MuJoCo's qpos with every hinge uniform in its range (+-pi without one) and a free root at
    1 m in a uniformly random orientation."""
    qpos = model.qpos0.copy()
    for j in range(model.njnt):
        a = model.jnt_qposadr[j]
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            lo, hi = model.jnt_range[j] if model.jnt_limited[j] else (-np.pi, np.pi)
            qpos[a] = rng.uniform(lo, hi)
        elif model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            e = rng.standard_normal(4)
            qpos[a : a + 3] = (0.0, 0.0, 1.0)
            qpos[a + 3 : a + 7] = e / np.linalg.norm(e)
    return qpos


def _lowest_surface(model, data) -> float:
    """The lowest point of the model's capsules and spheres (m), after ``mj_kinematics``.
    Against a plane a capsule's lowest point is one of its ends."""
    capsule, sphere = int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_SPHERE)
    low = np.inf
    for i in range(model.ngeom):
        kind = int(model.geom_type[i])
        if kind not in (capsule, sphere):
            continue
        z = data.geom_xpos[i, 2]
        if kind == capsule:
            z -= model.geom_size[i, 1] * abs(data.geom_xmat[i].reshape(3, 3)[2, 2])
        low = min(low, z - model.geom_size[i, 0])
    return low


@pytest.mark.parametrize(("scene", "env_id"), SCENES)
def test_the_lowest_candidate_is_mujocos_lowest_geom(scene, env_id):
    sm = build_scene_model(scene)
    model = gymnasium.make(env_id).unwrapped.model
    data = mujoco.MjData(model)
    free = FreeBodyCoordinates(model.nq - 7) if model.nq != model.nv else None
    rng = np.random.default_rng(11)
    ours, theirs = [], []
    for _ in range(300):
        qpos = _random_qpos(model, rng)
        if free is not None:  # our q: (quaternion, position, joints)
            q = free.from_mujoco(np.concatenate([qpos, np.zeros(model.nv)])[None])[0, : model.nq]
        else:  # the planar scenes' q is MuJoCo's qpos
            q = qpos
        data.qpos[:] = qpos
        mujoco.mj_kinematics(model, data)
        theirs.append(_lowest_surface(model, data) - MARGIN_IN_RADIUS.get(scene, 0.0))
        ours.append(sm.contact_model.distances(q[None])[0].min() + sm.scene.ground_height)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-8)


def _combined_friction(model, geom: int, floor: int) -> float:
    """MuJoCo's sliding friction of a contact between ``geom`` and ``floor`` at equal priority:
    the larger of the two geoms' (every gym file here has priority 0 and no explicit pair)."""
    assert model.geom_priority[geom] == model.geom_priority[floor] == 0
    return float(max(model.geom_friction[geom, 0], model.geom_friction[floor, 0]))


@pytest.mark.parametrize(("scene", "env_id"), SCENES)
def test_every_candidate_has_mujocos_friction_against_the_floor(scene, env_id):
    """Each candidate's friction coefficient is MuJoCo's for its body's geom against the floor.
    The HalfCheetah's file gives every geom, the floor included, 0.4: a scene with 1.0 (as ours
    had) gives its policies traction that MuJoCo's HalfCheetah does not have."""
    sm = build_scene_model(scene)
    model = gymnasium.make(env_id).unwrapped.model
    floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    assert floor >= 0 and model.npair == 0
    colliding = [g for g in range(model.ngeom) if g != floor and (
                 model.geom_contype[g] & model.geom_conaffinity[floor]
                 or model.geom_conaffinity[g] & model.geom_contype[floor])]  # fmt: skip
    combined = {_combined_friction(model, g, floor) for g in colliding}
    ours = {c.friction for c in sm.scene.contacts}
    assert ours == combined, (ours, combined)
    checked = 0
    for contact in sm.scene.contacts:  # by body, where the body has its MuJoCo name
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, contact.body)
        geoms = [g for g in colliding if model.geom_bodyid[g] == body]
        if body < 0 or not geoms:
            continue
        assert contact.friction in {_combined_friction(model, g, floor) for g in geoms}, contact
        checked += 1
    assert checked >= 1
