"""Exact (mu -> 0) solutions against Drake's MobyLcpSolver (Lemke), an independent solver."""

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from moby_reference import moby
from numdiff import random_p_matrix

from drake_abs import solve_lcp


@settings(max_examples=40)
@given(d=st.integers(1, 50), seed=st.integers(0, 2**32 - 1), mu=st.sampled_from([0.0, 1e-12]))
def test_random_p_matrix_lcp_agrees_with_moby(d, seed, mu):
    rng = np.random.default_rng(seed)
    F = random_p_matrix(rng, d)
    q = rng.normal(size=d) * rng.choice([1e-2, 1.0, 1e2])
    ok, z_moby = moby(F, q)
    assume(ok)
    r = solve_lcp(F, q, mu, strict=True)
    scale = 1.0 + np.abs(z_moby).max()
    np.testing.assert_allclose(r.lam, z_moby, atol=1e-6 * scale, rtol=0)


@settings(max_examples=20)
@given(d=st.integers(2, 30), rank=st.integers(1, 30), seed=st.integers(0, 2**32 - 1))
def test_singular_psd_matrix_agrees_with_moby_on_the_unique_part(d, rank, seed):
    # F = J J^T with redundant contacts: lam is not unique at mu = 0, but F lam and s are.
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(d, min(rank, d)))
    F = J @ J.T
    # strictly feasible by construction (lam0 > 0, s0 > 0), so the central path exists
    q = rng.uniform(0.01, 1.0, size=d) - F @ rng.uniform(0.01, 1.0, size=d)
    ok, z_moby = moby(F, q)
    assume(ok)
    r = solve_lcp(F, q, 0.0, strict=True)
    scale = 1.0 + np.abs(F @ z_moby).max()
    np.testing.assert_allclose(F @ r.lam, F @ z_moby, atol=1e-6 * scale)
    assert np.all(r.lam >= 0) and np.all(r.slack >= 0)
    assert np.abs(r.lam * r.slack).max() < 1e-12 * scale**2
