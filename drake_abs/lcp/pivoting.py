"""Crossover from the interior point to an exact LCP solution by principal pivoting
(docs/math.md section 3b).

At ``mu = 0`` the LCP ``lam >= 0, w = F lam + q >= 0, lam_i w_i = 0`` is a finite problem: once
the set ``A`` of contacts with ``lam_i > 0`` is known, ``lam_A`` solves the linear system
``F_AA lam_A = -q_A``, every other ``lam_i`` is 0, and the candidate is a solution exactly when
``lam_A >= 0`` and ``w_i >= 0`` off ``A`` (``w_A = 0`` by construction). This module guesses
``A`` from an interior iterate (even one that stalled or diverged), solves that system, and
corrects a wrong guess by principal pivots (flipping contacts in or out of ``A``):

- block pivots: every contact that violates its sign flips at once, while the number of
  violations keeps falling (at most ``BLOCK_TRIES`` block pivots in a row without a new best);
- otherwise single pivots on the least violating index (Murty's least-index rule) until the
  count falls below its best again.

For a P-matrix every ``F_AA`` is non-singular and the least-index rule is finite, so this
combination (the safeguarded block principal pivoting of Judice and Pires) ends at the unique
solution; the pivot budget (``max_pivots``) bounds the work, and a problem that exhausts it is
reported as not solved. For other matrices (the copositive friction cone) a pivot can meet a
singular ``F_AA`` or cycle; the attempt then stops and the problem stays unsolved.

Nothing here decides convergence: :mod:`drake_abs.lcp.ipm` turns an exact candidate into a point
on the central path at the solver's floor (:func:`central_start`) and hands it to the compiled
iterations, whose own residual test (``residual <= tol``) accepts or rejects it.

Everything runs per problem in numpy (d up to a few hundred), and only on the problems the
interior point did not solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Block pivots allowed in a row without lowering the best count of violations.
BLOCK_TRIES = 3


@dataclass(frozen=True)
class PivotResult:
    """Outcome of :func:`principal_pivoting` for one problem of size d.

    Attributes:
        lam: (d,) candidate, exact zeros off the active set (NaN where ``ok`` is False and no
            system could be solved).
        w: (d,) ``F lam + q``, with exact zeros on the active set.
        active: (d,) bool, the final active set.
        pivots: principal pivot steps taken (a block pivot counts once).
        ok: the candidate passed the sign test (no violation beyond roundoff).
    """

    lam: np.ndarray
    w: np.ndarray
    active: np.ndarray
    pivots: int
    ok: bool


def complementary_point(
    F: np.ndarray, q: np.ndarray, active: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """The complementary basic solution of the set ``active``: ``lam_A = -F_AA^-1 q_A`` (one
    step of iterative refinement), ``lam = 0`` elsewhere, ``w = F lam + q`` with ``w_A = 0``.

    Args:
        F: (d, d). q: (d,). active: (d,) bool.

    Returns:
        ``(lam, w)``, each (d,), or None when ``F_AA`` is singular or the solution not finite.
    """
    d = q.shape[0]
    lam = np.zeros(d)
    idx = np.flatnonzero(active)
    if idx.size:
        sub = F[np.ix_(idx, idx)]
        with np.errstate(all="ignore"):
            try:
                x = np.linalg.solve(sub, -q[idx])
                x -= np.linalg.solve(sub, sub @ x + q[idx])  # refinement: one more solve
            except np.linalg.LinAlgError:
                return None
        if not np.all(np.isfinite(x)):
            return None
        lam[idx] = x
    with np.errstate(all="ignore"):
        w = F @ lam + q
    if not np.all(np.isfinite(w)):
        return None
    w[idx] = 0.0
    return lam, w


def violations(
    F: np.ndarray, q: np.ndarray, lam: np.ndarray, w: np.ndarray, active: np.ndarray, eta: float
) -> np.ndarray:
    """(d,) bool: the contacts whose sign condition fails by more than roundoff.

    ``lam_i < 0`` on the active set or ``w_i < 0`` off it, each measured against the size of the
    terms in row i, ``|q_i| + (|F| |lam|)_i`` (``lam_i`` weighted by ``|F_ii|``), relative
    tolerance ``eta``.
    """
    with np.errstate(all="ignore"):
        row = np.abs(q) + np.abs(F) @ np.abs(lam)
        diag = np.abs(np.diagonal(F))
    bad_lam = active & (lam * diag < -eta * row)
    bad_w = ~active & (w < -eta * row)
    return bad_lam | bad_w


def principal_pivoting(
    F: np.ndarray, q: np.ndarray, active: np.ndarray, *, max_pivots: int, eta: float
) -> PivotResult:
    """Safeguarded block principal pivoting from the guess ``active`` (module docstring).

    Args:
        F: (d, d) LCP matrix. q: (d,). active: (d,) bool, the starting guess of ``lam > 0``.
        max_pivots: largest number of pivot steps (>= 0).
        eta: relative roundoff tolerance of the sign test (:func:`violations`).
    """
    A = np.array(active, dtype=bool)
    best = A.size + 1
    tries = BLOCK_TRIES
    lam = w = np.full(A.size, np.nan)
    for pivots in range(max_pivots + 1):
        point = complementary_point(F, q, A)
        if point is None:
            return PivotResult(lam, w, A, pivots, False)
        lam, w = point
        bad = violations(F, q, lam, w, A, eta)
        n_bad = int(bad.sum())
        if n_bad == 0:
            return PivotResult(lam, w, A, pivots, True)
        if pivots == max_pivots:
            break
        if n_bad < best:
            best, tries = n_bad, BLOCK_TRIES
            A ^= bad
        elif tries > 0:
            tries -= 1
            A ^= bad
        else:  # Murty's least-index pivot: finite for P-matrices
            A[np.flatnonzero(bad)[0]] ^= True
    return PivotResult(lam, w, A, max_pivots, False)


def active_guess(lam: np.ndarray, s: np.ndarray, D: np.ndarray) -> np.ndarray:
    """(d,) bool guess of the active set from an interior iterate ``(lam, s)`` (original units;
    any values, non-finite included) and the solver's Jacobi scale D (d,): ``lam_i > s_i`` in
    the scaled variables ``lam D`` and ``s / D``. Entries that are not finite count inactive."""
    with np.errstate(all="ignore"):
        guess = lam * D > s / D
    return guess & np.isfinite(lam) & np.isfinite(s)


def solve_by_pivoting(
    F: np.ndarray,
    q: np.ndarray,
    guesses: list[np.ndarray],
    *,
    max_pivots: int,
    eta: float,
) -> tuple[PivotResult, int]:
    """Principal pivoting from each guess (d,) bool in turn until one passes the sign test.

    Args:
        F: (d, d). q: (d,). guesses: starting active sets, tried in order (duplicates skipped).
        max_pivots: pivot budget of each attempt. eta: see :func:`violations`.

    Returns:
        The first passing :class:`PivotResult` (or the last attempt's), and the pivots spent
        over every attempt.
    """
    spent = 0
    seen: list[np.ndarray] = []
    result = None
    for guess in guesses:
        if any(np.array_equal(guess, g) for g in seen):
            continue
        seen.append(guess)
        result = principal_pivoting(F, q, guess, max_pivots=max_pivots, eta=eta)
        spent += result.pivots
        if result.ok:
            break
    assert result is not None  # at least one guess
    return result, spent


def central_start(
    lam: np.ndarray, w: np.ndarray, target: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A strictly positive point next to an exact solution ``(lam, w)`` (each (..., d), >= 0 up
    to roundoff) whose products are the targets (..., d), > 0: the larger of ``lam_i, w_i``
    kept, the other ``target_i`` divided by it; ``sqrt(target_i)`` for both where both vanish
    (degenerate contacts). For a strictly complementary solution this is the central-path
    point at ``target`` to first order."""
    lam = np.maximum(lam, 0.0)
    w = np.maximum(w, 0.0)
    root = np.sqrt(target)
    with np.errstate(all="ignore"):
        use_lam = (lam >= w) & (lam > root)
        use_w = ~use_lam & (w > root)
        lam0 = np.where(use_lam, lam, np.where(use_w, target / w, root))
        s0 = np.where(use_lam, target / lam, np.where(use_w, w, root))
    return lam0, s0
