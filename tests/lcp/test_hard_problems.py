"""Hard solvable LCPs are solved or flagged (issue 13; docs/math.md section 3b).

Csizmadia's P-matrices (exponential handicap: the interior point alone diverges from d = 32),
Murty's and Fathy's problems, non-symmetric P-matrices beyond the exact minor check (d > 10),
and unsolvable problems that must stay flagged (the families: drake_abs.lcp.problems, shared
with benchmarks/bench_lcp.py). Every answer the solver calls converged is verified here
independently of the solver's own residual.
"""

import warnings

import numpy as np
import pytest
from moby_reference import moby

from drake_abs import LCPConvergenceError, LCPConvergenceWarning, LCPStatus, MatrixClass, solve_lcp
from drake_abs.lcp import ipm
from drake_abs.lcp.problems import csizmadia, fathy, murty, scaled_p_matrices

#: Relative tolerance of the independent check (the solver's tol is 1e-12; the check recomputes
#: w = F lam + q in the unscaled variables, so it allows the roundoff of that product).
CHECK_TOL = 1e-10


def assert_valid(F, q, lam, tol=CHECK_TOL):
    """lam solves the LCP (F, q): lam >= 0, w = F lam + q >= 0 and min(lam_i F_ii, w_i) ~ 0,
    each relative to the size of row i's terms (double precision cannot do better when those
    terms are 2^63, as in Csizmadia's problem at d = 64)."""
    w = F @ lam + q
    row = np.abs(q) + np.abs(F) @ np.abs(lam)
    assert np.all(lam >= 0)
    assert np.all(w >= -tol * row), np.min(w / row)
    comp = np.minimum(lam * np.abs(np.diag(F)), np.abs(w))
    assert np.all(comp <= tol * row), np.max(comp / row)


@pytest.mark.parametrize("d", [20, 24, 32, 48, 64])
def test_csizmadia_p_matrices_converge_and_verify(d):
    F, q, x = csizmadia(d)
    r = solve_lcp(F, q, 0.0, jacobians=True)  # default policy: not refused
    assert r.matrix_class == MatrixClass.P_MATRIX
    assert r.converged and r.residual <= r.tol
    assert_valid(F, q, r.lam)
    np.testing.assert_allclose(r.lam, x, atol=1e-9)
    # the Jacobian at an exact solution is the active-set one: -F_AA^-1 on A, 0 elsewhere
    A = x > 0
    expected = np.zeros((d, d))
    expected[np.ix_(A, A)] = -np.linalg.inv(F[np.ix_(A, A)])
    np.testing.assert_allclose(r.dlam_dq, expected, atol=1e-9 * np.abs(expected).max())


def test_csizmadia_with_q_minus_one_has_exponentially_large_answers():
    # all contacts active, lam_i = 2^i: the answer spans 19 decades at d = 64
    d = 64
    F = 2.0 * np.eye(d) - np.tril(np.ones((d, d)))
    q = -np.ones(d)
    r = solve_lcp(F, q, 0.0)
    assert r.converged
    assert_valid(F, q, r.lam)
    np.testing.assert_allclose(r.lam, 2.0 ** np.arange(d), rtol=1e-12)


@pytest.mark.parametrize("d, policy", [(32, "attempt"), (48, "raise")])
def test_interior_point_alone_fails_on_csizmadia(monkeypatch, d, policy):
    """The problem this file is about: without the crossover, the interior point diverges and
    reports it honestly (residual above 1e20): at d = 32 as the old default mode had to treat
    it (not shown P, attempted), at d = 48 even as a recognised P-matrix. With the crossover
    both converge (tests above)."""
    monkeypatch.setattr(ipm, "POLISH", False)
    F, q, _ = csizmadia(d)
    with pytest.warns(LCPConvergenceWarning):
        r = solve_lcp(F, q, 0.0, on_bad_matrix=policy)
    assert not r.converged and r.residual > 1e20
    assert not r.polished and r.pivots == 0


@pytest.mark.parametrize("family", [murty, fathy])
@pytest.mark.parametrize("d", [16, 32, 64])
def test_murty_and_fathy_problems(family, d):
    F, q, x = family(d)
    r = solve_lcp(F, q, 0.0)
    assert r.converged
    assert_valid(F, q, r.lam)
    np.testing.assert_allclose(r.lam, x, atol=1e-9)


@pytest.mark.parametrize("d", [12, 24, 48])
def test_non_psd_p_matrix_beyond_the_exact_check_is_not_refused(d):
    rng = np.random.default_rng(1000 + d)
    F = scaled_p_matrices(rng, d, 1)[0]
    assert np.linalg.eigvalsh(F + F.T)[0] < 0  # not PSD: the old code refused it at d > 10
    q = rng.normal(size=(16, d))
    r = solve_lcp(F, q, 0.0)
    assert np.all(r.matrix_class == MatrixClass.UNVERIFIED)
    assert r.converged.all()
    for b in range(q.shape[0]):
        assert_valid(F, q[b], r.lam[b])


def test_permuted_csizmadia_is_recognised_as_a_p_matrix():
    F, q, x = csizmadia(40)
    perm = np.random.default_rng(7).permutation(40)
    r = solve_lcp(F[np.ix_(perm, perm)], q[perm], 0.0)
    assert r.matrix_class == MatrixClass.P_MATRIX and r.converged
    np.testing.assert_allclose(r.lam, x[perm], atol=1e-9)


def test_batch_keeps_easy_problems_and_polishes_only_the_failures():
    F, q, x = csizmadia(32)
    Q = np.stack([q, np.abs(q) + 1.0, -np.ones(32)])  # hard, trivially inactive, all active
    r = solve_lcp(F, Q, 0.0)
    assert r.converged.all()
    assert not r.polished[1]  # lam = 0 is found by the interior point
    for b in range(3):
        assert_valid(F, Q[b], r.lam[b])
    np.testing.assert_allclose(r.lam[0], x, atol=1e-9)


def test_smoothed_answers_stay_honest_when_the_crossover_cannot_finish_them():
    """At mu > 0 the exact solution is only a start for the centring steps: whatever is
    reported converged must satisfy the softened equations; the rest are flagged."""
    F, q, _ = csizmadia(64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LCPConvergenceWarning)
        r = solve_lcp(F, q, 1e-6)
    assert r.converged == (r.residual <= r.tol)
    if r.converged:
        np.testing.assert_allclose(r.lam * r.slack, 1e-6, rtol=1e-9)
        np.testing.assert_allclose(r.slack, F @ r.lam + q, atol=1e-9 * np.abs(F) @ r.lam)
    else:
        assert r.status != LCPStatus.CONVERGED and not r.polished


def test_unsolvable_lcps_are_flagged_never_converged():
    d = 16
    rng = np.random.default_rng(5)
    # infeasible: row 0 of F is zero and q_0 < 0, so w_0 = q_0 < 0 whatever lam is
    F = rng.normal(size=(d, d))
    F[0] = 0.0
    q = rng.normal(size=d)
    q[0] = -1.0
    with pytest.raises(ValueError, match="non-positive principal minor"):
        solve_lcp(F, q, 0.0)  # shown not P (F_00 = 0): refused by default
    with pytest.warns(LCPConvergenceWarning, match="did not converge"):
        r = solve_lcp(F, q, 0.0, on_bad_matrix="attempt")
    assert not r.converged and not r.polished and r.residual > r.tol
    with pytest.raises(LCPConvergenceError):
        solve_lcp(F, q, 0.0, on_bad_matrix="attempt", strict=True)
    # -I with q < 0: w = q - lam < 0 for every lam >= 0
    with pytest.warns(LCPConvergenceWarning):
        r = solve_lcp(-np.eye(d), -np.ones(d), 0.0, on_bad_matrix="attempt")
    assert not r.converged


@pytest.mark.parametrize("family", [csizmadia, murty, fathy])
def test_against_moby_where_its_answer_is_valid(family):
    F, q, _ = family(24)
    r = solve_lcp(F, q, 0.0)
    assert r.converged
    assert_valid(F, q, r.lam)
    valid, z = moby(F, q)
    if valid:  # a P-matrix LCP has one solution: a valid Moby answer must agree
        np.testing.assert_allclose(r.lam, z, atol=1e-8 * (1 + np.abs(z).max()))
