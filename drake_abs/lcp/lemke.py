"""Lemke's complementary pivoting for the exact (mu = 0) LCP, the crossover's last resort
(docs/math.md section 3b).

Principal pivoting (:mod:`drake_abs.lcp.pivoting`) is finite for P-matrices, but the
Stewart-Trinkle friction LCP is only copositive: its ``F_AA`` can be singular and its pivots
can cycle, and then the crossover finds nothing although the problem has a solution. Lemke's
method (Lemke 1965; Cottle, Pang and Stone, *The Linear Complementarity Problem*, section 4.4)
processes copositive-plus matrices, which include the Stewart-Trinkle matrix (Stewart and
Trinkle 1996): it either ends at a solution or on a secondary ray, which for such matrices
means the problem has none.

The method works on the system ``w - F lam - e z0 = q`` with an artificial variable ``z0`` and
the covering vector ``e = 1``. It starts from the almost-complementary basis in which ``z0``
enters at the row of the most negative ``q_i``, and each step brings in the complement of the
variable that just left, with the minimum-ratio test choosing the row that leaves. It ends when
``z0`` leaves.

Ties in the ratio test (a degenerate basis) go to ``z0`` when its row is among them, and
otherwise are broken by the lexicographic rule (Cottle, Pang and Stone, section 4.9): among the
tied rows, the smallest ratio of the tableau's ``w`` columns (which hold the inverse of the
current basis) to the pivot element, column by column, decides. That rule is what keeps the
method finite on degenerate problems, where the plain minimum ratio can cycle: on the 40-row
bimatrix game ``tobenna`` of the Siconos LCP collection (every ``q_i`` of its eight
normalisation rows is -1, and its payoff blocks repeat entries) Lemke's method with ties going to
the largest pivot element had not ended after 10,000 pivots; with the lexicographic rule it ends
at a solution after 127. The first pivot's ties (several rows at the most negative ``q_i``) are
broken the same way. A tableau that overflows ends the method with nothing found.

Only the final basis is used here: the set of basic ``lam_i``, handed to principal pivoting as
a guess, which solves ``F_AA lam_A = -q_A`` afresh (so the roundoff the tableau accumulates
does not reach the answer) and checks the signs. The compiled interior-point iterations then
verify the candidate against ``tol`` as for any crossover answer: nothing here decides
convergence.
"""

from __future__ import annotations

import numpy as np

#: Relative size below which a tableau entry counts as zero in the ratio test.
PIVOT_TOL = 1e-11


def lemke_active_set(
    F: np.ndarray, q: np.ndarray, *, max_pivots: int
) -> tuple[np.ndarray | None, int]:
    """The active set (``lam_i`` basic) of the basis where Lemke's method ends.

    Args:
        F: (d, d) LCP matrix. q: (d,). max_pivots: pivot budget (> 0).

    Returns:
        ``(active, pivots)``: active (d,) bool, or None when the method ends on a ray (no
        solution found) or exhausts ``max_pivots``; all False when ``q >= 0`` (``lam = 0``
        solves the problem). ``pivots`` is the pivot steps spent.
    """
    d = q.shape[0]
    if np.all(q >= 0):
        return np.zeros(d, dtype=bool), 0
    # Jacobi scaling keeps the tableau's entries comparable; it changes no active set
    diag = np.abs(np.diagonal(F))
    scale = np.where(diag > 0, 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0)), 1.0)
    Fs = F * scale[:, None] * scale[None, :]
    qs = q * scale
    # columns: w (0..d-1), lam (d..2d-1), z0 (2d), right-hand side (2d+1)
    z0 = 2 * d
    T = np.hstack([np.eye(d), -Fs, -np.ones((d, 1)), qs[:, None]])
    if not np.isfinite(T).all():
        return None, 0  # the scaled problem is not representable: no basis to trust
    basis = np.arange(d)
    entering = z0
    row = _ratio_test(T, basis, entering, z0, first=True)
    for pivots in range(1, max_pivots + 1):
        with np.errstate(all="ignore"):
            _pivot(T, row, entering)
        if not np.isfinite(T).all():
            return None, pivots  # the tableau overflowed: stop, nothing found
        leaving = int(basis[row])
        basis[row] = entering
        if leaving == z0:
            active = np.zeros(d, dtype=bool)
            lam_basic = basis[(basis >= d) & (basis < z0)]
            active[lam_basic - d] = True
            return active, pivots
        entering = leaving + d if leaving < d else leaving - d  # the complement
        row = _ratio_test(T, basis, entering, z0)
        if row is None:
            return None, pivots  # secondary ray
    return None, max_pivots


def _pivot(T: np.ndarray, row: int, col: int) -> None:
    """Gauss-Jordan pivot of the tableau T on (row, col), in place."""
    T[row] /= T[row, col]
    factors = T[:, col].copy()
    factors[row] = 0.0
    T -= np.outer(factors, T[row])


def _ratio_test(
    T: np.ndarray, basis: np.ndarray, col: int, z0: int, *, first: bool = False
) -> int | None:
    """The leaving row for the entering column ``col``: the minimum of ``rhs_i / T_i,col``
    over the rows with ``T_i,col > 0``; among ties, z0's row, else the lexicographic rule of the
    module docstring. With ``first`` (z0 entering the initial basis ``w``, column ``-e``), the
    rows are those of the most negative right-hand side instead, the ratios taken against
    ``-T_i,col = 1``, ties broken by the same rule."""
    d = T.shape[0]
    column = T[:, col]
    if first:
        rhs = T[:, -1]
        top_rhs = np.abs(rhs).max()
        worst = rhs.min()
        rows = np.flatnonzero(rhs <= worst + PIVOT_TOL * max(top_rhs, 1.0))
        pivot = -column[rows]
    else:
        top = np.abs(column).max()
        positive = column > PIVOT_TOL * max(top, 1.0)
        if not positive.any():
            return None
        rows = np.flatnonzero(positive)
        pivot = column[rows]
        ratios = np.maximum(T[rows, -1], 0.0) / pivot
        best = ratios.min()
        tied = ratios <= best + PIVOT_TOL * max(best, 1.0)
        if not tied.any():  # not comparable (cannot happen for a finite tableau)
            return None
        rows, pivot = rows[tied], pivot[tied]
        if np.any(basis[rows] == z0):
            return int(rows[basis[rows] == z0][0])
    # lexicographic rule: the smallest row (T_i,0 .. T_i,d-1) / pivot element, column by column,
    # over the columns of the basis inverse (the w columns). For the first pivot the pivot
    # elements -T_i,col are all 1: the lexicographically smallest row (q_i, e_i) leaves, which
    # keeps every row of the new basis lexicographically positive.
    for k in range(d):
        if rows.size <= 1:
            break
        ratios = T[rows, k] / pivot
        best = ratios.min()
        tied = ratios <= best + PIVOT_TOL * max(abs(best), 1.0)
        if not tied.any():  # not comparable (cannot happen for a finite tableau)
            break
        rows, pivot = rows[tied], pivot[tied]
    return int(rows[np.argmax(pivot)])
