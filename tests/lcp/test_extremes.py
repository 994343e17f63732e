"""Extremes (docs/math.md section 3; issue 2 section 5): mu from 1e-14 to 1e3, F condition
numbers up to 1e10, |q| up to 1e8, batches from 1 to 1e5, many contacts, stiff and large time steps.

Everywhere: no NaN or inf, and ``converged`` is True exactly when ``residual <= tol``.
"""

import numpy as np
import pytest
from numdiff import random_p_matrix

from drake_abs import (
    ContactAware,
    Exact,
    Fixed,
    GaussianMatched,
    LCPConvergenceWarning,
    LCPStatus,
    point_mass_lcs,
    solve_lcp,
)
from drake_abs.lcp.closed_form import softened_lcp_1d, softened_lcp_1d_dlam_dz

MUS = [0.0, 1e-14, 1e-10, 1e-6, 1e-2, 1.0, 1e3]
Q_SCALES = [1e-8, 1.0, 1e4, 1e8]


def conditioned_matrix(rng, d, cond, *, symmetric=True):
    """A positive definite matrix with the given condition number (symmetric part for skew)."""
    Q, _ = np.linalg.qr(rng.normal(size=(d, d)))
    F = Q @ np.diag(np.logspace(0, -np.log10(cond), d)) @ Q.T
    if not symmetric:
        W = rng.normal(size=(d, d))
        F = F + 1e-3 * (W - W.T)
    return F


def assert_honest(r, F, q):
    """Check a result independently of the solver's own residual: recompute F lam + q and
    lam o s, and hold every converged problem to the documented contract."""
    for name in ("lam", "slack", "mu", "residual"):
        assert np.all(np.isfinite(getattr(r, name))), name
    if r.dlam_dq is not None:
        assert np.all(np.isfinite(r.dlam_dq)) and np.all(np.isfinite(r.dlam_dmu))
    assert np.all(r.lam > 0) and np.all(r.slack > 0)
    np.testing.assert_array_equal(r.converged, r.residual <= r.tol)
    lam, s = np.atleast_2d(r.lam), np.atleast_2d(r.slack)
    q = np.broadcast_to(q, lam.shape)
    Fl = np.einsum("...ij,...j->...i", F, lam)
    row_scale = np.abs(q) + np.abs(s) + np.einsum("...ij,...j->...i", np.abs(F), lam)
    primal = np.abs(s - Fl - q) / row_scale
    conv = np.atleast_1d(r.converged)
    # each row's backward error (a little above tol: recomputed in the unscaled variables)
    assert np.all(primal[conv] <= 10 * r.tol), primal[conv].max()
    # complementarity: |lam_i s_i - target_i| <= tol target_i + gap_atol_i, with gap_atol_i the
    # exact floor (1e-15 c)^2 plus 1e-13 times the largest target F couples to contact i
    # (c = max |q_i| / sqrt(F_ii), up to the solver's power-of-two rounding: factor 2 at most)
    target = np.atleast_2d(r.mu_target)
    Fdiag = np.diagonal(F, axis1=-2, axis2=-1)
    c = 2 * np.max(np.abs(q) / np.sqrt(np.where(Fdiag > 0, Fdiag, 1.0)), axis=-1, keepdims=True)
    coupled = (np.abs(F) + np.abs(np.swapaxes(F, -1, -2))) > 0
    coupled = np.broadcast_to(
        coupled & ~np.eye(F.shape[-1], dtype=bool), lam.shape + lam.shape[-1:]
    )
    atol = (1e-15 * c) ** 2 + 1.01e-13 * np.where(coupled, target[:, None, :], 0).max(-1)
    gap_err = np.abs(lam * s - target)
    assert np.all(gap_err[conv] <= 1.01 * r.tol * target[conv] + atol[conv] + 1e-300)


@pytest.mark.parametrize("cond", [1.0, 1e4, 1e10])
@pytest.mark.parametrize("symmetric", [True, False])
def test_mu_q_and_conditioning_extremes(cond, symmetric, rng):
    d = 10
    F = conditioned_matrix(rng, d, cond, symmetric=symmetric)
    failures = []
    for scale in Q_SCALES:
        q = rng.normal(size=(64, d)) * scale
        for mu in MUS:
            r = solve_lcp(F, q, mu, jacobians=True, max_iterations=200)
            assert_honest(r, F, q)
            if not r.converged.all():
                failures.append((scale, mu, int((~r.converged).sum()), float(r.residual.max())))
    # honest flags are required everywhere; convergence is required too on this well-posed set
    assert not failures, failures


def test_mu_is_reached_per_contact_over_the_whole_range(rng):
    d = 6
    F = random_p_matrix(rng, d)
    q = rng.normal(size=(200, d))
    mu = 10.0 ** rng.uniform(-14, 3, size=(200, d))  # per contact, 17 decades
    r = solve_lcp(F, q, mu, strict=True)
    assert_honest(r, F, q)
    # the documented contract: |lam_i s_i - mu_i| <= tol mu_i + gap_atol, where gap_atol is
    # 1e-13 max_j mu_j (coupling roundoff) plus the exact floor (1e-15 c)^2 (c ~ |q| here)
    gap_atol = 1e-13 * mu.max(axis=1, keepdims=True) + 1e-28
    assert np.all(np.abs(r.mu - mu) <= r.tol * mu + gap_atol)
    # and where mu_i dominates that absolute part, the relative error is at the tol level
    well_resolved = mu >= 1e-3 * mu.max(axis=1, keepdims=True)
    np.testing.assert_allclose(r.mu[well_resolved], mu[well_resolved], rtol=2e-10)


@pytest.mark.parametrize("batch", [1, 10, 1000, 100_000])
def test_batches_from_one_to_1e5(batch, rng):
    q = rng.normal(size=(batch, 1)) * 10.0 ** rng.uniform(-4, 4, size=(batch, 1))
    r = solve_lcp(np.array([[0.01]]), q, 1e-10, jacobians=True, strict=True)
    assert_honest(r, np.array([[0.01]]), q)
    assert r.lam.shape == (batch, 1) and r.dlam_dq.shape == (batch, 1, 1)


def test_per_problem_matrices_batch(rng):
    F = np.stack([conditioned_matrix(rng, 4, c) for c in np.logspace(0, 10, 50)])
    q = rng.normal(size=(50, 4)) * 1e3
    r = solve_lcp(F, q, 1e-8, jacobians=True, strict=True)
    assert_honest(r, F, q)


def test_many_contacts(rng):
    d = 100
    F = random_p_matrix(rng, d)
    q = rng.normal(size=d)
    r = solve_lcp(F, q, 1e-10, jacobians=True, strict=True)
    assert_honest(r, F, q)
    assert r.iterations <= 40


def test_singular_psd_matrix_with_redundant_contacts(rng):
    # four contacts on one body share its 2 velocities: F = J M^-1 J^T has rank 2
    J = rng.normal(size=(4, 2))
    F = J @ J.T
    q = rng.uniform(0.1, 1, size=4) - F @ rng.uniform(0.1, 1, size=4)
    for mu in (0.0, 1e-8, 1e-2):
        r = solve_lcp(F, q, mu, jacobians=True, strict=True)
        assert_honest(r, F, q)


@pytest.mark.parametrize("h", [1e-5, 1e-3, 0.1, 1.0])
@pytest.mark.parametrize("mass", [1e-4, 1.0, 1e4])
@pytest.mark.parametrize(
    "policy",
    [Exact(), Fixed(1e-12), Fixed(1e2), ContactAware(1.0, 0.01), GaussianMatched(0.01)],
    ids=repr,
)
def test_point_mass_stiff_and_large_time_steps(h, mass, policy):
    lcs = point_mass_lcs(3, time_step=h, mass=mass)
    x = np.zeros((7, 6))
    x[:, 2] = [-1e3, -1.0, -1e-6, 0.0, 1e-6, 1.0, 1e3]  # deep penetration to far away
    x[:, 5] = -10.0
    r = lcs.step(x, np.zeros(3), policy, gradient="total", strict=True)
    for name in ("x_next", "impulse", "dx_dx", "dx_du", "dimpulse_dx"):
        assert np.all(np.isfinite(getattr(r, name))), name
    if isinstance(policy, Exact):
        # hard contact: no penetration after the step (up to the solver's tolerance)
        assert np.all(r.x_next[:, 2] >= -1e-9 * (1 + np.abs(x[:, 2])))


def test_infeasible_rows_are_never_reported_converged():
    """A diverging contact must not hide another row's residual (one scale per row)."""
    cases = [
        (np.diag([0.0, 1.0]), np.array([-1.0, -1.0]), 0.0),  # row 0 has no solution
        (np.array([[0.0, 1.0], [-1.0, 0.0]]), np.array([1.0, -1.0]), 0.0),  # skew: infeasible
        (np.zeros((1, 1)), np.array([0.0]), 1.0),  # s = 0 always: no central-path point
        (np.zeros((3, 3)), np.array([1.0, -1.0, 2.0]), 1e-6),
    ]
    for F, q, mu in cases:
        with pytest.warns(LCPConvergenceWarning):
            r = solve_lcp(F, q, mu, jacobians=True, on_bad_matrix="attempt")
        assert not r.converged, (F, q)
        assert np.all(np.isfinite(r.lam)) and r.residual > r.tol


def test_unrepresentable_solutions_are_flagged():
    with pytest.warns(LCPConvergenceWarning):
        r = solve_lcp(np.array([[1e-320]]), np.array([-1.0]), 0.0, jacobians=True)
    assert not r.converged and r.status == LCPStatus.NUMERICAL_FAILURE


@pytest.mark.parametrize("d", [2, 3])
def test_uncoupled_contacts_keep_their_own_accuracy(d, rng):
    """Diagonal F: every contact must match its own closed form, whatever the others' mu and z."""
    B = 2000
    Fd = 10.0 ** rng.uniform(-3, 3, size=d)
    z = rng.choice([-1, 1], size=(B, d)) * 10.0 ** rng.uniform(-6, 3, size=(B, d))
    mu = 10.0 ** rng.uniform(-12, 2, size=(B, d))
    r = solve_lcp(np.diag(Fd), z, mu, jacobians=True, strict=True)
    np.testing.assert_allclose(r.lam, softened_lcp_1d(z, Fd, mu), rtol=1e-10, atol=0)
    np.testing.assert_allclose(
        np.diagonal(r.dlam_dq, axis1=1, axis2=2), softened_lcp_1d_dlam_dz(z, Fd, mu), rtol=1e-9
    )
    # one scalar mu with |z| mixed over 9 decades
    r = solve_lcp(np.diag(Fd), z, 1e-6, strict=True)
    np.testing.assert_allclose(r.lam, softened_lcp_1d(z, Fd, 1e-6), rtol=1e-10, atol=0)
