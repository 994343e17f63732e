"""The one closed-loop engine: protocols refused by name, the reverse pass against independent
paths (forward-mode accumulation, separate single-objective passes, central differences), the MPC
as a policy (one QP solve per step, gradient equal to paper 003's forward-mode eq. 8), and model
parameter gradients of whole rollouts against central differences of re-built scenes."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from mpc_setup import A_H, B_H, PRM, THETA, U_MAX, U_MIN, U_REF, X_MAX, X_MIN, X_REF
from scene_variants import with_friction, with_mass

from drake_abs import (
    ContactAware,
    Fixed,
    LcsStepper,
    LinearStepper,
    ModelJacobians,
    Step,
    open_loop,
    point_mass_lcs,
    reverse_pass,
    rollout,
)
from drake_abs.engine import PullbackPolicy
from drake_abs.mpc.graybox import TrackingCost, closed_loop
from drake_abs.mpc.policy import MpcPolicy
from drake_abs.mpc.qp_mpc import MpcSpec, QpMpc
from drake_abs.policy.policies import LinearPolicy, MLPPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.tasks import quadcopter as qc

NX, NU = 4, 2


def _ball(smoothing=None):
    smoothing = ContactAware(1e-2, 0.05) if smoothing is None else smoothing
    lcs = point_mass_lcs(2, time_step=0.02)
    reward = QuadraticReward(
        np.diag([0.0, 1.0, 0.0, 0.01]), 0.01 * np.eye(NU), np.array([1.0, 0.2, 0.0, 0.0]),
        Q_final=np.diag([10.0, 1.0, 0.0, 0.0]),
    )  # fmt: skip
    return LcsStepper(lcs, smoothing), reward, np.array([0.0, 0.3, 1.0, -1.0])


# --- protocols and bad input -------------------------------------------------------------------


def test_every_argument_is_checked_by_name():
    stepper, reward, x0 = _ball()
    policy = LinearPolicy(NX, NU)
    theta, noise = np.zeros(policy.n_params), np.zeros((2, 5, NU))
    with pytest.raises(TypeError, match="stepper must be a Stepper"):
        rollout(stepper.smoothing, policy, theta, x0, noise, reward)
    with pytest.raises(TypeError, match="policy must be a Policy"):
        rollout(stepper, object(), theta, x0, noise, reward)
    with pytest.raises(TypeError, match="reward must be a Reward"):
        rollout(stepper, policy, theta, x0, noise, object())
    with pytest.raises(ValueError, match="gradient=True needs a reward"):
        rollout(stepper, policy, theta, x0, noise)
    with pytest.raises(ValueError, match="parameters=True needs gradient=True"):
        rollout(stepper, policy, theta, x0, noise, reward, gradient=False, parameters=True)
    with pytest.raises(ValueError, match=r"^noise contains NaN"):
        rollout(stepper, policy, theta, x0, np.full((2, 5, NU), np.nan), reward)


def test_an_lcs_rollout_differentiates_its_matrices():
    """An LCS's matrices are its model parameters: the rollout's gradient with respect to the
    ground offset d[0] and the contact compliance F[0,0] against central differences of
    rollouts of re-built systems."""
    stepper, reward, x0 = _ball()
    policy = LinearPolicy(NX, NU)
    theta = 0.1 * np.random.default_rng(3).standard_normal(policy.n_params)
    noise = np.random.default_rng(4).standard_normal((2, 40, NU))
    traj = rollout(stepper, policy, theta, x0, noise, reward, sigma=0.1, parameters=True)
    names = stepper.parameter_names
    assert traj.model_parameter_names == names and traj.grad_model.shape == (2, len(names))
    values = stepper.lcs.parameter_values()
    for name in ("d[0]", "F[0,0]"):
        k = names.index(name)
        step = 1e-7 * max(1.0, abs(values[k]))
        e = np.zeros_like(values)
        e[k] = step
        plus = replace(stepper, lcs=stepper.lcs.with_parameters(values + e))
        minus = replace(stepper, lcs=stepper.lcs.with_parameters(values - e))
        fd = (
            rollout(plus, policy, theta, x0, noise, reward, sigma=0.1).returns
            - rollout(minus, policy, theta, x0, noise, reward, sigma=0.1).returns
        ) / (2 * step)
        assert np.abs(fd).max() > 1e-3  # the parameter matters along these rollouts
        np.testing.assert_allclose(traj.grad_model[:, k], fd, rtol=1e-5, atol=1e-6)


def test_without_a_reward_the_engine_only_simulates():
    stepper, _, x0 = _ball()
    policy = LinearPolicy(NX, NU)
    traj = rollout(stepper, policy, np.ones(policy.n_params), x0, np.zeros((3, 7, NU)),
                   gradient=False)  # fmt: skip
    assert traj.returns is None and traj.grad is None
    assert traj.x.shape == (3, 8, NX) and traj.impulse.shape == (3, 7, 1) and traj.used.all()


# --- the reverse pass --------------------------------------------------------------------------


def test_k_objectives_at_once_equal_k_separate_passes(rng):
    """reverse_pass with K = 2 cotangents (and a policy) equals two passes of one each."""
    stepper, reward, x0 = _ball()
    policy = MLPPolicy(NX, NU, (6,))
    theta = policy.init(rng, 0.5)
    traj = rollout(stepper, policy, theta, x0, rng.standard_normal((3, 15, NU)), reward, sigma=0.2)
    steps = [stepper.step(traj.x[:, t], traj.u[:, t]) for t in range(15)]
    Fx = np.stack([s.dx_dx for s in steps], 1)
    Fu = np.stack([s.dx_du for s in steps], 1)

    def vjps():
        return [lambda g, t=t: policy.vjp(theta, traj.x[:, t], g) for t in range(15)]

    seeds = rng.standard_normal((3, 2, NX))
    both = reverse_pass(Fx, Fu, seeds, policy_vjps=vjps(), n_policy_params=theta.size,
                        keep_inputs=True)  # fmt: skip
    for k in range(2):
        one = reverse_pass(Fx, Fu, seeds[:, k : k + 1], policy_vjps=vjps(),
                           n_policy_params=theta.size, keep_inputs=True)  # fmt: skip
        np.testing.assert_allclose(both.x0[:, k], one.x0[:, 0], rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(both.policy[:, k], one.policy[:, 0], rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(both.inputs[:, :, k], one.inputs[:, :, 0], rtol=1e-13)


def test_open_loop_jacobians_equal_the_closed_loop_input_gradient(rng):
    """The final state's Jacobian from open_loop, contracted with a terminal reward's gradient,
    is the closed-loop engine's d return / d x0 with a zero policy: two uses of one pass."""
    stepper, _, x0 = _ball(Fixed(1e-3))
    u = rng.standard_normal((25, NU))
    ol = open_loop(stepper, x0, u)
    goal = np.array([1.0, 0.2, 0.0, 0.0])
    reward = QuadraticReward(np.zeros((NX, NX)), np.zeros((NU, NU)), goal, np.eye(NX))
    policy = LinearPolicy(NX, NU)
    cl = rollout(stepper, policy, np.zeros(policy.n_params), x0, u[None], reward)
    dr_dxH = -2 * (ol.x[0, -1] - goal)
    np.testing.assert_allclose(cl.grad_x0[0], dr_dxH @ ol.dxH_dx0[0], rtol=1e-12)
    # and the policy's bias column is the sum over steps of dr/du_t
    np.testing.assert_allclose(
        cl.grad[0, -NU:], np.einsum("i,tij->j", dr_dxH, ol.dxH_du[0]), rtol=1e-12
    )


# --- the MPC as a policy -----------------------------------------------------------------------

COST = TrackingCost(np.eye(12), 0.01 * np.eye(4), np.eye(12), X_REF, U_REF, X_MIN, X_MAX, 300.0)


def _mpc():
    spec = MpcSpec(A_H, B_H, 10, X_REF, U_REF, U_MIN, U_MAX, X_MIN, X_MAX)
    return QpMpc(spec, THETA)


def test_mpc_policy_products_match_its_jacobians(rng):
    policy = MpcPolicy(_mpc())
    assert isinstance(policy, PullbackPolicy)
    x = X_REF + 0.3 * rng.standard_normal((3, 12))
    u, vjp = policy.pullback(THETA, x)
    du_dx, du_dth = policy.jacobians(THETA, x)
    g = rng.standard_normal((3, 4))
    gx, gth = vjp(g)
    np.testing.assert_allclose(u, policy.act(THETA, x), rtol=1e-12)
    np.testing.assert_allclose(gx, np.einsum("mi,mij->mj", g, du_dx), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(gth, np.einsum("mi,mij->mj", g, du_dth), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(policy.vjp(THETA, x, g)[1], gth, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("source", ["exact", "model"])
def test_mpc_closed_loop_gradient_equals_forward_mode_eq_8(source):
    """The engine's reverse pass against paper 003's forward accumulation (eq. 8a-8c), written
    out here independently; one QP solve per step (the reverse pass re-solves nothing)."""
    T = 15
    mpc = _mpc()
    plant = qc.QuadcopterStepper(PRM)
    x0 = X_REF + np.r_[1.0, -0.5, 0.3, np.zeros(9)]
    r = closed_loop(mpc, THETA, x0, T, plant, COST, gradient=source)
    assert mpc.solves - mpc.retries == T and r.fallback_steps == 0
    ref = QpMpc(mpc.spec, THETA)
    Jx, grad, x, w = np.zeros((12, THETA.size)), np.zeros(THETA.size), x0.copy(), 300.0
    for _ in range(T):
        sol = ref.solve(x, jacobians=True)
        _, gx, gu = COST.stage(x, sol.u0)
        gv = COST.violation(x)[1]
        Ju = sol.du0_dx @ Jx + sol.du0_dtheta
        grad += (gx + w * gv) @ Jx + gu @ Ju
        s = plant.step(x, sol.u0, jacobians=True)
        A, B = (s.dx_dx, s.dx_du) if source == "exact" else (A_H, B_H)
        Jx = A @ Jx + B @ Ju
        x = s.x_next
    grad += (COST.terminal(x)[1] + w * COST.violation(x)[1]) @ Jx
    np.testing.assert_allclose(r.x[-1], x, rtol=1e-12)
    np.testing.assert_allclose(r.gradient, grad, rtol=1e-9, atol=1e-9 * np.abs(grad).max())


def test_model_jacobians_keep_the_true_next_state():
    lin = LinearStepper(A_H, B_H)
    wrapped = ModelJacobians(qc.QuadcopterStepper(PRM), 2 * A_H, B_H)
    x, u = np.tile(X_REF + 0.1, (2, 1)), np.tile(U_REF + 5.0, (2, 1))
    s = wrapped.step(x, u)
    np.testing.assert_array_equal(s.x_next, qc.step(x, u, PRM).x_next)
    np.testing.assert_array_equal(s.dx_dx[1], 2 * A_H)
    assert lin.step(x, u).dx_du.shape == (2, 12, 4)


# --- model parameters: a whole rollout's gradient ----------------------------------------------

EPS = 1e-6


def test_model_parameter_gradient_of_a_rollout_matches_re_built_scenes(tmp_path):
    """dJ/d(ground height, friction, mass) of a pushed box's closed loop (8 steps, a linear
    feedback policy) against central differences of the same closed loop on re-built scenes:
    what learning contact parameters from rollouts needs of the engine."""
    from drake_abs.multibody import Scene, build_scene_model

    scene = Scene.load("box_push")
    model = build_scene_model(scene)
    stepper = model.stepper(smoothing=ContactAware(1e-3, 0.02))
    nx, nu = model.x0.size, model.contact_model.nu
    policy = LinearPolicy(nx, nu, x_ref=tuple(model.x0))
    theta = np.zeros(policy.n_params)
    theta[:nx] = [-2.0, 0.0, 0.0, -1.0, 0.0, 0.0]  # push against x and v_x
    theta[-1] = 3.0
    goal = model.x0 + np.r_[0.2, 0.0, 0.0, 0.0, 0.0, 0.0]
    reward = QuadraticReward(np.eye(nx), 0.01 * np.eye(nu), goal, 10 * np.eye(nx))
    noise = np.zeros((1, 8, nu))

    def J(s: Scene) -> float:
        st = build_scene_model(s).stepper(smoothing=ContactAware(1e-3, 0.02))
        traj = rollout(st, policy, theta, model.x0, noise, reward, gradient=False)
        assert traj.converged.all()
        return float(traj.returns[0])

    traj = rollout(stepper, policy, theta, model.x0, noise, reward, parameters=True)
    assert traj.converged.all()
    names = traj.model_parameter_names
    assert names == stepper.parameter_names
    g = traj.grad_model[0]
    scale = 1.0 + np.abs(g).max()
    h = scene.ground_height
    fd = (J(replace(scene, ground_height=h + EPS)) - J(replace(scene, ground_height=h - EPS))) / (
        2 * EPS
    )
    assert abs(fd) > 1e-4  # the push depends on where the ground is
    assert g[names.index("ground_height")] == pytest.approx(fd, abs=1e-5 * scale)
    friction = [i for i, n in enumerate(names) if n.startswith("friction")]
    fd = (J(with_friction(scene, 0, EPS)) - J(with_friction(scene, 0, -EPS))) / (2 * EPS)
    assert abs(fd) > 1e-4  # the box slides: friction matters
    assert g[friction].sum() == pytest.approx(fd, abs=1e-5 * scale)
    m = model.plant.GetBodyByName("box").default_mass()
    fd = (
        J(with_mass(scene, "box", 1 + EPS / m, tmp_path))
        - J(with_mass(scene, "box", 1 - EPS / m, tmp_path))
    ) / (2 * EPS)
    assert abs(fd) > 1e-4
    assert g[names.index("mass[box]")] == pytest.approx(fd, abs=1e-5 * scale)


# --- one step record ---------------------------------------------------------------------------


def test_every_stepper_returns_the_one_step_record():
    from drake_abs.multibody import build_scene_model

    box = build_scene_model("box_push")
    cases = [
        (LcsStepper(point_mass_lcs(2)), np.array([[0.0, 0.01, 0.0, -1.0]]), np.zeros((1, 2))),
        (box.stepper(), box.x0[None], np.full((1, box.contact_model.nu), 3.0)),
        (qc.QuadcopterStepper(PRM), X_REF[None], U_REF[None]),
        (LinearStepper(A_H, B_H), X_REF[None], U_REF[None]),
        (ModelJacobians(box.stepper(), np.eye(6), np.ones((6, 1))), box.x0[None], np.ones((1, 1))),
    ]
    for stepper, x, u in cases:
        s = stepper.step(x, u)
        assert isinstance(s, Step), type(stepper).__name__
        B, nx = x.shape
        nc = s.impulse.shape[1]
        assert s.x_next.shape == (B, nx) and s.converged.shape == (B,) and s.converged.all()
        assert s.dx_dx.shape == (B, nx, nx) and s.dx_du.shape == (B, nx, u.shape[1])
        assert s.mu.shape == (B, nc) and s.iterations.shape == (B,)


def test_an_overflowing_contact_free_step_is_flagged_not_valid():
    """A linear model that overflows: its non-finite steps are unconverged, and the rollout is
    dropped (NaN Jacobians), never returned as a valid result."""
    unstable = LinearStepper(1e200 * np.eye(2), np.ones((2, 1)))
    with np.errstate(all="ignore"), pytest.warns(UserWarning):
        traj = open_loop(unstable, np.ones(2), np.zeros((3, 1)))
    assert traj.converged[0, 0] and not traj.converged[0, 1:].any()
    assert not traj.used[0] and np.isnan(traj.dxH_dx0).all()
    with np.errstate(all="ignore"):  # the thrust overflows
        step = qc.QuadcopterStepper(PRM).step(np.zeros((2, 12)), np.full((2, 4), 1e160))
    assert not step.converged.any()


class _Sine:
    """A time-varying controller: u_t = sin(0.3 t), whatever the state."""

    time_varying = True
    nx, nu = 2, 1

    def act(self, theta, x, t):
        return np.full((x.shape[0], 1), np.sin(0.3 * t))


def test_a_time_varying_policy_runs_forward_and_equals_its_open_loop():
    from drake_abs.contact.lcs import LcsStepper
    from drake_abs.engine import open_loop, rollout
    from drake_abs.tasks.point_mass import point_mass_lcs

    stepper = LcsStepper(point_mass_lcs(1))
    x0 = np.array([0.5, 0.0])
    closed = rollout(stepper, _Sine(), np.zeros(0), x0, np.zeros((1, 12, 1)), gradient=False)
    inputs = np.sin(0.3 * np.arange(12))[:, None]
    np.testing.assert_array_equal(closed.x, open_loop(stepper, x0, inputs, jacobians=False).x)
    with pytest.raises(ValueError, match="time-varying"):
        from drake_abs.policy.rewards import QuadraticReward

        reward = QuadraticReward(Q=np.eye(2), R=np.eye(1), x_goal=np.zeros(2))
        rollout(stepper, _Sine(), np.zeros(0), x0, np.zeros((1, 12, 1)), reward)
