"""gymnasium's Hopper-v5 and HalfCheetah-v5 on our plant (drake_abs.tasks.locomotion, adapters,
gym_env).

Checked against gymnasium's own environments (same qpos / qvel set into MuJoCo): the observation
vector, the reward of one of our transitions (gymnasium's ``_get_rew`` on our states), the
Hopper's termination (``is_healthy``), the reset noise (same seed, same states), the gears and
control range. Derivatives (reward, observation, ObservationPolicy, ActionScaled) against central
differences; gymnasium's ``check_env`` on the environment; a batched rollout through the engine
against the environment stepped by hand, and its policy gradient against central differences.
"""

from __future__ import annotations

import pickle
import subprocess
import sys

import numpy as np
import pytest
from numdiff import central_difference

gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from drake_abs.engine import LinearStepper, rollout  # noqa: E402
from drake_abs.policy.policies import LinearPolicy, MLPPolicy  # noqa: E402
from drake_abs.tasks.adapters import ActionScaled, ObservationPolicy  # noqa: E402
from drake_abs.tasks.gym_env import DrakeAbsEnv, register_envs  # noqa: E402
from drake_abs.tasks.locomotion import (  # noqa: E402
    GymLocomotionReward,
    HealthyRanges,
    LocomotionObservation,
    locomotion_task,
)

NAMES = ("hopper", "half_cheetah")


@pytest.fixture(scope="module")
def tasks():
    return {name: locomotion_task(name) for name in NAMES}


@pytest.fixture(scope="module")
def gym_envs():
    envs = {name: gymnasium.make(t).unwrapped for name, t in
            (("hopper", "Hopper-v5"), ("half_cheetah", "HalfCheetah-v5"))}  # fmt: skip
    yield envs
    for env in envs.values():
        env.close()


def random_states(rng, task, M, *, velocity=3.0):
    """States near the initial one: q jittered, v of the given scale (Hopper: healthy pitch)."""
    x = np.tile(task.x0, (M, 1))
    x[:, : task.nq] += rng.uniform(-0.1, 0.1, (M, task.nq))
    x[:, task.nq :] += velocity * rng.standard_normal((M, task.nx - task.nq))
    return x


def set_mujoco(env, x):
    nq = env.model.nq
    env.set_state(x[:nq], x[nq:])


# ---------------------------------------------------------------------------- against gymnasium


@pytest.mark.parametrize("name", NAMES)
def test_observation_is_gymnasiums(name, tasks, gym_envs, rng):
    task, env = tasks[name], gym_envs[name]
    x = random_states(rng, task, 8, velocity=8.0)  # some hopper velocities beyond the clip
    assert task.n_obs == env.observation_space.shape[0] == (11 if name == "hopper" else 17)
    ours = task.observation(x)
    for m in range(len(x)):
        set_mujoco(env, x[m])
        np.testing.assert_array_equal(ours[m], env._get_obs())
    if name == "hopper":
        assert np.any(np.abs(x[:, task.nq :]) > 10)  # the clip was exercised


@pytest.mark.parametrize("name", NAMES)
def test_one_transitions_reward_is_gymnasiums_formula(name, tasks, gym_envs, rng):
    """Our stepper's transition, scored by gymnasium's own _get_rew at the state after it (its
    healthy test included), with the velocity over our time step."""
    task, env = tasks[name], gym_envs[name]
    x = task.x0[None] + 0.01 * rng.standard_normal((3, task.nx))
    a = rng.uniform(-1.5, 1.5, (3, task.nu))  # beyond the range too: the cost is on the action
    x_next = task.stepper.step(x, a, jacobians=False).x_next
    r, *_ = task.reward.transition(x, a, x_next)
    info = task.info(x, a, x_next)
    for m in range(3):
        set_mujoco(env, x_next[m])
        velocity = (x_next[m, 0] - x[m, 0]) / task.dt
        want, want_info = env._get_rew(velocity, a[m])
        assert r[m] == pytest.approx(want, rel=1e-12, abs=1e-12)
        assert -info["reward_ctrl"][m] == pytest.approx(env.control_cost(a[m]), rel=1e-12)
        for key, value in want_info.items():
            assert info[key][m] == pytest.approx(value, rel=1e-12, abs=1e-12), key
        assert info["x_velocity"][m] == pytest.approx(velocity, rel=1e-12)
    assert task.dt == env.dt  # gymnasium's control period: frame_skip * timestep


def test_hopper_termination_and_healthy_reward_are_gymnasiums(tasks, gym_envs, rng):
    task, env = tasks["hopper"], gym_envs["hopper"]
    x = random_states(rng, task, 40, velocity=30.0)
    x[:, 1] = rng.uniform(0.6, 0.8, 40)  # height around 0.7
    x[:, 2] = rng.uniform(-0.3, 0.3, 40)  # pitch around +-0.2
    edges = np.tile(task.x0, (6, 1))
    edges[0, 1] = 0.7  # open intervals: on the bound is unhealthy
    edges[1, 2] = 0.2
    edges[2, 2] = -0.2
    edges[3, 7] = 100.0  # a velocity at the state range's bound
    edges[4, 5] = -100.5
    x = np.concatenate([x, edges])
    ours = task.reward.terminated(x)
    survive = task.reward.terms(x[:1].repeat(len(x), 0), np.zeros((len(x), 3)), x)
    for m in range(len(x)):
        set_mujoco(env, x[m])
        assert ours[m] == (not env.is_healthy), m
        assert survive["reward_survive"][m] == env.healthy_reward
    assert 5 < ours.sum() < len(x) - 5  # both outcomes occur
    assert ours[-6:-1].all() and not ours[-1]


def test_half_cheetah_never_terminates(tasks, rng):
    x = random_states(rng, tasks["half_cheetah"], 5, velocity=200.0)
    assert not tasks["half_cheetah"].reward.terminated(x).any()


@pytest.mark.parametrize("name", NAMES)
def test_reset_draws_gymnasiums_noise(name, tasks, rng):
    """Same seed, same initial states: the first reset and the next one."""
    task = tasks[name]
    theirs = gymnasium.make({"hopper": "Hopper-v5", "half_cheetah": "HalfCheetah-v5"}[name])
    ours = DrakeAbsEnv(task)
    for seed in (0, 7):
        o1, info1 = ours.reset(seed=seed)
        o2, info2 = theirs.reset(seed=seed)
        np.testing.assert_allclose(o1, o2, rtol=0, atol=1e-15)
        assert info1.keys() == info2.keys()
        np.testing.assert_allclose(ours.reset()[0], theirs.reset()[0], rtol=0, atol=1e-15)
    first_two = task.initial_states(np.random.default_rng(3), 2)
    ours.reset(seed=3)
    np.testing.assert_array_equal(ours.state, first_two[0])
    ours.reset()
    np.testing.assert_array_equal(ours.state, first_two[1])
    theirs.close()


@pytest.mark.parametrize("name", NAMES)
def test_gears_and_control_range_are_mujocos(name, tasks, gym_envs):
    task, env = tasks[name], gym_envs[name]
    np.testing.assert_array_equal(task.stepper.scale, env.model.actuator_gear[:, 0])
    np.testing.assert_array_equal(env.model.actuator_ctrlrange, np.tile([-1.0, 1.0], (task.nu, 1)))
    # the scene's stepper clips torque at gear * 1: gymnasium's ctrl clip to [-1, 1]
    np.testing.assert_array_equal(task.plant.effort, task.stepper.scale)
    env_space = DrakeAbsEnv(task).action_space
    assert env_space == env.action_space


# ---------------------------------------------------------------------------- derivatives


@pytest.mark.parametrize("name", NAMES)
def test_reward_derivatives_match_central_differences(name, tasks, rng):
    task = tasks[name]
    reward = task.reward
    x, x_next = random_states(rng, task, 4), random_states(rng, task, 4)
    x_next[:, 1:3] = task.x0[1:3]  # healthy (Hopper), away from every bound
    u = rng.uniform(-1.2, 1.2, (4, task.nu))
    r, dr_dx, dr_du, dr_dxn = reward.transition(x, u, x_next)
    for m in range(4):
        xm, um, xnm = x[m : m + 1], u[m : m + 1], x_next[m : m + 1]
        f = [
            lambda z, um=um, xnm=xnm: reward.transition(z[None], um, xnm)[0],
            lambda z, xm=xm, xnm=xnm: reward.transition(xm, z[None], xnm)[0],
            lambda z, xm=xm, um=um: reward.transition(xm, um, z[None])[0],
        ]
        for g, at, want in zip(f, (x[m], u[m], x_next[m]), (dr_dx, dr_du, dr_dxn), strict=True):
            np.testing.assert_allclose(want[m], central_difference(g, at)[0], rtol=1e-7, atol=1e-7)
    assert np.all(dr_dx[:, 0] == -1.0 / task.dt)
    zero_r, zero_dr = reward.terminal(x)
    assert not zero_r.any() and not zero_dr.any()


def test_observation_jacobian_and_vjp_match_central_differences(tasks, rng):
    obs = tasks["hopper"].observation
    x = random_states(rng, tasks["hopper"], 3, velocity=8.0)
    x[:, 6:] += np.where(np.abs(np.abs(x[:, 6:]) - 10) < 0.01, 0.05, 0.0)  # off the kink
    J = obs.jacobian(x)
    g = rng.standard_normal((3, obs.n_obs))
    for m in range(3):
        fd = central_difference(lambda z: obs(z[None])[0], x[m])
        np.testing.assert_allclose(J[m], fd, atol=1e-9)
        np.testing.assert_allclose(obs.vjp(x, g)[m], g[m] @ fd, atol=1e-9)
    assert np.any(J[:, 5:, 6:].sum(axis=(1, 2)) < 6)  # some rows clipped to zero


@pytest.mark.parametrize("inner_kind", ["mlp", "linear"])
def test_observation_policy_derivatives_match_central_differences(inner_kind, tasks, rng):
    task = tasks["hopper"]
    inner = (MLPPolicy(task.n_obs, task.nu, (5,)) if inner_kind == "mlp"
             else LinearPolicy(task.n_obs, task.nu))  # fmt: skip
    policy = task.policy(inner)
    assert (policy.nx, policy.nu, policy.n_params) == (task.nx, task.nu, inner.n_params)
    theta = rng.standard_normal(policy.n_params) * 0.5
    x = random_states(rng, task, 3, velocity=8.0)
    x[:, 6:] += np.where(np.abs(np.abs(x[:, 6:]) - 10) < 0.01, 0.05, 0.0)
    du_dx, du_dth = policy.jacobians(theta, x)
    g_u = rng.standard_normal((3, task.nu))
    g_x, g_th = policy.vjp(theta, x, g_u)
    for m in range(3):
        fx = central_difference(lambda z: policy.act(theta, z[None])[0], x[m])
        fth = central_difference(lambda th, xm=x[m : m + 1]: policy.act(th, xm)[0], theta)
        np.testing.assert_allclose(du_dx[m], fx, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(du_dth[m], fth, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(g_x[m], g_u[m] @ fx, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(g_th[m], g_u[m] @ fth, rtol=1e-6, atol=1e-8)


def test_action_scaled_linear_stepper_and_bad_input(rng):
    A, B = rng.standard_normal((4, 4)), rng.standard_normal((4, 2))
    scaled = ActionScaled(LinearStepper(A, B), [3.0, -0.5])
    x, a = rng.standard_normal((2, 4)), rng.standard_normal((2, 2))
    s = scaled.step(x, a)
    np.testing.assert_allclose(s.x_next, x @ A.T + (a * [3.0, -0.5]) @ B.T)
    fd = central_difference(lambda w: scaled.step(x[:1], w[None], jacobians=False).x_next[0], a[0])
    np.testing.assert_allclose(s.dx_du[0], fd, atol=1e-8)
    copy = pickle.loads(pickle.dumps(scaled))
    np.testing.assert_array_equal(copy.step(x, a).x_next, s.x_next)
    with pytest.raises(ValueError, match="scale"):
        ActionScaled(LinearStepper(A, B), [1.0, 0.0])
    with pytest.raises(ValueError, match="u must have nu = 2"):
        scaled.step(x, rng.standard_normal((2, 3)))
    with pytest.raises(TypeError, match="stepper"):
        ActionScaled(object(), 1.0)


def test_action_scaled_scene_stepper_jacobian_clip_and_pickle(tasks, rng):
    """On the Hopper in contact: dx/da = dx/dtau gear against central differences; an action
    beyond 1 is the action 1 (torque clipped at the effort limit) with a zero column."""
    task = tasks["hopper"]
    x = task.x0.copy()
    x[1] -= 0.04  # the foot on the ground
    a = np.array([0.3, -0.4, 1.6])
    s = task.stepper.step(x[None], a[None])
    assert s.converged.all() and s.impulse.sum() > 0
    fd = central_difference(
        lambda w: task.stepper.step(x[None], w[None], jacobians=False).x_next[0], a, 1e-6
    )
    np.testing.assert_allclose(s.dx_du[0, :, :2], fd[:, :2], rtol=1e-5, atol=1e-7)
    assert not s.dx_du[0, :, 2].any() and fd[:, 2] == pytest.approx(0.0)
    inner = task.stepper.stepper.step(x[None], (a * task.stepper.scale)[None])
    np.testing.assert_array_equal(s.x_next, inner.x_next)
    np.testing.assert_allclose(s.dx_du, inner.dx_du * task.stepper.scale)
    one = task.stepper.step(x[None], np.array([[0.3, -0.4, 1.0]]), jacobians=False)
    np.testing.assert_allclose(s.x_next, one.x_next, rtol=0, atol=1e-12)
    copy = pickle.loads(pickle.dumps(task.stepper))  # rebuilt from the scene (Ray workers)
    np.testing.assert_allclose(copy.step(x[None], a[None]).x_next, s.x_next, atol=1e-12)


# ---------------------------------------------------------------------------- the environment


@pytest.mark.filterwarnings("ignore:.*Box observation space m..imum value is:UserWarning")
@pytest.mark.parametrize("name", NAMES)
def test_gymnasium_check_env_passes(name, tasks):
    """(gymnasium's own Hopper-v5 draws the same warnings about its unbounded observations.)"""
    from gymnasium.utils.env_checker import check_env

    check_env(DrakeAbsEnv(tasks[name], max_episode_steps=20), skip_render_check=True)


def test_registered_env_runs_under_gymnasium_make():
    register_envs()
    env = gymnasium.make("drake_abs/HalfCheetah-v0")
    assert env.spec.max_episode_steps == 1000
    obs, _ = env.reset(seed=1)
    obs, r, terminated, truncated, info = env.step(env.action_space.sample())
    assert obs.shape == (17,) and np.isfinite(r) and not (terminated or truncated)
    assert info["converged"] and set(info) >= {"x_velocity", "reward_forward", "reward_ctrl"}
    env.close()


def test_env_bad_input(tasks):
    env = DrakeAbsEnv(tasks["hopper"], max_episode_steps=2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action must have shape"):
        env.step(np.zeros(4))
    with pytest.raises(ValueError, match="render_mode"):
        DrakeAbsEnv(tasks["hopper"], render_mode="human")
    with pytest.raises(ValueError, match="max_episode_steps"):
        DrakeAbsEnv(tasks["hopper"], max_episode_steps=0)
    with pytest.raises(ValueError, match="name must be one of"):
        locomotion_task("humanoid")
    assert [env.step(np.zeros(3))[3] for _ in range(2)] == [False, True]  # truncated at 2


def test_rewards_bad_input():
    with pytest.raises(ValueError, match="dt"):
        GymLocomotionReward.hopper(0.0)
    with pytest.raises(ValueError, match="need healthy"):
        GymLocomotionReward(9, 9, 6, 0.01, healthy_reward=1.0)
    with pytest.raises(ValueError, match="angle"):
        HealthyRanges(angle=(0.2, -0.2))
    reward = GymLocomotionReward.half_cheetah(0.01)
    with pytest.raises(ValueError, match=r"u must have shape \(M, nu\)"):
        reward.transition(np.zeros((1, 18)), np.zeros((1, 3)), np.zeros((1, 18)))
    with pytest.raises(ValueError, match="inner must take the observation"):
        ObservationPolicy(LinearPolicy(18, 6), LocomotionObservation(9, 9))


def test_task_modules_import_without_drake():
    code = (
        "import sys, drake_abs.tasks.locomotion, drake_abs.tasks.adapters, "
        "drake_abs.tasks.gym_env; "
        "bad = [m for m in sys.modules if m.startswith(('pydrake', 'pinocchio'))]; "
        "assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


# ---------------------------------------------------------------------------- batched rollouts


def test_engine_rollout_is_the_environment_stepped_by_hand(rng):
    """A deterministic closed loop: the engine's return, end of episode and states equal the
    environment's (a strict height bound ends the Hopper's episode as it lands)."""
    task = locomotion_task("hopper", reward_options={"healthy": HealthyRanges(z=(1.235, np.inf))})
    inner = MLPPolicy(task.n_obs, task.nu, (8,))
    theta = inner.init(rng, 0.3)
    H = 20
    traj = rollout(task.stepper, task.policy(inner), theta, task.x0, np.zeros((2, H, task.nu)),
                   task.reward, sigma=0.0)  # fmt: skip
    env = DrakeAbsEnv(task)
    env.reset(seed=0)
    env.set_state(task.x0[:6], task.x0[6:])
    obs, total, steps = task.observation(env.state[None])[0], 0.0, 0
    for _ in range(H):
        obs, r, terminated, _, _ = env.step(inner.act(theta, obs[None])[0])
        total, steps = total + r, steps + 1
        np.testing.assert_allclose(env.state, traj.x[0, steps], rtol=0, atol=1e-12)
        if terminated:
            break
    assert terminated and 1 < steps < H  # the episode ended inside the horizon
    np.testing.assert_array_equal(traj.alive.sum(axis=1), [steps, steps])
    np.testing.assert_allclose(traj.returns, total, rtol=1e-12)
    assert np.all(np.isfinite(traj.grad)) and np.abs(traj.grad).max() > 0


def test_objective_rollout_gradient_matches_central_differences(tasks, rng):
    """The Hopper's first steps (in the air): FOPG's per-rollout gradient of the transition
    reward, through ObservationPolicy and ActionScaled, against central differences."""
    task = tasks["hopper"]
    inner = MLPPolicy(task.n_obs, task.nu, (6,))
    objective = task.objective(inner, horizon=6, sigma=0.3)
    theta = inner.init(rng, 0.5)
    noise = objective.noise(rng, 3)
    traj = objective.rollout(theta, noise)
    assert np.all(np.isfinite(traj.returns)) and traj.alive.all() and traj.used.all()
    d = rng.standard_normal(theta.size)
    fd = central_difference(
        lambda s: objective.rollout(theta + s[0] * d, noise, gradient=False).returns,
        np.zeros(1), 1e-6,
    )[:, 0]  # fmt: skip
    np.testing.assert_allclose(traj.grad @ d, fd, rtol=1e-5, atol=1e-6)
    copy = pickle.loads(pickle.dumps(objective))  # as sent to Ray workers
    np.testing.assert_allclose(copy.rollout(theta, noise).grad, traj.grad, rtol=1e-12)
    states = task.initial_states(rng, 3)  # gymnasium's noisy starts, one per rollout
    noisy = rollout(task.stepper, objective.policy, theta, states, noise, task.reward, sigma=0.3)
    assert np.all(np.isfinite(noisy.returns)) and np.all(np.isfinite(noisy.grad))


def test_smooth_survive_term_is_a_differentiable_stand_in_for_the_indicator(rng):
    from drake_abs.tasks.locomotion import SmoothHealthy

    smooth = SmoothHealthy(z_width=0.05, angle_width=0.02)
    x = np.zeros((4, 12))
    x[:, 1] = [1.25, 0.7, 1.25, 0.9]  # deep inside, on the height bound, ...
    x[:, 2] = [0.0, 0.0, 0.2, 0.1]  # ..., on the pitch bound, near it
    s, ds = smooth.value_and_gradient(x)
    assert s[0] > 0.99 and s[1] == pytest.approx(0.5, abs=1e-3) and s[2] == pytest.approx(0.5, 1e-3)
    assert 0.5 < s[3] < s[0]
    for m in range(4):
        fd = central_difference(lambda z: smooth.value_and_gradient(z[None])[0], x[m], 1e-7)
        np.testing.assert_allclose(ds[m], fd[0], rtol=1e-6, atol=1e-9)
    assert (ds[:, 3:] == 0).all()  # only the height and the pitch
    wide = SmoothHealthy(z_width=0.2, angle_width=0.2).value_and_gradient(x[3:])[0]
    assert wide[0] < s[3]  # a wider (smoother) term is felt farther inside the ranges
    with pytest.raises(ValueError, match="z_width must be a finite number > 0"):
        SmoothHealthy(z_width=0.0)


def test_smooth_survive_reward_has_its_gradient_and_keeps_gymnasiums_termination(rng):
    from drake_abs.tasks.locomotion import SmoothHealthy

    smooth = GymLocomotionReward.hopper(0.008, smooth_survive=SmoothHealthy())
    plain = GymLocomotionReward.hopper(0.008)
    x = np.tile(np.r_[0.0, 1.25, 0.0, np.zeros(9)], (3, 1)) + 0.01 * rng.standard_normal((3, 12))
    xn = x.copy()
    xn[:, 1] = [1.25, 0.71, 0.69]
    xn[:, 2] = [0.19, 0.0, 0.0]
    u = rng.standard_normal((3, 3))
    r, dx, du, dxn = smooth.transition(x, u, xn)
    for m in range(3):
        xm, um = x[m : m + 1], u[m : m + 1]
        fd = central_difference(lambda z, xm=xm, um=um: smooth.transition(xm, um, z[None])[0],
                                xn[m], 1e-7)  # fmt: skip
        np.testing.assert_allclose(dxn[m], fd[0], rtol=1e-6, atol=1e-8)
    np.testing.assert_array_equal(smooth.terminated(xn), plain.terminated(xn))
    assert smooth.terminated(xn).tolist() == [False, False, True]
    assert (r < plain.transition(x, u, xn)[0])[:2].all()  # near a bound: less than the full bonus
    with pytest.raises(ValueError, match="smooth_survive needs healthy"):
        GymLocomotionReward.half_cheetah(0.05, smooth_survive=SmoothHealthy())


@pytest.mark.parametrize(
    "options, says",
    [
        ({"control_period": float("nan")}, "control_period must be a finite number > 0"),
        ({"control_period": -0.01}, "control_period must be a finite number > 0"),
        ({"control_period": "fast"}, "control_period must be a finite number > 0"),
        ({"substeps": 0}, "substeps"),
        ({"substeps": 1.5}, "substeps"),
        ({"contact": "soft"}, r"contact must be one of \['hard', 'mujoco'\]"),
    ],
)
def test_bad_control_periods_and_substeps_are_named(options, says):
    with pytest.raises(ValueError, match=says):
        locomotion_task("hopper", **options)


def test_substeps_split_the_control_period():
    task = locomotion_task("half_cheetah", substeps=2)
    assert task.dt == pytest.approx(0.05) and task.substeps == 2
    assert task.plant.model.h == pytest.approx(0.025)


@pytest.mark.parametrize("name", ["hopper", "ant"])
def test_mujocos_soft_contact_is_a_task_option(name):
    """contact="mujoco": the scene's soft-contact option (the file's solref and solimp; the Ant
    without a second margin, its radii hold it). A body resting on it sinks into the ground, as
    in MuJoCo, where the hard plant keeps it on the surface."""
    from drake_abs.multibody.stepper import SOFT_PENETRATION_TOL

    hard, soft = locomotion_task(name), locomotion_task(name, contact="mujoco")
    assert hard.plant.compliance is None and soft.plant.compliance is not None
    assert soft.plant.penetration_tolerance == SOFT_PENETRATION_TOL
    if name == "ant":
        assert np.all(soft.plant.compliance.margin == 0.0)
    x = x_hard = soft.x0[None]
    for _ in range(60):  # 0.5 s (Hopper) to 3 s (Ant) of zero action: fallen or settled
        x_hard = hard.stepper.step(x_hard, np.zeros((1, hard.nu))).x_next
        x = soft.stepper.step(x, np.zeros((1, soft.nu))).x_next
    assert soft.plant.penetration(x)[0] > 1e-4  # soft: resting inside the ground
    assert hard.plant.penetration(x_hard)[0] < 1e-6  # hard: on it
