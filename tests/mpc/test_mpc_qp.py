"""The QP-MPC core (paper 003 eq. 4, docs/math.md section 9): theta parameterisation, KKT Jacobians
against central differences with active input, state and slack constraints, the weakly active
rule, LQR equivalence, OSQP's adjoint as an independent path, failure statuses and fallback,
bad input."""

import numpy as np
import osqp
import pytest
from mpc_setup import (
    A_H,
    B_H,
    K_LQR,
    P_DARE,
    Q_D,
    R_D,
    THETA,
    U_REF,
    X_REF,
)
from numdiff import central_difference

from drake_abs.engine import LinearStepper
from drake_abs.mpc.qp_mpc import (
    MpcSpec,
    MpcStatus,
    QpMpc,
    ThetaLayout,
    cost_matrices,
    theta_from_cost,
)
from drake_abs.tasks import quadcopter as qc


def paper_spec(**kw) -> MpcSpec:
    """The quadcopter MPC of paper 003 section 7 (model: the exact hover linearisation)."""
    x_min, x_max = qc.QuadcopterConstraints().state_bounds()
    u_min, u_max = qc.QuadcopterConstraints().input_bounds()
    return MpcSpec(A_H, B_H, 12, X_REF, U_REF, u_min, u_max, x_min, x_max, **kw)


def test_theta_layout_and_round_trip(rng):
    lay = ThetaLayout(12, 4)
    assert lay.size == 12 + 4 + 78
    Q, R, P = cost_matrices(THETA, 12, 4)
    np.testing.assert_allclose(Q, np.diag(Q_D), atol=1e-15)
    np.testing.assert_allclose(R, np.diag(R_D), atol=1e-15)
    np.testing.assert_allclose(P, P_DARE, rtol=1e-12, atol=1e-12)
    theta = rng.normal(size=lay.size)
    Q, R, P = cost_matrices(theta, 12, 4)
    L = lay.lower_factor(theta)
    assert np.allclose(L, np.tril(L)) and L[1, 0] == theta[lay.p][1]  # row-major tril order
    np.testing.assert_allclose(P, L @ L.T + 1e-6 * np.eye(12))
    np.testing.assert_allclose(np.diag(Q), theta[:12] ** 2 + 1e-6)


def test_jacobians_match_central_differences_with_active_constraints():
    """From the origin the target is 7 m away: rotor speeds at 630 rad/s, velocity, angle and rate
    bounds active, some slacks positive. du0/dx and du0/dtheta from the KKT adjoint match central
    differences of the polished OSQP solution."""
    mpc = QpMpc(paper_spec(), THETA)
    x = np.zeros(12)
    sol = mpc.solve(x, jacobians=True)
    assert sol.status == MpcStatus.SOLVED and sol.polished and not sol.fallback
    assert np.any(np.isclose(sol.u_plan, 630.0)), "an input bound should be active"
    assert sol.slack.max() > 1e-3, "a softened state constraint should be violated"
    assert sol.active > 50
    fx = central_difference(lambda z: mpc.solve(z).u0, x, 1e-5)
    ft = central_difference(lambda t: mpc.solve(x, t).u0, THETA, 1e-6)
    scale_x, scale_t = np.abs(fx).max(), np.abs(ft).max()
    assert scale_x > 10 and scale_t > 10
    np.testing.assert_allclose(sol.du0_dx, fx, atol=1e-7 * scale_x)
    np.testing.assert_allclose(sol.du0_dtheta, ft, atol=1e-7 * scale_t)


@pytest.mark.parametrize("offset", [0.3, 1.5])
def test_jacobians_match_central_differences_near_the_target(rng, offset):
    mpc = QpMpc(paper_spec(), THETA + 0.1 * rng.normal(size=THETA.size))
    x = X_REF + offset * rng.normal(size=12) * np.r_[np.ones(3), 0.3 * np.ones(9)]
    sol = mpc.solve(x, jacobians=True)
    assert sol.status == MpcStatus.SOLVED
    fx = central_difference(lambda z: mpc.solve(z).u0, x, 1e-5)
    ft = central_difference(lambda t: mpc.solve(x, t).u0, mpc.theta, 1e-6)
    np.testing.assert_allclose(sol.du0_dx, fx, atol=1e-7 * np.abs(fx).max())
    np.testing.assert_allclose(sol.du0_dtheta, ft, atol=1e-7 * np.abs(ft).max())


def test_unconstrained_mpc_with_riccati_terminal_cost_is_lqr(rng):
    """No constraints and P from the DARE: u0 = u_ref - K (x - x_ref) for every x and horizon,
    du0/dx = -K, and the closed loop's Jacobian is (A - B K)^T."""
    for horizon in (1, 5, 12):
        mpc = QpMpc(MpcSpec(A_H, B_H, horizon, X_REF, U_REF), THETA)
        for _ in range(3):
            x = X_REF + rng.normal(size=12)
            sol = mpc.solve(x, jacobians=True)
            np.testing.assert_allclose(sol.u0, U_REF - K_LQR @ (x - X_REF), rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(sol.du0_dx, -K_LQR, rtol=1e-8, atol=1e-9)
    # closed loop on the model itself: chain du0/dx through T steps
    plant = LinearStepper(A_H, B_H)
    mpc = QpMpc(MpcSpec(A_H, B_H, 12, np.zeros(12), np.zeros(4)), THETA)
    x = rng.normal(size=12)
    J = np.eye(12)
    for _ in range(20):
        sol = mpc.solve(x, jacobians=True)
        step = plant.step(x, sol.u0, jacobians=True)
        J = (step.dx_dx + step.dx_du @ sol.du0_dx) @ J
        x = step.x_next
    closed = np.linalg.matrix_power(A_H - B_H @ K_LQR, 20)
    np.testing.assert_allclose(J, closed, rtol=1e-7, atol=1e-9)


def test_weakly_active_constraint_is_released_deterministically():
    """An input bound placed exactly at the unconstrained optimum is active with a zero
    multiplier: the rule treats it as inactive (the released branch's Jacobian is -K), counts
    it, and picks the same branch on every solve, warm-started or not.

    Repeated solves are warm-started from the previous one, which changes OSQP's rho and the
    roundoff of the polished solution (the bound's residual is 0.0 cold and -3.3e-14 warm with
    osqp 1.1.3), so they are compared to a tolerance: the released branch's Jacobians are
    smooth functions of the active set, so equal active sets give equal Jacobians up to the
    KKT solve's roundoff (1e-10 relative is far below the 1e-8 LQR check and far above ulps).
    Bit-identical numbers are promised only for the same call sequence on a fresh controller
    (tested in tests/test_determinism.py)."""
    x = X_REF + np.r_[0.3, -0.2, 0.1, 0.05, 0, 0, 0.02, 0, 0, 0, 0, 0]
    free = QpMpc(MpcSpec(A_H, B_H, 12, X_REF, U_REF), THETA).solve(x)
    u_max = np.full(4, np.inf)
    u_max[0] = free.u0[0]
    mpc = QpMpc(MpcSpec(A_H, B_H, 12, X_REF, U_REF, u_max=u_max), THETA)
    first = mpc.solve(x, jacobians=True)
    assert first.weakly_active >= 1 and first.active == 0
    np.testing.assert_allclose(first.du0_dx, -K_LQR, rtol=1e-8, atol=1e-9)
    for _ in range(3):
        again = mpc.solve(x, jacobians=True)
        assert again.active == first.active and again.weakly_active == first.weakly_active
        np.testing.assert_allclose(again.du0_dx, first.du0_dx, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(again.du0_dtheta, first.du0_dtheta, rtol=1e-10, atol=1e-12)


def test_osqp_adjoint_is_an_independent_path_where_no_slack_is_positive(rng):
    """OSQP's own adjoint derivative (one call per input) agrees with the KKT adjoint near the
    target. (From far away, with positive slacks, OSQP 1.1.3's adjoint disagreed with central
    differences in our checks; the KKT path is the default.)"""
    mpc = QpMpc(paper_spec(), THETA)
    x = X_REF + np.r_[2.0, 2.0, 0.0, np.zeros(9)]
    kkt = mpc.solve(x, jacobians=True)
    adj = mpc.solve(x, jacobians=True, method="osqp_adjoint")
    assert kkt.active > 0 and kkt.slack.max() < 1e-9
    np.testing.assert_allclose(adj.du0_dx, kkt.du0_dx, atol=1e-5 * np.abs(kkt.du0_dx).max())
    np.testing.assert_allclose(
        adj.du0_dtheta, kkt.du0_dtheta, atol=1e-5 * np.abs(kkt.du0_dtheta).max()
    )


def test_infeasible_hard_constraints_give_status_and_fallback_never_nan():
    mpc = QpMpc(paper_spec(soft_state_constraints=False), THETA)
    x = X_REF.copy()
    x[3] = 5.0  # 5 m/s, and |v| <= 2 m/s is required from the next step on
    sol = mpc.solve(x, jacobians=True)
    assert sol.status == MpcStatus.PRIMAL_INFEASIBLE and sol.fallback
    np.testing.assert_array_equal(sol.u0, np.clip(U_REF, 0.0, 630.0))
    assert np.all(np.isfinite(sol.u0)) and np.isnan(sol.objective)
    assert not sol.du0_dx.any() and not sol.du0_dtheta.any()
    assert sol.u_plan is None
    ok = mpc.solve(X_REF + 0.01, jacobians=True)  # the next solve recovers
    assert ok.status == MpcStatus.SOLVED and not ok.fallback


def test_iteration_limit_gives_status_and_fallback():
    mpc = QpMpc(paper_spec(), THETA, osqp_settings={"max_iter": 1})
    sol = mpc.solve(np.zeros(12))
    assert sol.status == MpcStatus.MAX_ITER_REACHED
    assert sol.fallback and np.all(np.isfinite(sol.u0))
    assert mpc.retries == 1  # retried once from a cold start before falling back


class _ReportsInaccurate:
    """An OSQP whose every solve reports SOLVED_INACCURATE, unpolished (the solution is OSQP's)."""

    def __init__(self, inner):
        self.inner = inner

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def solve(self, raise_error=False):
        res = self.inner.solve(raise_error=raise_error)
        res.info.status_val = osqp.SolverStatus.OSQP_SOLVED_INACCURATE
        res.info.status_polish = 0
        return res


def test_inaccurate_solution_is_applied_with_its_status_and_jacobian():
    reference = QpMpc(paper_spec(), THETA).solve(np.zeros(12), jacobians=True)
    mpc = QpMpc(paper_spec(), THETA)
    mpc._osqp = _ReportsInaccurate(mpc._osqp)
    sol = mpc.solve(np.zeros(12), jacobians=True)
    assert sol.status == MpcStatus.SOLVED_INACCURATE and not sol.fallback
    assert mpc.retries == 1 and not sol.polished
    np.testing.assert_allclose(sol.u0, reference.u0, rtol=1e-9)
    np.testing.assert_allclose(sol.du0_dx, reference.du0_dx, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(sol.du0_dtheta, reference.du0_dtheta, rtol=1e-7, atol=1e-7)


def test_warm_start_cuts_iterations():
    mpc = QpMpc(paper_spec(), THETA)
    cold = mpc.solve(np.zeros(12))
    warm = mpc.solve(np.zeros(12))
    assert warm.iterations < cold.iterations
    np.testing.assert_allclose(warm.u0, cold.u0, rtol=1e-10)


def test_inputs_are_not_mutated():
    mpc = QpMpc(paper_spec(), THETA)
    x, theta = np.zeros(12), THETA.copy()
    mpc.solve(x, theta, jacobians=True)
    np.testing.assert_array_equal(x, np.zeros(12))
    np.testing.assert_array_equal(theta, THETA)


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda m: m.solve(np.r_[np.nan, np.zeros(11)]), "x"),
        (lambda m: m.solve(np.zeros(11)), "x"),
        (lambda m: m.solve(np.zeros(12), np.zeros(5)), "theta"),
        (lambda m: m.set_theta(np.full(THETA.size, np.inf)), "theta"),
        (lambda m: m.solve(np.zeros(12), method="forward"), "method"),
    ],
)
def test_bad_input_raises_naming_the_argument(call, name):
    mpc = QpMpc(paper_spec(), THETA)
    with pytest.raises(ValueError, match=name):
        call(mpc)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"A": np.eye(3)}, "A"),
        ({"horizon": 0}, "horizon"),
        ({"u_min": np.full(4, 700.0)}, "u_min"),
        ({"x_ref": np.zeros(3)}, "x_ref"),
        ({"slack_quadratic": 0.0}, "slack_quadratic"),
        ({"slack_linear": -1.0}, "slack_linear"),
    ],
)
def test_bad_spec_raises_naming_the_field(kwargs, name):
    base = {"A": A_H, "B": B_H, "horizon": 12, "x_ref": X_REF, "u_ref": U_REF}
    base["u_min"], base["u_max"] = qc.QuadcopterConstraints().input_bounds()
    with pytest.raises(ValueError, match=name):
        MpcSpec(**{**base, **kwargs})


def test_theta_from_cost_rejects_unreachable_matrices():
    with pytest.raises(ValueError, match="q_diag"):
        theta_from_cost(np.zeros(12), R_D, P_DARE)
    with pytest.raises(ValueError, match="P"):
        theta_from_cost(Q_D, R_D, -np.eye(12))
