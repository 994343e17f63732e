"""Lemke's method as the crossover's last resort (drake_abs.lcp.lemke), on the Stewart-Trinkle
friction LCPs that principal pivoting cannot finish, against Drake's MobyLcpSolver."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from moby_reference import moby

from drake_abs import solve_lcp
from drake_abs.lcp import ipm
from drake_abs.lcp.lemke import lemke_active_set
from drake_abs.lcp.pivoting import complementary_point, solve_by_pivoting

HERE = Path(__file__).parent


def friction_lcp(rng, nc: int, nd: int, nv: int, h: float = 0.01):
    """A random Stewart-Trinkle LCP (normal rows, nd friction directions per contact, one cone
    row per contact): an SPD inverse mass W, random Jacobians, friction coefficients in
    [0.2, 1.5], free velocities and gaps of either sign. Copositive, not a P-matrix."""
    M = rng.normal(size=(nv, nv))
    W = np.linalg.inv(M @ M.T / nv + 0.1 * np.eye(nv))
    Jn = rng.normal(size=(nc, nv))
    D = rng.normal(size=(nc * nd, nv))
    if nd == 2:  # planar: the two directions of each contact are opposite
        D[1::2] = -D[0::2]
    E = np.kron(np.eye(nc), np.ones((nd, 1)))
    U = np.diag(rng.uniform(0.2, 1.5, nc))
    G = np.vstack([Jn, D])
    A = h * G @ W @ G.T
    F = np.zeros((nc * (nd + 2), nc * (nd + 2)))
    n, t = nc, nc * nd
    F[: n + t, : n + t] = A
    F[n : n + t, n + t :] = E
    F[n + t :, :n] = U
    F[n + t :, n : n + t] = -E.T
    v = rng.normal(size=nv)
    q = np.concatenate([rng.normal(0.0, 0.01, nc) + h * Jn @ v, D @ v, np.zeros(nc)])
    return F, q


def valid(F, q, lam, rtol=1e-9) -> bool:
    """A solution to ``rtol`` of each row's terms, the test moby_reference applies to Moby."""
    w = F @ lam + q
    row = np.abs(q) + np.abs(F) @ np.abs(lam)
    return bool(
        np.all(lam >= -rtol * row)
        and np.all(w >= -rtol * row)
        and np.all(np.minimum(np.abs(lam), np.abs(w)) <= rtol * (1.0 + row))
    )


@settings(max_examples=40, deadline=None)
@given(nc=st.integers(1, 6), nd=st.sampled_from([2, 4]), seed=st.integers(0, 2**32 - 1))
def test_lemke_solves_every_friction_lcp_that_moby_solves(nc, nd, seed):
    rng = np.random.default_rng(seed)
    F, q = friction_lcp(rng, nc, nd, nv=3 + 2 * nc)
    usable, _ = moby(F, q)
    d = q.size
    active, pivots = lemke_active_set(F, q, max_pivots=4 * d + 20)
    if not usable:
        return  # Moby found nothing valid: no claim either way
    assert active is not None, "Lemke ended on a ray where Moby found a solution"
    found, _ = solve_by_pivoting(F, q, [active], max_pivots=4 * d + 20,
                                 eta=8 * d * np.finfo(float).eps)  # fmt: skip
    assert found.ok
    assert valid(F, q, found.lam)
    assert 0 < pivots <= 4 * d + 20 or np.all(q >= 0)


def test_lemke_ends_on_a_ray_for_a_problem_without_solution():
    # w = -lam - 1 < 0 for every lam >= 0: no solution, and Lemke's method says so
    active, _ = lemke_active_set(np.array([[-1.0]]), np.array([-1.0]), max_pivots=10)
    assert active is None


def test_lemke_returns_the_empty_set_when_lam_zero_solves():
    active, pivots = lemke_active_set(np.eye(3), np.array([0.0, 1.0, 2.0]), max_pivots=10)
    assert active is not None and not active.any() and pivots == 0


def test_lemke_answers_a_p_matrix_problem_as_the_unique_solution():
    rng = np.random.default_rng(3)
    F = rng.normal(size=(6, 6))
    F = F @ F.T + 0.5 * np.eye(6)
    q = rng.normal(size=6)
    active, _ = lemke_active_set(F, q, max_pivots=50)
    lam, _ = complementary_point(F, q, active)
    usable, z = moby(F, q)
    assert usable
    np.testing.assert_allclose(lam, z, atol=1e-10)


def test_a_half_cheetah_exact_step_needs_lemke_and_is_then_solved(monkeypatch):
    """An exact (mu = 0) step of gymnasium's HalfCheetah on our plant (24 rows, cond(F) near
    1e17, symmetric part indefinite) that the interior point and principal pivoting leave
    unsolved: without Lemke's method it is flagged, with it it converges (verified by the
    compiled iterations), and the answer is a valid LCP solution, as Moby's is."""
    data = np.load(HERE / "half_cheetah_exact_lcp.npz")
    F, q = data["F"], data["z"]
    monkeypatch.setattr(ipm, "lemke_active_set", lambda F, q, max_pivots: (None, 0))
    with pytest.warns(ipm.LCPConvergenceWarning):
        without = solve_lcp(F, q, 0.0, on_bad_matrix="attempt")
    assert not without.converged
    monkeypatch.undo()
    r = solve_lcp(F, q, 0.0, on_bad_matrix="attempt")
    assert r.converged and r.polished and r.pivots > 0
    assert valid(F, q, r.lam, rtol=1e-9)
    usable, z = moby(F, q)
    assert usable and valid(F, q, z)


def test_lemke_stops_without_an_answer_when_the_tableau_overflows():
    """Jacobi scaling of a matrix with entries 1e300 off a 1e-300 diagonal overflows: nothing is
    returned (the crossover keeps the problem flagged), no exception."""
    F = np.array([[1e-300, 1e300], [-1e300, 1e-300]])
    with np.errstate(all="ignore"):
        active, pivots = lemke_active_set(F, np.array([-1.0, -1.0]), max_pivots=10)
    assert active is None and pivots == 0
