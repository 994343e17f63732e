"""MuJoCo as a stepper: the same numbers as gymnasium's environments and MuJoCo stepped by hand,
in the engine; Jacobians against central differences and chained over the frame skip; clear
errors for what finite differences cannot do."""

import pickle

import numpy as np
import pytest
from numdiff import central_difference

mujoco = pytest.importorskip("mujoco")
gymnasium = pytest.importorskip("gymnasium")

from drake_abs.engine import open_loop, rollout  # noqa: E402
from drake_abs.policy.policies import LinearPolicy  # noqa: E402
from drake_abs.policy.rewards import QuadraticReward  # noqa: E402
from drake_abs.reference.mujoco_plant import MujocoStepper, apply_options  # noqa: E402

ENVS = ("Hopper-v5", "HalfCheetah-v5")


@pytest.mark.parametrize("env_id", ENVS)
def test_engine_rollout_equals_gymnasium_env_steps(env_id):
    """Bit for bit, warm start included: one engine step is one ``env.step``."""
    env = gymnasium.make(env_id)
    raw = env.unwrapped
    env.reset(seed=3)
    x0 = np.concatenate([raw.data.qpos, raw.data.qvel])
    actions = np.random.default_rng(0).uniform(-1, 1, (80, raw.model.nu))
    expected = [x0]
    for a in actions:
        env.step(a)
        expected.append(np.concatenate([raw.data.qpos, raw.data.qvel]))
    stepper = MujocoStepper.from_gymnasium(env_id)
    assert stepper.frame_skip == raw.frame_skip and stepper.time_step == raw.dt
    traj = open_loop(stepper, x0, actions, jacobians=False)
    np.testing.assert_array_equal(traj.x[0], np.array(expected))
    assert traj.impulse.shape == (1, 80, raw.model.ngeom) and traj.impulse.sum() > 0


def test_a_batch_equals_each_row_stepped_alone():
    stepper = MujocoStepper.from_gymnasium("Hopper-v5")
    rng = np.random.default_rng(1)
    x0 = np.concatenate([stepper.model.qpos0, np.zeros(stepper.nv)]) + rng.normal(
        scale=0.05, size=(3, stepper.nx)
    )
    x0[:, 1] = 1.25
    actions = rng.uniform(-1, 1, (3, 30, stepper.nu))
    batch = open_loop(stepper, x0, actions, jacobians=False).x
    for b in range(3):
        alone = open_loop(MujocoStepper.from_gymnasium("Hopper-v5"), x0[b], actions[b],
                          jacobians=False)  # fmt: skip
        np.testing.assert_array_equal(batch[b], alone.x[0])


def test_mj_step_by_hand_with_frame_skip_and_options(tmp_path):
    """A model file, frame_skip 3 and Euler, against mj_step by hand on the same settings."""
    path = gymnasium.__file__.replace("__init__.py", "envs/mujoco/assets/half_cheetah.xml")
    stepper = MujocoStepper(path, frame_skip=3, options={"integrator": "Euler", "springs": False})
    model = mujoco.MjModel.from_xml_path(path)
    apply_options(model, {"integrator": "Euler", "springs": False})
    assert (model.jnt_stiffness == 0).all() and model.opt.integrator == 0
    data = mujoco.MjData(model)
    ctrl = np.random.default_rng(2).uniform(-1, 1, (40, model.nu))
    x0 = np.concatenate([model.qpos0, np.zeros(model.nv)])
    data.qpos[:] = model.qpos0
    xs = [x0]
    for c in ctrl:
        data.ctrl[:] = c
        mujoco.mj_step(model, data, nstep=3)
        xs.append(np.concatenate([data.qpos, data.qvel]))
    traj = open_loop(stepper, x0, ctrl, jacobians=False)
    np.testing.assert_array_equal(traj.x[0], np.array(xs))


@pytest.mark.parametrize("frame_skip", [1, 4])
def test_jacobians_match_central_differences_and_chain_over_the_frame_skip(frame_skip):
    options = {"integrator": "Euler"}
    stepper = MujocoStepper.from_gymnasium("Hopper-v5", frame_skip=frame_skip, options=options)
    rng = np.random.default_rng(3)
    x0 = np.concatenate([stepper.model.qpos0, np.zeros(stepper.nv)])
    traj = open_loop(stepper, x0, rng.uniform(-1, 1, (60 // frame_skip, 3)), jacobians=False)
    x, u = traj.x[0, -1], rng.uniform(-1, 1, 3)  # a foot on the ground by now
    probe = MujocoStepper.from_gymnasium("Hopper-v5", frame_skip=frame_skip, options=options)
    step = probe.step(x, u)
    assert step.impulse.sum() > 0

    def f(z):  # cold steps: a perturbed state never continues a row
        return probe.step(z[:12], z[12:], jacobians=False).x_next

    fd = central_difference(f, np.r_[x, u])
    scale = 1.0 + np.abs(fd).max()
    np.testing.assert_allclose(step.dx_dx, fd[:, :12], atol=1e-5 * scale)
    np.testing.assert_allclose(step.dx_du, fd[:, 12:], atol=1e-5 * scale)
    if frame_skip > 1:  # the chain rule: the product of the single steps' Jacobians
        one = MujocoStepper.from_gymnasium("Hopper-v5", frame_skip=1, options=options)
        Ax, Au, z = np.eye(12), np.zeros((12, 3)), x
        for _ in range(frame_skip):
            s = one.step(z, u)
            Ax, Au, z = s.dx_dx @ Ax, s.dx_dx @ Au + s.dx_du, s.x_next
        np.testing.assert_allclose(step.dx_dx, Ax, rtol=1e-9, atol=1e-9 * scale)
        np.testing.assert_allclose(step.dx_du, Au, rtol=1e-9, atol=1e-9 * scale)


def test_jacobians_leave_the_trajectory_unchanged():
    stepper = MujocoStepper.from_gymnasium("HalfCheetah-v5", options={"springs": False})
    x0 = np.concatenate([stepper.model.qpos0, np.zeros(stepper.nv)])
    ctrl = np.random.default_rng(4).uniform(-1, 1, (20, 6))
    with_jac = open_loop(stepper, x0, ctrl).x
    without = open_loop(MujocoStepper.from_gymnasium("HalfCheetah-v5", options={
        "springs": False}), x0, ctrl, jacobians=False).x  # fmt: skip
    np.testing.assert_array_equal(with_jac, without)


def test_closed_loop_gradient_in_mujoco_matches_central_differences():
    stepper = MujocoStepper.from_gymnasium("HalfCheetah-v5")
    nx, nu = stepper.nx, stepper.nu
    policy = LinearPolicy(nx=nx, nu=nu)
    reward = QuadraticReward(Q=np.eye(nx) * 0.1, R=np.eye(nu) * 0.01, x_goal=np.zeros(nx))
    theta = np.random.default_rng(5).normal(scale=0.05, size=policy.n_params)
    x0 = np.concatenate([stepper.model.qpos0, np.zeros(stepper.nv)])
    noise = np.zeros((1, 6, nu))
    traj = rollout(stepper, policy, theta, x0, noise, reward)

    def J(th):
        return rollout(stepper, policy, th, x0, noise, reward, gradient=False).returns[0]

    fd = central_difference(J, theta)
    np.testing.assert_allclose(traj.grad[0], fd, atol=1e-4 * (1 + np.abs(fd).max()))


def test_pickles_with_its_settings():
    euler = {"integrator": "Euler"}
    stepper = MujocoStepper.from_gymnasium("Hopper-v5", frame_skip=2, options=euler)
    copy = pickle.loads(pickle.dumps(stepper))
    x0 = np.concatenate([stepper.model.qpos0, np.zeros(stepper.nv)])
    np.testing.assert_array_equal(copy.step(x0, np.ones(3)).x_next,
                                  stepper.step(x0, np.ones(3)).x_next)  # fmt: skip
    assert copy.frame_skip == 2 and copy.model.opt.integrator == 0


def test_what_finite_differences_cannot_do_is_said():
    rk4 = MujocoStepper.from_gymnasium("Hopper-v5")  # hopper.xml integrates with RK4
    x0 = np.concatenate([rk4.model.qpos0, np.zeros(rk4.nv)])
    with pytest.raises(ValueError, match="RK4"):
        rk4.step(x0, np.zeros(3))
    rk4.step(x0, np.zeros(3), jacobians=False)  # the step itself works
    free = MujocoStepper(mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint name='base'/><geom size='.1'/></body></worldbody>"
        "</mujoco>"))  # fmt: skip
    assert free.nx == 13
    with pytest.raises(ValueError, match=r"free or ball joints \['base'\]"):
        free.step(np.r_[0, 0, 1, 1, 0, 0, 0, np.zeros(6)], np.zeros(0))


def test_bad_arguments_are_named(tmp_path):
    with pytest.raises(ValueError, match="no file"):
        MujocoStepper(tmp_path / "missing.xml")
    with pytest.raises(TypeError, match="model must be"):
        MujocoStepper(42)
    with pytest.raises(ValueError, match="frame_skip"):
        MujocoStepper.from_gymnasium("Hopper-v5", frame_skip=0)
    with pytest.raises(ValueError, match="unknown keys"):
        MujocoStepper.from_gymnasium("Hopper-v5", options={"integrater": "Euler"})
    with pytest.raises(ValueError, match="integrator"):
        MujocoStepper.from_gymnasium("Hopper-v5", options={"integrator": "rk45"})
    stepper = MujocoStepper.from_gymnasium("Hopper-v5")
    with pytest.raises(ValueError, match=r"x must have shape \(B, nx\) = \(B, 12\)"):
        stepper.step(np.zeros(11), np.zeros(3))
    with pytest.raises(ValueError, match="u must have shape"):
        stepper.step(np.zeros(12), np.zeros(4))
    with pytest.raises(ValueError, match="names no model parameters"):
        stepper.step(np.zeros(12), np.zeros(3), parameters=True)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_geom_impulses_are_mujocos_contact_forces(cone):
    """The step's geom impulses against mj_contactForce, contact by contact, for both cones."""
    stepper = MujocoStepper.from_gymnasium("HalfCheetah-v5", options={"cone": cone})
    model = stepper.model
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    ctrl = np.random.default_rng(6).uniform(-1, 1, (30, model.nu))
    force, total = np.zeros(6), 0.0
    for c in ctrl:
        x = stepper.state(data)
        data.ctrl[:] = c
        expected = np.zeros(model.ngeom)
        for _ in range(stepper.frame_skip):
            mujoco.mj_step(model, data)
            for i in range(data.ncon):
                mujoco.mj_contactForce(model, data, i, force)
                con = data.contact[i]
                expected[[con.geom1, con.geom2]] += force[0] * model.opt.timestep
        step = stepper.step(x, c, jacobians=False)
        np.testing.assert_array_equal(step.x_next, stepper.state(data))
        np.testing.assert_allclose(step.impulse, expected, rtol=1e-12, atol=1e-15)
        total += expected.sum()
    assert total > 0


def test_a_state_mujoco_resets_is_flagged_not_passed_off_as_physics():
    """MuJoCo silently resets a state whose velocity exceeds 1e10; the step must say it is not
    the model's (converged False, a warning), and the engine must not use such a rollout."""
    from drake_abs.reference.mujoco_plant import MujocoDivergenceWarning

    stepper = MujocoStepper.from_gymnasium("Hopper-v5")
    good = np.concatenate([stepper.model.qpos0, np.zeros(stepper.nv)])
    bad = good.copy()
    bad[7] = 1e11  # the root's vertical speed, m/s
    with pytest.warns(MujocoDivergenceWarning, match="1 of 2 states diverged"):
        step = stepper.step(np.stack([good, bad]), np.zeros((2, 3)), jacobians=False)
    np.testing.assert_array_equal(step.converged, [True, False])
    with pytest.warns(MujocoDivergenceWarning):
        traj = open_loop(stepper, np.stack([good, bad]), np.zeros((5, 3)), jacobians=False)
    np.testing.assert_array_equal(traj.used, [True, False])
