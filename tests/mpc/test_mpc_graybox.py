"""Closed-loop cost and gradients of the MPC policy (paper 003 eqs. 7-8), the zeroth-order
estimate (eq. 9), the gray-box update (eq. 10), and least-squares identification."""

import numpy as np
import pytest
from mpc_setup import (
    A_H,
    B_H,
    PRM,
    Q_D,
    R_D,
    THETA,
    U_MAX,
    U_MIN,
    U_REF,
    X_MAX,
    X_MIN,
    X_REF,
)
from numdiff import central_difference

from drake_abs.engine import LinearStepper
from drake_abs.mpc.graybox import (
    Schedule,
    TrackingCost,
    closed_loop,
    graybox_optimize,
    sample_unit_sphere,
    step_size,
    step_size_as_printed,
    zeroth_order_estimate,
)
from drake_abs.mpc.qp_mpc import MpcSpec, MpcStatus, QpMpc
from drake_abs.mpc.sysid import identify_linear_model
from drake_abs.tasks import quadcopter as qc

COST = TrackingCost(
    np.diag(Q_D), np.diag(R_D), np.diag(np.r_[np.ones(6), 1e3 * np.ones(3), np.ones(3)]),
    X_REF, U_REF, X_MIN, X_MAX, 300.0,
)  # fmt: skip


quad_plant = qc.QuadcopterStepper(PRM)


def paper_mpc(horizon=12, **settings) -> QpMpc:
    spec = MpcSpec(A_H, B_H, horizon, X_REF, U_REF, U_MIN, U_MAX, X_MIN, X_MAX)
    return QpMpc(spec, THETA, osqp_settings=settings)


def test_exact_closed_loop_gradient_matches_central_differences():
    """d total / d theta (eq. 8 with the plant's own Jacobians) over 12 steps from the origin,
    where input and state constraints are active and the penalty is nonzero (horizon N = 6 to
    keep the 188 finite-difference rollouts short)."""
    mpc = paper_mpc(horizon=6)
    steps = 12
    r = closed_loop(mpc, THETA, np.zeros(12), steps, quad_plant, COST, gradient="exact")
    assert r.violation > 0 and r.fallback_steps == 0
    assert np.all(r.status == MpcStatus.SOLVED)
    fd = central_difference(
        lambda t: closed_loop(mpc, t, np.zeros(12), steps, quad_plant, COST).total, THETA, 1e-6
    )
    np.testing.assert_allclose(r.gradient, fd, atol=2e-6 * np.abs(fd).max())
    assert r.total == pytest.approx(r.tracking_cost + 300.0 * r.violation)


def test_model_gradient_equals_exact_gradient_when_the_model_is_the_plant(rng):
    """With a linear plant equal to the prediction model, eq. 8a with (A, B) is exact."""
    A = A_H
    plant = LinearStepper(A, B_H)
    cost = TrackingCost(np.eye(12), 0.01 * np.eye(4), np.eye(12), np.zeros(12), np.zeros(4),
                        X_MIN, X_MAX)  # fmt: skip
    spec = MpcSpec(A, B_H, 8, None, None, U_MIN - U_REF, U_MAX - U_REF, X_MIN, X_MAX)
    mpc = QpMpc(spec, THETA)
    x0 = np.r_[1.0, -1.0, 0.5, 1.5, 0, 0, 0.3, 0, 0, 0, 0, 0]
    model = closed_loop(mpc, THETA, x0, 20, plant, cost, gradient="model")
    exact = closed_loop(mpc, THETA, x0, 20, plant, cost, gradient="exact")
    assert model.violation > 0
    np.testing.assert_allclose(model.gradient, exact.gradient, rtol=1e-12, atol=1e-12)
    for _ in range(3):  # and central differences along random directions
        v = sample_unit_sphere(rng, THETA.size)
        fd = central_difference(
            lambda h, v=v: np.array(
                [closed_loop(mpc, THETA + h[0] * v, x0, 20, plant, cost).total]
            ),
            np.zeros(1),
            1e-6,
        )[0, 0]
        assert model.gradient @ v == pytest.approx(
            fd, rel=1e-6, abs=1e-6 * np.abs(model.gradient).sum()
        )


def test_unsolved_qps_are_recorded_in_the_rollout_with_the_fallback_control():
    mpc = paper_mpc(max_iter=1)
    r = closed_loop(mpc, THETA, np.zeros(12), 5, quad_plant, COST, gradient="exact")
    assert r.fallback_steps == 5 and np.all(r.status != MpcStatus.SOLVED)
    np.testing.assert_array_equal(r.u, np.tile(U_REF, (5, 1)))  # hover, the fallback
    assert np.all(np.isfinite(r.x)) and np.all(np.isfinite(r.gradient))


def test_zeroth_order_estimate_is_unbiased_on_a_quadratic():
    """E[(n / delta) (f(theta + delta v) - f(theta)) v] = grad f exactly for a quadratic f."""
    rng = np.random.default_rng(7)
    n, samples, delta = 3, 200_000, 1e-2
    M = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, -0.2], [0.0, -0.2, 0.5]])
    b = np.array([0.5, -1.0, 2.0])
    theta = np.array([0.3, 0.1, -0.4])

    def f(t):
        return 0.5 * t @ M @ t + b @ t

    V = rng.standard_normal((samples, n))
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    values = np.array([0.5 * t @ M @ t + b @ t for t in theta + delta * V[:2000]])
    one = zeroth_order_estimate(f(theta), values[0], V[0], delta)
    np.testing.assert_allclose(one, (n / delta) * (values[0] - f(theta)) * V[0])
    pert = theta + delta * V
    fv = 0.5 * np.einsum("si,ij,sj->s", pert, M, pert) + pert @ b
    est = (n / delta) * (fv - f(theta))[:, None] * V
    grad = M @ theta + b
    stderr = est.std(axis=0) / np.sqrt(samples)
    assert np.all(np.abs(est.mean(axis=0) - grad) < 4 * stderr)


def test_sphere_samples_have_unit_norm_and_are_seeded():
    a = sample_unit_sphere(np.random.default_rng(3), 94)
    b = sample_unit_sphere(np.random.default_rng(3), 94)
    assert np.linalg.norm(a) == pytest.approx(1.0) and np.array_equal(a, b)


def test_step_sizes_and_schedules():
    assert step_size(1) == pytest.approx(5e-5 * 2.0 / 2**0.75)
    assert step_size(100) == pytest.approx(5e-5 * (np.log(100) + 2) / 101**0.75)
    assert step_size_as_printed(1) == pytest.approx(2.0 / 2**0.75)
    ks = np.arange(1, 100_000)
    alphas = 5e-5 * (np.log(ks) + 2) / (ks + 1) ** 0.75
    assert np.all(np.diff(alphas[5:]) < 0)  # vanishing
    assert Schedule(gamma=0.5).weight(3) == pytest.approx(0.5)
    assert Schedule(eta=0.0).weight(9) == 0.0 and Schedule(eta=1.0).label.startswith("model")
    with pytest.raises(ValueError, match="exactly one"):
        Schedule(gamma=0.5, eta=1.0)
    with pytest.raises(ValueError, match="eta"):
        Schedule(eta=1.5)
    with pytest.raises(ValueError, match="k"):
        step_size(0)


def _short_problem():
    mpc = paper_mpc()

    def evaluate(theta, with_gradient):
        evaluate.calls.append(with_gradient)
        return closed_loop(
            mpc, theta, np.zeros(12), 10, quad_plant, COST,
            gradient="model" if with_gradient else None,
        )  # fmt: skip

    evaluate.calls = []
    return evaluate


def test_graybox_is_reproducible_with_a_seed_and_differs_with_another():
    runs = []
    for seed in (0, 0, 1):
        res = graybox_optimize(
            _short_problem(), THETA, iterations=3, schedule=Schedule(gamma=0.5),
            rng=np.random.default_rng(seed),
        )  # fmt: skip
        runs.append(res)
    np.testing.assert_array_equal(runs[0].thetas, runs[1].thetas)
    assert [r.total for r in runs[0].trace] == [r.total for r in runs[1].trace]
    assert not np.array_equal(runs[0].theta, runs[2].theta)
    assert len(runs[0].trace) == 4 and runs[0].thetas.shape == (4, THETA.size)


def test_graybox_uses_only_the_estimates_its_weight_asks_for():
    model_only = _short_problem()
    graybox_optimize(model_only, THETA, iterations=2, schedule=Schedule(eta=1.0),
                     rng=np.random.default_rng(0))  # fmt: skip
    assert model_only.calls == [True, True, False]  # no perturbed rollouts
    zo_only = _short_problem()
    graybox_optimize(zo_only, THETA, iterations=2, schedule=Schedule(eta=0.0),
                     rng=np.random.default_rng(0))  # fmt: skip
    assert zo_only.calls == [False, False, False, False, False]  # no gradients


def test_graybox_step_is_the_projected_mixture(rng):
    """theta_2 = clip(theta_1 - alpha_1 (eta_1 J_model + (1 - eta_1) J_zo), -b, b)."""
    evaluate = _short_problem()
    bound = 5.0
    res = graybox_optimize(evaluate, THETA, iterations=1, schedule=Schedule(gamma=0.5),
                           rng=np.random.default_rng(4), bound=bound)  # fmt: skip
    theta1 = np.clip(THETA, -bound, bound)
    again = _short_problem()  # a fresh solver repeats the same solves in the same order
    r = again(theta1, True)
    v = sample_unit_sphere(np.random.default_rng(4), THETA.size)
    zo = zeroth_order_estimate(r.total, again(theta1 + 1e-4 * v, False).total, v, 1e-4)
    eta = 1 / 2**0.5
    want = np.clip(theta1 - step_size(1) * (eta * r.gradient + (1 - eta) * zo), -bound, bound)
    np.testing.assert_array_equal(res.thetas[1], want)
    assert np.all(np.abs(res.thetas) <= bound)


def test_identification_recovers_a_linear_system_exactly(rng):
    A = 0.9 * np.linalg.qr(rng.normal(size=(5, 5)))[0]
    B = rng.normal(size=(5, 2))
    x_ref, u_ref = rng.normal(size=5), rng.normal(size=2)
    x = rng.normal(size=(60, 5))
    u = rng.normal(size=(60, 2))
    x_next = x_ref + (x - x_ref) @ A.T + (u - u_ref) @ B.T
    m = identify_linear_model(x, u, x_next, x_ref, u_ref)
    np.testing.assert_allclose(m.A, A, atol=1e-12)
    np.testing.assert_allclose(m.B, B, atol=1e-12)
    assert m.rank == 7 and m.residual_rms.max() < 1e-12
    np.testing.assert_allclose(m.predict(x, u), x_next, atol=1e-12)
    c = identify_linear_model(x, u, x_next + 0.5, x_ref, u_ref, intercept=True)
    np.testing.assert_allclose(c.c, 0.5 * np.ones(5), atol=1e-12)


def test_identification_bad_input():
    with pytest.raises(ValueError, match="x_next"):
        identify_linear_model(np.zeros((20, 3)), np.zeros((20, 1)), np.zeros((19, 3)))
    with pytest.raises(ValueError, match="at least"):
        identify_linear_model(np.zeros((2, 3)), np.zeros((2, 1)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="u"):
        identify_linear_model(np.zeros((20, 3)), np.full((20, 1), np.nan), np.zeros((20, 3)))


def test_closed_loop_bad_input():
    mpc = paper_mpc()
    with pytest.raises(ValueError, match="x0"):
        closed_loop(mpc, THETA, np.zeros(3), 5, quad_plant, COST)
    with pytest.raises(ValueError, match="steps"):
        closed_loop(mpc, THETA, np.zeros(12), 0, quad_plant, COST)
    with pytest.raises(ValueError, match="gradient"):
        closed_loop(mpc, THETA, np.zeros(12), 5, quad_plant, COST, gradient="fd")
    with pytest.raises(ValueError, match="Q"):
        TrackingCost(np.eye(3), np.eye(4), np.eye(12), X_REF, U_REF, X_MIN, X_MAX)
