"""Bad input gets a ValueError naming the argument; failure is reported, never returned as NaN."""

import re
import warnings

import numpy as np
import pytest

from drake_abs import (
    LCS,
    ContactAware,
    Fixed,
    GaussianMatched,
    LCPConvergenceError,
    LCPConvergenceWarning,
    LCPRegularizationWarning,
    LCPStatus,
    LcsStepper,
    MatrixClass,
    open_loop,
    point_mass_lcs,
    solve_lcp,
)
from drake_abs.lcp import ipm

F2 = np.array([[2.0, 0.5], [0.5, 1.0]])
Q2 = np.array([-1.0, 0.5])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_inputs_name_the_argument(bad):
    F = F2.copy()
    F[0, 1] = bad
    with pytest.raises(ValueError, match=r"^F contains NaN or inf"):
        solve_lcp(F, Q2)
    q = Q2.copy()
    q[1] = bad
    with pytest.raises(ValueError, match=r"^q contains NaN or inf"):
        solve_lcp(F2, q)
    with pytest.raises(ValueError, match=r"^mu contains NaN or inf"):
        solve_lcp(F2, Q2, bad)


@pytest.mark.parametrize(
    "F, q, mu, message",
    [
        (np.eye(3), Q2, 0.0, r"F must have shape \(d, d\) = \(2, 2\)"),
        (F2, np.ones((2, 2, 2)), 0.0, r"q must be 1-D or 2-D"),
        (F2, np.ones((0,)), 0.0, r"q must have at least one contact"),
        (np.stack([F2] * 3), Q2, 0.0, r"F of shape \(3, 2, 2\) is a batch"),
        (np.stack([F2] * 3), np.ones((4, 2)), 0.0, r"F must have shape \(d, d\) or \(B, d, d\)"),
        (F2, Q2, np.ones(3), r"mu for a single problem must be a scalar or one per contact"),
        (F2, np.ones((4, 2)), np.ones(3), r"one per problem \(B,\) = \(4,\)"),
        (F2, np.ones((4, 2)), np.ones((4, 3)), r"one per contact \(B, d\) = \(4, 2\)"),
        (F2, Q2, -1e-3, r"mu must be >= 0"),
        (F2, "abc", 0.0, r"q must be a real numeric array"),
    ],
)
def test_wrong_shapes_and_values_say_what_is_expected(F, q, mu, message):
    with pytest.raises(ValueError, match=message):
        solve_lcp(F, q, mu)


def test_bad_options():
    with pytest.raises(ValueError, match="tol must be a positive finite number"):
        solve_lcp(F2, Q2, tol=0.0)
    with pytest.raises(ValueError, match="max_iterations must be an integer >= 1"):
        solve_lcp(F2, Q2, max_iterations=0)
    with pytest.raises(ValueError, match="max_iterations must be an integer >= 1"):
        solve_lcp(F2, Q2, max_iterations=2.5)
    for bad in (np.nan, 0.0, -1.0, 1.5):
        with pytest.raises(ValueError, match=r"exact_tol must be a finite number in \(0, 1\)"):
            solve_lcp(F2, Q2, exact_tol=bad)
    with pytest.raises(ValueError, match=r"warm_start\[0\] must have the shape of q, \(2,\)"):
        solve_lcp(F2, Q2, warm_start=(np.ones(3), np.ones(2)))
    with pytest.raises(ValueError, match=r"warm_start\[1\] must have the shape of q, \(3, 2\)"):
        solve_lcp(F2, np.ones((3, 2)), warm_start=(np.ones((3, 2)), np.ones((2, 3))))
    with pytest.raises(ValueError, match="on_bad_matrix must be"):
        solve_lcp(F2, Q2, on_bad_matrix="ignore")
    with pytest.raises(ValueError, match="warm_start .* strictly positive"):
        solve_lcp(F2, Q2, warm_start=(np.zeros(2), np.ones(2)))


NOT_P = np.array([[1.0, 2.0], [2.0, 1.0]])  # principal minor det = -3


def test_non_p_matrix_is_detected_and_raises_by_default():
    with pytest.raises(ValueError, match=r"F must be positive semidefinite or a P-matrix.*-1\.0"):
        solve_lcp(NOT_P, Q2)


def test_regularize_policy_warns_with_the_amount():
    with pytest.warns(LCPRegularizationWarning, match=r"delta up to 1\.0\d*e\+00"):
        r = solve_lcp(NOT_P, Q2, on_bad_matrix="regularize")
    assert r.regularization == pytest.approx(1.0, rel=1e-6)
    assert r.converged
    # the regularised problem is what was solved: s = (F + delta I) lam + q
    expected = (NOT_P + r.regularization * np.eye(2)) @ r.lam + Q2
    np.testing.assert_allclose(r.slack, expected, rtol=1e-10, atol=1e-12)


def test_attempt_policy_solves_and_reports_per_problem():
    r = solve_lcp(NOT_P, np.array([[1.0, 1.0], [-1.0, -1.0]]), 1e-6, on_bad_matrix="attempt")
    assert np.all(r.matrix_class == -1)
    assert np.all(np.isfinite(r.lam)) and np.all(r.converged == (r.residual <= r.tol))
    # both have solutions, although the Newton matrix is singular at the start point
    assert r.converged.all()
    np.testing.assert_allclose(r.lam[1], [1 / 3, 1 / 3], rtol=1e-4)


def test_matrix_classes():
    r = solve_lcp(F2, Q2)
    assert r.matrix_class == MatrixClass.PSD
    nonsym_p = np.array([[1.0, -3.0], [0.0, 1.0]])  # P-matrix (minors 1, 1, 1), not PSD
    assert solve_lcp(nonsym_p, Q2).matrix_class == MatrixClass.P_MATRIX


def test_iteration_limit_is_reported_not_hidden(monkeypatch):
    # the crossover would finish these problems by pivoting; here the limit itself is tested
    monkeypatch.setattr(ipm, "POLISH", False)
    with pytest.warns(LCPConvergenceWarning, match=r"did not converge: worst residual .* max_iter"):
        r = solve_lcp(F2, np.array([[-1.0, 0.5], [3.0, -2.0]]), 0.0, max_iterations=2)
    assert not r.converged.any()
    assert np.all(r.status == LCPStatus.MAX_ITERATIONS)
    assert np.all(r.residual > r.tol) and np.all(np.isfinite(r.lam))
    with pytest.raises(LCPConvergenceError, match="did not converge"):
        solve_lcp(F2, Q2, 0.0, max_iterations=2, strict=True)


def test_infeasible_lcp_is_flagged_without_nan():
    # F = 0 and q < 0: s = q < 0 is impossible, the LCP has no solution
    with pytest.warns(LCPConvergenceWarning):
        r = solve_lcp(np.zeros((1, 1)), np.array([-1.0]), 0.0, on_bad_matrix="attempt")
    assert not r.converged
    assert np.all(np.isfinite(r.lam)) and np.all(np.isfinite(r.slack))


def test_only_the_failing_problems_are_flagged():
    q = np.array([[1.0], [-1.0], [-2.0]])
    F = np.array([[[1.0]], [[0.0]], [[2.0]]])
    with pytest.warns(LCPConvergenceWarning, match="1 of 3"):
        r = solve_lcp(F, q, 0.0, on_bad_matrix="attempt")
    np.testing.assert_array_equal(r.converged, [True, False, True])


def test_inputs_are_not_mutated(rng):
    F = F2.copy()
    q = rng.normal(size=(5, 2))
    mu = np.full((5, 2), 1e-3)
    copies = [a.copy() for a in (F, q, mu)]
    solve_lcp(F, q, mu, jacobians=True)
    for a, b in zip((F, q, mu), copies, strict=True):
        np.testing.assert_array_equal(a, b)


def test_lcs_validation_names_the_matrix():
    lcs = point_mass_lcs(2)
    kwargs = {k: getattr(lcs, k) for k in "ABCcDEFd"}
    with pytest.raises(ValueError, match=re.escape("LCS.C must have shape (dx, d) = (4, 1)")):
        LCS(**{**kwargs, "C": np.ones((4, 2))})
    with pytest.raises(ValueError, match="LCS.F contains NaN"):
        LCS(**{**kwargs, "F": np.array([[np.nan]])})
    with pytest.raises(ValueError, match="F must be positive semidefinite"):
        LCS(**{**kwargs, "F": np.array([[-1.0]])})
    with pytest.raises(ValueError, match=r"x must have shape \(dx,\) or \(B, dx\) with dx = 4"):
        lcs.step(np.zeros(3), np.zeros(2))
    with pytest.raises(ValueError, match=r"u must have shape"):
        lcs.step(np.zeros((3, 4)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="gradient must be 'frozen' or 'total'"):
        lcs.step(np.zeros(4), np.zeros(2), gradient="full")
    with pytest.raises(ValueError, match=r"u must have shape \(du,\) or \(B, du\) = \(1, 2\)"):
        open_loop(LcsStepper(lcs), np.zeros(4), np.zeros((5, 3)))
    with pytest.raises(ValueError, match=r"u must have shape \(N, nu\) or \(B, N, nu\) with B = 2"):
        open_loop(LcsStepper(lcs), np.zeros((2, 4)), np.zeros((3, 5, 2)))
    with pytest.raises(ValueError, match="time_step must be a finite number > 0"):
        point_mass_lcs(2, time_step=0.0)
    with pytest.raises(ValueError, match=r"^x contains NaN or inf"):
        lcs.step(np.array([0.0, np.nan, 0.0, 0.0]), np.zeros(2))
    with pytest.raises(ValueError, match=r"^x0 contains NaN or inf"):
        open_loop(LcsStepper(lcs), np.array([0.0, np.inf, 0.0, 0.0]), np.zeros((3, 2)))
    with pytest.raises(ValueError, match=r"solver_options may set tol.*\['jacobians'\]"):
        LCS(**kwargs, solver_options={"jacobians": True})
    with pytest.raises(ValueError, match="tol must be a positive finite number"):
        LCS(**kwargs, solver_options={"tol": -1.0})

    class Negative(Fixed):
        def mu(self, z, F):
            return -super().mu(z, F)

    with pytest.raises(ValueError, match=r"smoothing .*Negative.*finite mu >= 0"):
        lcs.step(np.zeros(4), np.zeros(2), Negative(1e-3))


def test_lcs_does_not_freeze_the_callers_arrays():
    A = np.eye(4)
    lcs = point_mass_lcs(2)
    LCS(**{**{k: getattr(lcs, k) for k in "BCcDEFd"}, "A": A})
    assert A.flags.writeable
    A[0, 0] = 2.0  # the caller's array stays theirs


def test_policy_parameters_are_checked():
    with pytest.raises(ValueError, match="Fixed.value must be a finite number >= 0"):
        Fixed(-1.0)
    with pytest.raises(ValueError, match="ContactAware.length must be a finite number > 0"):
        ContactAware(mu_max=1.0, length=0.0)
    with pytest.raises(ValueError, match="needs mu_min <= mu_max"):
        ContactAware(mu_max=1.0, length=1.0, mu_min=2.0)
    with pytest.raises(ValueError, match="GaussianMatched.sigma must be a finite number > 0"):
        GaussianMatched(sigma=np.nan)
    with pytest.raises(ValueError, match=r"GaussianMatched needs every diagonal entry F_ii > 0"):
        GaussianMatched(sigma=0.1).mu(np.zeros((1, 2)), np.diag([1.0, 0.0]))


def test_gaussian_matched_mu_is_zero_where_kappa_or_slack_is_not_positive():
    # c2 = -1 makes both kappa and the matched slack negative near z = 0: mu must be 0, not > 0
    policy = GaussianMatched(sigma=0.1, c2=-1.0)
    z = np.array([[0.0], [0.05], [-0.05]])
    F = np.array([[1.0]])
    np.testing.assert_array_equal(policy.mu(z, F), 0.0)
    np.testing.assert_array_equal(policy.dmu_dz(z, F), 0.0)


def test_no_warning_when_everything_converges():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        solve_lcp(F2, np.array([[-1.0, 0.5], [2.0, 1.0]]), 1e-8, jacobians=True)


def test_same_input_same_numbers(rng):
    q = rng.normal(size=(50, 2))
    a = solve_lcp(F2, q, 1e-6, jacobians=True)
    b = solve_lcp(F2, q, 1e-6, jacobians=True)
    np.testing.assert_array_equal(a.lam, b.lam)
    np.testing.assert_array_equal(a.dlam_dq, b.dlam_dq)


def test_warm_start_from_a_solution_cuts_iterations(rng):
    q = rng.normal(size=(20, 2))
    cold = solve_lcp(F2, q, 1e-6)
    near = solve_lcp(F2, q + 1e-6, 1e-6, warm_start=(cold.lam, cold.slack))
    assert near.converged.all() and np.median(near.iterations) < np.median(cold.iterations)
