"""The solver against the one-contact closed form (docs/math.md section 2)."""

import numpy as np
import pytest

from drake_abs import solve_lcp
from drake_abs.lcp.closed_form import (
    softened_lcp_1d,
    softened_lcp_1d_dlam_dmu,
    softened_lcp_1d_dlam_dz,
)

Z = np.concatenate([-np.logspace(3, -6, 28), [0.0], np.logspace(-6, 3, 28)])
MUS = np.logspace(-12, 2, 29)


@pytest.mark.parametrize("F", [1e-3, 0.37, 1.0, 1e3])
def test_matches_closed_form_over_mu_and_z(F):
    # every (z, mu) pair of the grid in one batch, per-problem mu
    z, mu = (a.ravel() for a in np.meshgrid(Z, MUS))
    r = solve_lcp(np.array([[F]]), z[:, None], mu, jacobians=True, strict=True)
    lam = r.lam[:, 0]
    ref = softened_lcp_1d(z, F, mu)
    np.testing.assert_allclose(lam, ref, rtol=1e-10, atol=0)
    np.testing.assert_allclose(r.slack[:, 0], mu / ref, rtol=1e-9)  # s = mu / lam, no cancellation
    np.testing.assert_allclose(r.mu[:, 0], mu, rtol=1e-10)
    np.testing.assert_allclose(r.dlam_dq[:, 0, 0], softened_lcp_1d_dlam_dz(z, F, mu), rtol=1e-9)
    np.testing.assert_allclose(r.dlam_dmu[:, 0], softened_lcp_1d_dlam_dmu(z, F, mu), rtol=1e-9)


def test_closed_form_derivatives_against_finite_differences():
    F = 0.5
    for mu in (1e-6, 1e-2, 1.0):
        for z in (-2.0, -0.01, 0.0, 0.003, 1.5):
            eps = 1e-6 * max(1.0, abs(z))
            fd = (softened_lcp_1d(z + eps, F, mu) - softened_lcp_1d(z - eps, F, mu)) / (2 * eps)
            assert softened_lcp_1d_dlam_dz(z, F, mu) == pytest.approx(fd, rel=1e-6, abs=1e-9)
            em = 1e-4 * mu
            fdm = (softened_lcp_1d(z, F, mu + em) - softened_lcp_1d(z, F, mu - em)) / (2 * em)
            assert softened_lcp_1d_dlam_dmu(z, F, mu) == pytest.approx(fdm, rel=1e-6)


def test_exact_lcp_is_max_of_zero_and_minus_z_over_f():
    F = 2.0
    r = solve_lcp(np.array([[F]]), Z[:, None], 0.0, strict=True)
    np.testing.assert_allclose(r.lam[:, 0], np.maximum(0, -Z / F), rtol=1e-12, atol=1e-12)
    # mu = 0 is solved to the exact floor and says so
    assert np.all(r.mu_target > 0) and np.all(r.mu_target <= (1e-15 * np.abs(Z).max()) ** 2 * 4)


def test_larger_mu_means_more_force_at_a_distance():
    # the documented direction: more smoothing = larger impulse before contact
    lam = [solve_lcp(np.array([[1.0]]), np.array([0.1]), mu).lam[0] for mu in (1e-6, 1e-3, 1e-1)]
    assert lam[0] < lam[1] < lam[2]
