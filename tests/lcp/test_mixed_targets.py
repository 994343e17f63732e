"""A contact already at its target is held there while others with larger targets are still
centring (drake_abs.lcp.ipm_kernel, step 6): on a frictional contact whose normal row is
smoothed 100 times less than its friction rows (the rigid-body step divides the friction rows'
mu by h), the iterations used to leave the normal row's target and cycle."""

from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from drake_abs import solve_lcp
from drake_abs.lcp import ipm

DATA = np.load(Path(__file__).with_name("half_cheetah_mixed_mu_lcp.npz"))


def central_point(F, q, mu):
    """The central-path point found independently: ``log lam + log(F lam + q) = log mu`` by
    scipy's least squares, from several starts, keeping the best."""
    rng = np.random.default_rng(0)

    def resid(y):
        lam = np.exp(y)
        return y + np.log(np.maximum(F @ lam + q, 1e-300)) - np.log(mu)

    best = min((least_squares(resid, rng.normal(0, 1, q.size), xtol=1e-15, ftol=1e-15,
                              gtol=1e-15) for _ in range(20)), key=lambda r: r.cost)  # fmt: skip
    assert best.cost < 1e-25
    return np.exp(best.x)


def test_mixed_targets_converge_from_the_default_start_alone(monkeypatch):
    F, q, mu = DATA["F"], DATA["z"], DATA["mu"]
    assert mu.max() / mu.min() == 100
    monkeypatch.setattr(ipm, "SECOND_START", False)  # no retries, no crossover
    r = solve_lcp(F, q, mu, on_bad_matrix="attempt", strict=True)
    assert r.iterations < 30
    np.testing.assert_allclose(r.lam * r.slack, mu, rtol=1e-10)
    np.testing.assert_allclose(r.lam, central_point(F, q, mu), rtol=1e-8)


def test_mixed_targets_converge_over_a_range_of_scales(monkeypatch):
    """Before the fix the band mu x [0.99, 1.5] failed on this problem; every scale converges
    now, from the default start alone, and matches the independent central point."""
    F, q, mu = DATA["F"], DATA["z"], DATA["mu"]
    monkeypatch.setattr(ipm, "SECOND_START", False)
    for scale in (0.5, 0.99, 1.0, 1.1, 1.5, 3.0):
        r = solve_lcp(F, q, mu * scale, on_bad_matrix="attempt", strict=True)
        np.testing.assert_allclose(r.lam, central_point(F, q, mu * scale), rtol=1e-8)


def test_exact_contacts_at_the_floor_keep_centring_beside_smoothed_ones(monkeypatch):
    """A monotone (Anitescu) step of solo12 under the Gaussian-matched design: per-contact mu
    from 1e-28 (exact: the floor target) to 2e-6. Contacts at the floor are not held there but
    centre with the others (holding them let their products collapse to 1e-80 and the solve
    stall); the smoothed contacts are held at their targets. From the default start alone."""
    data = np.load(Path(__file__).with_name("solo12_anitescu_floor_lcp.npz"))
    F, q, mu = data["F"], data["z"], data["mu"]
    assert mu.min() < 1e-25 and mu.max() > 1e-6
    monkeypatch.setattr(ipm, "SECOND_START", False)
    r = solve_lcp(F, q, mu, on_bad_matrix="trusted", strict=True)
    assert r.iterations < 40
    smoothed = mu > 1e-10
    np.testing.assert_allclose((r.lam * r.slack)[smoothed], mu[smoothed], rtol=1e-10)
