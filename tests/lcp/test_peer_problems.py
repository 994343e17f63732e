"""Two exact LCPs of a peer solver's test collection that the crossover finishes (issue 35, item
7), checked independently of the solver's residual and against Drake's MobyLcpSolver.

Both come from the LCP collection of Siconos (``numerics/src/LCP/test/data``, Apache-2.0),
whose dense matrix files list F column by column:

- Pang's isolated-solution problem (``lcp_Pang_isolated_sol.dat``), d = 3, neither monotone nor
  a P-matrix (zero diagonal). Its first row ``w_1 = -lam_2 - lam_3`` forces
  ``lam_2 = lam_3 = w_1 = 0``, the other two force ``lam_1 = 1``: the one solution is the
  vertex ``lam = (1, 0, 0), w = 0``, with no interior point next to it, so no strictly positive
  iterate can pass the solver's test; the crossover answers with the vertex itself.
- ``tobenna`` (``lcp_tobenna.dat``, stored here as ``siconos_tobenna_lcp.npz``), d = 40: a
  bimatrix-game LCP (all-ones diagonal blocks, integer payoffs 1 .. 250, eight normalisation
  rows with q = -1). Copositive-plus and feasible, so Lemke's method must end at a solution,
  but the problem is degenerate: without the lexicographic rule it cycles past any budget.
  Drake 1.58's MobyLcpSolver reports success on it with ``w_i = -1`` and ``lam_i w_i = 100``.

Read row by row instead, both files give infeasible problems (a row ``w_i = -(...) - 1``), which
must stay flagged.
"""

from pathlib import Path

import numpy as np
import pytest
from moby_reference import moby

from drake_abs import LCPConvergenceWarning, LCPStatus, solve_lcp
from drake_abs.lcp import ipm
from drake_abs.lcp.lemke import lemke_active_set

HERE = Path(__file__).parent

#: The independent check's tolerance, relative to each row's terms (as in test_hard_problems).
CHECK_TOL = 1e-10


def pang_isolated() -> tuple[np.ndarray, np.ndarray]:
    """Pang's isolated-solution problem (module docstring): (F (3, 3), q (3,))."""
    F = np.array([[0.0, -1.0, -1.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    return F, np.array([0.0, -1.0, 1.0])


def tobenna() -> tuple[np.ndarray, np.ndarray]:
    """Siconos's ``tobenna`` (module docstring): (F (40, 40), q (40,))."""
    data = np.load(HERE / "siconos_tobenna_lcp.npz")
    return data["F"], data["q"]


def assert_solves(F: np.ndarray, q: np.ndarray, lam: np.ndarray, tol: float = CHECK_TOL) -> None:
    """lam solves the LCP (F, q), recomputed here: lam >= 0, w = F lam + q >= 0 and
    min(lam_i, w_i) ~ 0, each relative to its row's terms ``|q_i| + (|F| |lam|)_i`` (and 1 for a
    row whose terms all vanish, as Pang's first row does at its solution)."""
    w = F @ lam + q
    row = np.maximum(np.abs(q) + np.abs(F) @ np.abs(lam), 1.0)
    assert np.all(lam >= 0)
    assert np.all(w >= -tol * row), np.min(w / row)
    assert np.all(np.minimum(lam, np.abs(w)) <= tol * row), np.max(np.minimum(lam, np.abs(w)) / row)


@pytest.mark.parametrize("problem", [pang_isolated, tobenna])
def test_peer_problem_is_solved_and_verified(problem):
    F, q = problem()
    r = solve_lcp(F, q, 0.0, on_bad_matrix="attempt")
    assert r.converged and r.status == LCPStatus.CONVERGED and r.residual <= r.tol
    assert r.polished  # the interior point alone does not finish either
    assert_solves(F, q, r.lam)


def test_pang_answer_is_the_isolated_vertex_and_moby_agrees():
    F, q = pang_isolated()
    r = solve_lcp(F, q, 0.0, on_bad_matrix="attempt")
    np.testing.assert_array_equal(r.lam, [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(r.slack, [0.0, 0.0, 0.0])
    usable, z = moby(F, q)
    assert usable
    np.testing.assert_allclose(r.lam, z, atol=1e-12)


def test_pang_needs_the_vertex_check(monkeypatch):
    """Without accepting the crossover's vertex, Pang's problem stays flagged: every positive
    point fails the test on its first row."""
    monkeypatch.setattr(ipm, "_check_vertices", lambda *args, **kwargs: None)
    F, q = pang_isolated()
    with pytest.warns(LCPConvergenceWarning):
        r = solve_lcp(F, q, 0.0, on_bad_matrix="attempt")
    assert not r.converged and not r.polished


def test_pang_is_never_converged_when_smoothed():
    """At mu > 0 the softened problem has no solution (row 1 needs lam_2 + lam_3 < 0 for
    s_1 > 0): the vertex must not be passed off as the central-path point."""
    F, q = pang_isolated()
    with pytest.warns(LCPConvergenceWarning):
        r = solve_lcp(F, q, 1e-6, on_bad_matrix="attempt")
    assert not r.converged and not r.polished


def test_pang_jacobians_do_not_exist_and_are_flagged():
    """At the degenerate vertex (lam_i = w_i = 0 for i = 2, 3) the implicit Jacobians do not
    exist: with jacobians=True the problem is flagged, never returned with invented numbers."""
    F, q = pang_isolated()
    with pytest.warns(LCPConvergenceWarning):
        r = solve_lcp(F, q, 0.0, on_bad_matrix="attempt", jacobians=True)
    assert not r.converged and r.status == LCPStatus.NUMERICAL_FAILURE
    assert np.all(np.isnan(r.dlam_dq))


def test_tobenna_with_jacobians_and_smoothed():
    """tobenna's solution is strictly complementary enough for the interior point to finish
    from the crossover's start: Jacobians exist, and mu = 1e-6 converges as well."""
    F, q = tobenna()
    r = solve_lcp(F, q, 0.0, on_bad_matrix="attempt", jacobians=True)
    assert r.converged and np.all(np.isfinite(r.dlam_dq))
    assert_solves(F, q, r.lam)
    smooth = solve_lcp(F, q, 1e-6, on_bad_matrix="attempt")
    assert smooth.converged
    np.testing.assert_allclose(smooth.lam * smooth.slack, 1e-6, rtol=1e-9)


def test_lexicographic_lemke_finishes_tobenna_within_the_crossover_budget():
    F, q = tobenna()
    budget = ipm.PIVOTS_PER_CONTACT * q.size + ipm.PIVOTS_EXTRA
    active, pivots = lemke_active_set(F, q, max_pivots=budget)
    assert active is not None and pivots <= budget


def test_tobenna_against_moby():
    """Moby's answer is used only where it is valid (moby_reference); ours must be valid
    whatever Moby does, and where both are valid both solve the problem."""
    F, q = tobenna()
    r = solve_lcp(F, q, 0.0, on_bad_matrix="attempt")
    assert r.converged
    assert_solves(F, q, r.lam)
    usable, z = moby(F, q)
    if usable:
        assert_solves(F, q, z, tol=1e-9)


@pytest.mark.parametrize("problem", [pang_isolated, tobenna])
def test_the_files_read_row_by_row_are_infeasible_and_stay_flagged(problem):
    F, q = problem()
    with pytest.warns(LCPConvergenceWarning, match="did not converge"):
        r = solve_lcp(F.T.copy(), q, 0.0, on_bad_matrix="attempt")
    assert not r.converged and not r.polished and r.residual > r.tol
    assert not moby(F.T.copy(), q)[0]
