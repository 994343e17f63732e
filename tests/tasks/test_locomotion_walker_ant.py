"""gymnasium's Walker2d-v5 and Ant-v5 on our plant (scenes gym_walker2d, gym_ant; tasks
"walker2d", "ant" of drake_abs.tasks.locomotion, drake_abs.tasks.ant, drake_abs.tasks.free_body).

Against MuJoCo (gymnasium's own models and environments): the scenes' masses and inertias, a
passive free flight stepped by both with the same integrator, the observation vector, the reward
(gymnasium's ``_get_rew`` on our transitions), termination (``is_healthy``), reset noise (same
seed), gears and control range, and the Ant's contact wrenches (``cfrc_ext``) at rest, where soft
and hard contact come close. Derivatives against central differences; a rollout's policy gradient
through the engine; gymnasium's ``check_env``.
"""

from __future__ import annotations

import pickle
from dataclasses import replace

import numpy as np
import pytest
from numdiff import central_difference

gymnasium = pytest.importorskip("gymnasium")
mujoco = pytest.importorskip("mujoco")

from drake_abs.engine import rollout  # noqa: E402
from drake_abs.multibody.builder import build_scene_model  # noqa: E402
from drake_abs.multibody.scene import Scene  # noqa: E402
from drake_abs.policy.policies import LinearPolicy  # noqa: E402
from drake_abs.reference.mujoco_plant import MujocoStepper  # noqa: E402
from drake_abs.tasks.free_body import FreeBodyCoordinates  # noqa: E402
from drake_abs.tasks.gym_env import DrakeAbsEnv  # noqa: E402
from drake_abs.tasks.locomotion import locomotion_task  # noqa: E402

NAMES = ("walker2d", "ant")
ENV_IDS = {"walker2d": "Walker2d-v5", "ant": "Ant-v5"}
SCENES = {"walker2d": "gym_walker2d", "ant": "gym_ant"}


@pytest.fixture(scope="module")
def tasks():
    return {name: locomotion_task(name) for name in NAMES}


@pytest.fixture(scope="module")
def gym_envs():
    envs = {name: gymnasium.make(ENV_IDS[name]).unwrapped for name in NAMES}
    yield envs
    for env in envs.values():
        env.close()


def to_mujoco(task, x) -> np.ndarray:
    """MuJoCo's (qpos, qvel) (M, nx) of our states x (M, nx)."""
    coords = task.reset_noise.coordinates
    return np.asarray(x, float) if coords is None else coords.to_mujoco(x)


def set_mujoco(env, task, x):
    xm = to_mujoco(task, x[None])[0]
    env.set_state(xm[: env.model.nq], xm[env.model.nq :])


def random_states(rng, task, M, *, velocity=3.0):
    """States near the initial one (Ant: a random unit quaternion near level), height kept."""
    x = np.tile(task.x0, (M, 1))
    x[:, : task.nq] += rng.uniform(-0.1, 0.1, (M, task.nq))
    x[:, task.nq :] += velocity * rng.standard_normal((M, task.nx - task.nq))
    if task.name == "ant":
        x[:, 0:4] /= np.linalg.norm(x[:, 0:4], axis=1, keepdims=True)
        x[:, 6] = 0.6
    return x


# --------------------------------------------------------------------------- the scenes


@pytest.mark.parametrize("name", NAMES)
def test_masses_and_inertias_are_mujocos(name, gym_envs):
    """Every body's mass, centre of mass and rotational inertia (world frame, initial pose)."""
    sm = build_scene_model(Scene.load(SCENES[name]))
    model, data = gym_envs[name].model, mujoco.MjData(gym_envs[name].model)
    mujoco.mj_forward(model, data)
    plant = sm.plant
    ctx = plant.CreateDefaultContext()
    for b in range(1, model.nbody):
        body = plant.GetBodyByName(
            mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
        )
        X = plant.EvalBodyPoseInWorld(ctx, body)
        M_B = body.CalcSpatialInertiaInBodyFrame(ctx)
        R = X.rotation().matrix()
        I_ours = R @ M_B.Shift(M_B.get_com()).CalcRotationalInertia().CopyToFullMatrix3() @ R.T
        R_mj = data.ximat[b].reshape(3, 3)
        I_mj = R_mj @ np.diag(model.body_inertia[b]) @ R_mj.T
        assert M_B.get_mass() == pytest.approx(model.body_mass[b], rel=1e-14)
        np.testing.assert_allclose(X.multiply(M_B.get_com()), data.xipos[b], atol=1e-14)
        np.testing.assert_allclose(I_ours, I_mj, rtol=0, atol=1e-14 * np.abs(I_mj).max())
    report = sm.model_report()
    assert report["mass"] == pytest.approx(model.body_mass.sum(), rel=1e-14)
    joints = {j["name"]: j for j in report["joints"]}
    for j in range(1 if name == "ant" else 3, model.njnt):  # the legs' hinges
        info = joints[mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)]
        dof = model.jnt_dofadr[j]
        assert info["damping"] == model.dof_damping[dof]
        assert info["armature"] == model.dof_armature[dof]
        assert info["stiffness"] == model.jnt_stiffness[j] == 0.0  # no springs in these files
        np.testing.assert_allclose((info["lower"], info["upper"]), model.jnt_range[j], rtol=1e-15)
    assert not model.dof_frictionloss.any()  # nor dry joint friction


@pytest.mark.parametrize("name", NAMES)
def test_passive_free_flight_is_mujocos(name, tasks, rng):
    """Zero torque, in the air (joints inside their ranges, spinning, thrown up), 0.3 s at
    h = 2 ms, MuJoCo with the same semi-implicit Euler step: the Walker to rounding; the Ant to
    2e-8 (MuJoCo turns the quaternion by the exponential map, we by its linearisation and a
    normalisation: a third-order difference per step)."""
    h, task = 0.002, tasks[name]
    model = build_scene_model(replace(Scene.load(SCENES[name]), time_step=h))
    ours = model.stepper()
    theirs = MujocoStepper.from_gymnasium(
        ENV_IDS[name], frame_skip=1, options={"integrator": "Euler", "timestep": h}
    )
    x = task.x0.copy()
    nq = task.nq
    if name == "walker2d":
        x[1], x[3:9] = 2.0, [-0.5, -0.5, 0.0, -0.6, -0.4, 0.1]
    else:
        e = rng.standard_normal(4)
        x[0:4], x[6], x[7:nq] = (
            e / np.linalg.norm(e),
            2.0,
            [0.1, 0.8, -0.1, -0.8, 0.2, -0.9, 0, 0.9],
        )
    x[nq:] = rng.uniform(-0.5, 0.5, task.nx - nq)  # no joint reaches a limit in 0.3 s
    x[nq + (1 if name == "walker2d" else 5)] = 1.0  # up
    xo, xm = x[None], to_mujoco(task, x[None])
    u = np.zeros((1, task.nu))
    for _ in range(150):
        so = ours.step(xo, u, jacobians=False)
        xo, xm = so.x_next, theirs.step(xm, u, jacobians=False).x_next
        assert not so.impulse.any() and not so.limit_impulse.any()  # free flight throughout
    gap = np.abs(to_mujoco(task, xo) - xm).max()
    assert gap < (1e-13 if name == "walker2d" else 2e-8), gap


# --------------------------------------------------------------------------- against gymnasium


@pytest.mark.parametrize("name", NAMES)
def test_observation_is_gymnasiums(name, tasks, gym_envs, rng):
    task, env = tasks[name], gym_envs[name]
    x = random_states(rng, task, 6, velocity=8.0)
    ours = task.observation(x)
    for m in range(len(x)):
        set_mujoco(env, task, x[m])
        want = env._get_obs()
        if name == "ant":  # gymnasium's default adds cfrc_ext: the task's obs is its head
            assert want.shape == (105,) and task.n_obs == 27
            env.data.cfrc_ext[:] = rng.uniform(-3, 3, env.data.cfrc_ext.shape)
            full = task.observation.with_contact_forces(x[m : m + 1], env.data.cfrc_ext[None, 1:])
            np.testing.assert_allclose(full[0], env._get_obs(), rtol=0, atol=1e-15)
            want = want[:27]
        else:
            assert task.n_obs == 17
        np.testing.assert_allclose(ours[m], want, rtol=0, atol=1e-15)
    if name == "walker2d":
        assert np.any(np.abs(x[:, task.nq :]) > 10)  # the clip was exercised


@pytest.mark.parametrize("name", NAMES)
def test_one_transitions_reward_is_gymnasiums_formula(name, tasks, gym_envs, rng):
    """gymnasium's _get_rew on the state after our step, with our velocity over the control
    period; the Ant's cfrc_ext set to our step's wrenches (its contact cost then is ours)."""
    task, env = tasks[name], gym_envs[name]
    x = task.x0[None] + 0.01 * rng.standard_normal((3, task.nx))
    if name == "ant":
        x[:, 6] = 0.58  # feet on the ground: contact in the step
    a = rng.uniform(-1.5, 1.5, (3, task.nu))
    step = task.stepper.step(x, a, jacobians=False)
    extra = {"step": step} if name == "ant" else {}
    r = task.reward.transition(x, a, step.x_next, **extra)[0]
    info = task.info(x, a, step.x_next, **extra)
    for m in range(3):
        set_mujoco(env, task, step.x_next[m])
        if name == "ant":
            env.data.cfrc_ext[0] = 0.0  # the world's row: always 0 in MuJoCo (cleared here)
            env.data.cfrc_ext[1:] = task.reward.wrenches(step.x_next, step)[m]
            velocity = info["x_velocity"][m]
        else:
            velocity = (step.x_next[m, 0] - x[m, 0]) / task.dt
        want, want_info = env._get_rew(velocity, a[m])
        assert r[m] == pytest.approx(want, rel=1e-12, abs=1e-12)
        for key, value in want_info.items():
            assert info[key][m] == pytest.approx(value, rel=1e-12, abs=1e-12), key
    if name == "ant":
        assert np.all(info["reward_contact"] < 0)  # the contact cost was exercised
    assert task.dt == env.dt


@pytest.mark.parametrize("name", NAMES)
def test_termination_is_gymnasiums(name, tasks, gym_envs, rng):
    task, env = tasks[name], gym_envs[name]
    x = random_states(rng, task, 40, velocity=30.0)
    if name == "walker2d":
        x[:, 1] = rng.uniform(0.6, 2.2, 40)
        x[:, 2] = rng.uniform(-1.3, 1.3, 40)
        edges = np.tile(task.x0, (4, 1))
        edges[0, 1], edges[1, 1], edges[2, 2], edges[3, 2] = 0.8, 2.0, 1.0, -1.0  # open
    else:
        x[:, 6] = rng.uniform(0.1, 1.1, 40)
        edges = np.tile(task.x0, (4, 1))
        edges[0, 6], edges[1, 6], edges[2, 6] = 0.2, 1.0, 1.0 + 1e-12  # closed interval
        edges[3, 20] = np.nan
    x = np.concatenate([x, edges])
    ours = task.reward.terminated(x)
    for m in range(len(x)):
        set_mujoco(env, task, x[m])
        assert ours[m] == (not env.is_healthy), m
    assert 5 < ours.sum() < len(x) - 5


@pytest.mark.parametrize("name", NAMES)
def test_reset_draws_gymnasiums_noise(name, tasks):
    """Same seed, same initial states (the Ant's mapped to MuJoCo's qpos, qvel: its noisy
    quaternion kept off the unit sphere, as gymnasium leaves it)."""
    task = tasks[name]
    theirs = gymnasium.make(ENV_IDS[name]).unwrapped
    ours = DrakeAbsEnv(task)
    for seed in (0, 7):
        ours.reset(seed=seed)
        theirs.reset(seed=seed)
        want = np.concatenate([theirs.data.qpos, theirs.data.qvel])
        np.testing.assert_allclose(to_mujoco(task, ours.state[None])[0], want, atol=1e-15)
    if name == "ant":
        assert abs(np.linalg.norm(ours.state[:4]) - 1) > 1e-3
    theirs.close()


@pytest.mark.parametrize("name", NAMES)
def test_gears_and_control_range_are_mujocos(name, tasks, gym_envs):
    task, env = tasks[name], gym_envs[name]
    np.testing.assert_array_equal(task.stepper.scale, env.model.actuator_gear[:, 0])
    np.testing.assert_array_equal(env.model.actuator_ctrlrange, np.tile([-1.0, 1.0], (task.nu, 1)))
    np.testing.assert_array_equal(task.plant.effort, task.stepper.scale)
    # the motors drive the same joints in the same order
    joint_of = [mujoco.mj_id2name(env.model, mujoco.mjtObj.mjOBJ_JOINT, j)
                for j in env.model.actuator_trnid[:, 0]]  # fmt: skip
    plant = task.plant.model.plant
    ours = [plant.get_joint_actuator(i).joint().name() for i in plant.GetJointActuatorIndices()]
    assert ours == joint_of
    assert DrakeAbsEnv(task).action_space == env.action_space


def test_ant_contact_wrenches_at_rest_come_close_to_mujocos(tasks, gym_envs):
    """The Ant settled by MuJoCo (40 zero-action steps from seed 0's reset), one step of each
    from the same state: the wrenches per body (cfrc_ext) and the contact cost. Measured: the
    same three feet in contact; normal forces within 0.35 N of MuJoCo's (3.9, 3.6, 1.7 N
    against 3.9, 3.7, 1.3), torques within 0.48 N m, the total force within 0.7 N (the weight
    is 8.94 N), friction components up to 0.66 N apart (three feet: the friction forces are
    statically indeterminate, soft and hard contact split them differently), the contact costs
    0.0070 and 0.0069. Not closer: MuJoCo's contact is soft (the settled state penetrates,
    which our hard step pushes out within the step) and its force is the last 10 ms physics
    step's, ours the mean over the 50 ms period."""
    task, env = tasks["ant"], gym_envs["ant"]
    env.reset(seed=0)
    for _ in range(40):
        env.step(np.zeros(8))
    x = task.reset_noise.coordinates.from_mujoco(
        np.concatenate([env.data.qpos, env.data.qvel])[None]
    )
    env.step(np.zeros(8))
    theirs = env.data.cfrc_ext[1:].copy()
    step = task.stepper.step(x, np.zeros((1, 8)), jacobians=False)
    ours = task.reward.wrenches(step.x_next, step)[0]
    touching = np.any(theirs != 0, axis=1)
    np.testing.assert_array_equal(np.any(np.abs(ours) > 1e-6, axis=1), touching)
    assert touching.sum() == 3
    assert np.abs(ours[:, 5] - theirs[:, 5]).max() < 0.4  # normal forces
    assert np.abs(ours[:, :3] - theirs[:, :3]).max() < 0.5  # torques
    assert np.abs(ours[:, 3:5] - theirs[:, 3:5]).max() < 0.7  # friction
    assert np.abs(ours[:, 3:].sum(0) - theirs[:, 3:].sum(0)).max() < 0.7
    assert task.reward.contact_cost(ours[None])[0] == pytest.approx(env.contact_cost, rel=0.05)
    # the wrench's torque is about the Ant's centre of mass (MuJoCo's subtree_com of the torso)
    p, com = task.reward.contact_wrenches.points_and_com(step.x_next[0, : task.nq])
    np.testing.assert_allclose(com, env.data.subtree_com[1], atol=0.02)


# --------------------------------------------------------------------------- derivatives


def test_free_body_map_and_its_jacobian(rng):
    coords = FreeBodyCoordinates(3)
    x = rng.standard_normal((4, coords.nx))
    x[:, :4] *= rng.uniform(0.5, 2.0, (4, 1))  # off the unit sphere too
    xm = coords.to_mujoco(x)
    np.testing.assert_allclose(coords.from_mujoco(xm), x, atol=1e-14)
    J = coords.jacobian(x)
    for m in range(4):
        fd = central_difference(lambda z: coords.to_mujoco(z[None])[0], x[m])
        np.testing.assert_allclose(J[m], fd, atol=1e-8)
    with pytest.raises(ValueError, match="x must have shape"):
        coords.to_mujoco(x[:, :-1])


@pytest.mark.parametrize("name", NAMES)
def test_observation_and_reward_derivatives_match_central_differences(name, tasks, rng):
    """Every smooth term. The Ant's contact cost has no derivative (module docstring): the
    check is on the reward without it (the step held fixed)."""
    task = tasks[name]
    obs, reward = task.observation, task.reward
    x = random_states(rng, task, 3, velocity=4.0)
    if name == "walker2d":
        x[:, task.nq :] += np.where(np.abs(np.abs(x[:, task.nq :]) - 10) < 0.01, 0.05, 0.0)
    x_next = random_states(rng, task, 3)
    u = rng.uniform(-1.2, 1.2, (3, task.nu))
    g = rng.standard_normal((3, obs.n_obs))
    J = obs.jacobian(x)
    extra = {}
    if name == "ant":
        extra = {"step": task.stepper.step(x_next, u, jacobians=False)}

    def smooth(x_, u_, xn_):
        terms = reward.terms(x_, u_, xn_)
        return sum(v for k, v in terms.items() if k.startswith("reward_"))

    _, dr_dx, dr_du, dr_dxn = reward.transition(x, u, x_next, **{k: v for k, v in extra.items()})
    for m in range(3):
        fd = central_difference(lambda z: obs(z[None])[0], x[m])
        np.testing.assert_allclose(J[m], fd, atol=1e-8)
        np.testing.assert_allclose(obs.vjp(x, g)[m], g[m] @ fd, atol=1e-8)
        xm, um, xnm = x[m : m + 1], u[m : m + 1], x_next[m : m + 1]
        for f, at, want in (
            (lambda z, um=um, xnm=xnm: smooth(z[None], um, xnm), x[m], dr_dx),
            (lambda z, xm=xm, xnm=xnm: smooth(xm, z[None], xnm), u[m], dr_du),
            (lambda z, xm=xm, um=um: smooth(xm, um, z[None]), x_next[m], dr_dxn),
        ):
            np.testing.assert_allclose(want[m], central_difference(f, at)[0], rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("name", NAMES)
def test_rollout_policy_gradient_matches_central_differences(name, tasks, rng):
    """A short rollout through the engine from gymnasium's noisy starts (the Walker in the
    air; the Ant landing from its first step's ankle-limit push, in contact in its last
    substeps), linear policy of the observation: the per-rollout gradient along two random
    directions against central differences of the returns. The Ant's contact cost has no
    derivative: its gradient equals that of the reward without the contact cost, which is
    checked against central differences; the contact cost's own share is measured."""
    task = tasks[name]
    inner = LinearPolicy(task.n_obs, task.nu)
    policy = task.policy(inner)
    theta = 0.05 * rng.standard_normal(inner.n_params)
    H = 4 if name == "walker2d" else 3
    x0 = task.initial_states(np.random.default_rng(5), 2)
    noise = rng.standard_normal((2, H, task.nu))
    smooth = task.reward if name == "walker2d" else replace(task.reward, contact_wrenches=None)

    def returns(th, reward):
        return rollout(task.stepper, policy, th, x0, noise, reward, sigma=0.2,
                       gradient=False).returns  # fmt: skip

    traj = rollout(task.stepper, policy, theta, x0, noise, task.reward, sigma=0.2)
    assert traj.used.all() and np.all(np.isfinite(traj.grad))
    if name == "ant":
        assert traj.impulse.max() > 0.1  # contact
        without = rollout(task.stepper, policy, theta, x0, noise, smooth, sigma=0.2)
        np.testing.assert_array_equal(without.grad, traj.grad)
        assert np.all(traj.returns < without.returns)  # the contact cost's value counts
    for _ in range(2):
        d = rng.standard_normal(theta.size)
        fd = central_difference(
            lambda s, d=d: returns(theta + s[0] * d, smooth), np.zeros(1), 1e-6
        )[:, 0]  # fmt: skip
        np.testing.assert_allclose(traj.grad @ d, fd, rtol=1e-6, atol=1e-6)


# --------------------------------------------------------------------------- the environment


@pytest.mark.filterwarnings("ignore:.*Box observation space m..imum value is:UserWarning")
@pytest.mark.parametrize("name", NAMES)
def test_gymnasium_check_env_passes(name, tasks):
    from gymnasium.utils.env_checker import check_env

    env = DrakeAbsEnv(tasks[name], max_episode_steps=5)
    check_env(env, skip_render_check=True)
    env.reset(seed=1)
    _, _, _, _, info = env.step(np.zeros(tasks[name].nu))
    want = {
        "walker2d": {"x_position", "z_distance_from_origin", "reward_survive"},
        "ant": {"y_position", "distance_from_origin", "y_velocity", "reward_contact"},
    }
    assert want[name] <= info.keys()


def test_ant_reward_pickles_and_refuses_bad_input(tasks, rng):
    reward = tasks["ant"].reward
    copy = pickle.loads(pickle.dumps(reward))  # as sent to Ray workers: the plant rebuilt
    x = tasks["ant"].initial_states(rng, 2)
    x[:, 6] = 0.58
    u = np.zeros((2, 8))
    step = tasks["ant"].stepper.step(x, u, jacobians=False)
    np.testing.assert_array_equal(copy.transition(x, u, step.x_next, step=step)[0],
                                  reward.transition(x, u, step.x_next, step=step)[0])  # fmt: skip
    with pytest.raises(ValueError, match="step must be given"):
        reward.transition(x, u, step.x_next)
    with pytest.raises(ValueError, match="u must have shape"):
        reward.terms(x, u[:, :3], step.x_next)
    with pytest.raises(ValueError, match="impulse must have shape"):
        reward.contact_wrenches(step.x_next, step.impulse[:, :2], None, 0.05)
