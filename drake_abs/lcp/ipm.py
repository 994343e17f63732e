"""Batched primal-dual interior point for the mu-softened LCP (docs/math.md section 3; Zhang et al.
2023,
Appendix B, Algorithm 3).

Solves, for every problem b of a batch and every contact i,

    lam >= 0,   s = F lam + q >= 0,   lam_i s_i = mu_i,

stopping on the requested central-path point ``mu`` rather than at an arbitrary iterate, so that
the returned solution (and its implicit-function-theorem Jacobians) is the unique mu-softened
solution. ``mu = 0`` solves the exact LCP (hard contact). **A larger mu means more smoothing.**

Algorithm (per problem; the iterations are compiled in :mod:`drake_abs.lcp.ipm_kernel`, looped over
the batch):

1. Scale: ``F' = D^-1 F D^-1`` with ``D ~ sqrt(diag F)``, and ``q' = D^-1 q / c`` with
   ``c = max |D^-1 q|`` (powers of two, so the scaling is exact). The products ``lam_i s_i`` scale
   by ``1 / c^2``; every tolerance below is relative and the scaled problem is O(1).
2. Mehrotra predictor-corrector on the infeasible-start Newton system
   ``[-F I; S Lam] [dl; ds] = -[r_p; r_c]``, reduced to ``(S + Lam F) dl = -r_c + Lam r_p`` and
   solved with the rows of ``S + Lam F`` equilibrated by ``1 / (s + lam)``.
   The centering target of each contact is ``max(sigma * mu_cur, mu_i)`` with
   ``sigma = (mu_aff / mu_cur)^3``: the duality measure is never driven below the requested mu.
3. Once a contact reaches its target, its Newton target is exactly ``mu_i`` (no second-order
   correction): pure centering steps converge quadratically onto the central-path point.
4. Step length: a fraction ``tau`` of the step to the boundary of the positive orthant, 0.995
   by default. Near the solution (the Newton step nearly full, ``a_max >= 0.9``) the fraction
   follows the gap being closed, ``1 - tau = max(mu_cur, 1e-10)``, so that the gap shrinks
   quadratically rather than at most 200x per iteration (exact solves: 13.8 -> 9.5 iterations
   on the box benchmark's problems); that longer step is kept only if it passes the tests
   below and leaves every ``lam_i s_i`` at least half its target.

Second start: a problem that does not converge from the default start (``lam = s = 1`` in
scaled units) is solved again from a start next to "every contact separating" (in scaled units
``s0 = max(q, 1e-2)``, ``lam0 = max(mu, 1e-4) / s0``: :func:`separated_start`), and that answer
replaces the first only if it converges. It costs nothing on problems that converge at once.
Found on a frictional contact at rest above the ground, whose friction rows have q = 0: the
exact answer is lam = 0 with every friction slack 0 (degenerate), and from the default start
the iterates drift along the cone's unbounded direction; from the separated start it converges
in 4 to 8 iterations for every mu. The iterations reported are those of both starts.

Crossover (docs/math.md section 3b): a problem that still does not converge (the interior
point stalled or diverged, as on Csizmadia's P-matrices at d >= 32, whose handicap is
exponential in d) goes through :mod:`drake_abs.lcp.pivoting`: the active set is guessed from
its last iterate (then from ``q < 0``), corrected by principal pivots to an exact solution of
the mu = 0 LCP, and the compiled iterations are run again from a point next to it whose products
are the requested targets. Where principal pivoting fails (a singular ``F_AA`` or cycling, as on
the copositive friction matrices), Lemke's method (:mod:`drake_abs.lcp.lemke`) supplies the
active set instead. That answer replaces the old one only if it passes the same test below;
``result.pivots`` and ``result.polished`` report it. At mu = 0 this finishes P-matrix problems
whatever their conditioning (pivoting is finite for P-matrices; the pivot budget
``PIVOTS_PER_CONTACT d + PIVOTS_EXTRA`` bounds the work), and Stewart-Trinkle friction problems
that the interior point leaves (on gymnasium's HalfCheetah, 55 of 55 such steps in a test run:
cond(F) near 1e17, the symmetric part indefinite), and degenerate problems that only the
lexicographic rule of Lemke's method finishes (the 40-row bimatrix game ``tobenna`` of the
Siconos LCP collection, on which Drake 1.58's MobyLcpSolver reports success with ``w_i = -1``). An
exact LCP whose solution has no interior point next to it (Pang's isolated-solution problem,
d = 3, neither monotone nor P: no positive iterate can pass the test below) is answered by the
crossover's exact vertex itself when the test passes there (:func:`_check_vertices`): its
``lam`` and ``slack`` then hold exact zeros. At mu > 0 the exact solution is only a start for
the centring steps to mu (a vertex never passes): attempted, verified, often not enough (it is
measured in ``benchmarks/bench_lcp.py``). It costs nothing on problems that converge.

Safeguards: steps keep the contacts still driving down in the wide neighbourhood
``lam_i s_i >= 1e-3 mean`` (backtracking), and a problem whose duality measure stalls drops the
second-order correction, which otherwise can cycle. A problem not known to be monotone (the
friction cone, ``on_bad_matrix="attempt"``) then also backtracks its Newton steps on the residual
norm (Armijo), since near a fold of a non-monotone central path full steps can cycle.
Known limit, measured on 4000 random positive-definite problems (d = 2, eigenvalues scaled over
1e-3..1e3, q standard normal, mu = 0 and 1e-6): from the default start alone, 0.7 to 0.9 % fail
at cond(F) = 1e8 and 1.9 to 2.4 % at 1e10 (cycling along F's near-null direction); with the
second starts none fail at 1e8 and 0.02 % (1 in 5000) at 1e10, reported as not converged.

Convergence of a problem means ``residual <= tol`` where, in the scaled variables::

    residual = max( max_i |s_i - (F lam)_i - q_i| / (|q_i| + |s_i| + (|F| |lam|)_i),
                    max_i |lam_i s_i - mu_i| / (mu_i + gap_atol_i / tol) )

The first term is the backward error of each row (relative to the size of the terms summed in
it, so that one diverging contact cannot hide another's residual); the second says
``|lam_i s_i - mu_i| <= tol mu_i + gap_atol_i``. The absolute part is what double precision
resolves: ``gap_atol_i = exact_tol^2 + 1e-13 max {mu_j : F_ij != 0 or F_ji != 0, j != i}`` (scaled
units), i.e. the exact floor plus the roundoff that a contact held at a large mu_j couples into
contact i through F (zero for contacts F does not couple). For ``mu = 0`` (exact contact) it is
the complementarity tolerance; targets below the floor ``(exact_tol * c)^2`` (original units)
are raised to it and ``result.mu_target`` reports the raised value.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass
from typing import Literal

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.lcp.ipm_kernel import solve
from drake_abs.lcp.lemke import lemke_active_set
from drake_abs.lcp.matrix_class import MatrixClass, classify_matrix
from drake_abs.lcp.pivoting import active_guess, central_start, solve_by_pivoting
from drake_abs.lcp.sensitivity import implicit_jacobians
from drake_abs.lcp.status import LCPStatus

OnBadMatrix = Literal["raise", "regularize", "attempt", "trusted"]


class LCPConvergenceWarning(UserWarning):
    """Some problems of a batch stopped before meeting the tolerance (non-strict mode)."""


class LCPConvergenceError(RuntimeError):
    """Some problems of a batch stopped before meeting the tolerance (strict mode)."""


class LCPRegularizationWarning(UserWarning):
    """F was regularised before solving; the message says by how much."""


@dataclass(frozen=True)
class LCPResult:
    """Solution of a (batch of) softened LCP(s).

    Shapes are for a batch of B problems with d contacts; for a single problem the leading B
    axis is absent. Units: ``lam`` in the units of F^-1 q (impulses for contact problems),
    ``slack`` in the units of q.

    Attributes:
        lam: (B, d) contact variables, > 0; >= 0 with exact zeros only in an exact (mu = 0)
            answer that is the crossover's vertex (a ``polished`` problem whose LCP has no
            interior point next to its solution, ``ipm._check_vertices``).
        slack: (B, d) ``s = F lam + q`` as carried by the solver (primal residual within tol);
            > 0, with the same exception as ``lam``.
        mu: (B, d) central-path value reached, ``lam * slack`` per contact.
        mu_target: (B, d) central-path value requested (after the exact floor was applied).
        iterations: (B,) interior-point iterations taken.
        converged: (B,) True exactly when ``residual <= tol``.
        status: (B,) :class:`LCPStatus` codes.
        residual: (B,) the convergence measure of the module docstring.
        regularization: (B,) ``delta`` added to F's diagonal (``F + delta I``), 0 if none.
        matrix_class: (B,) :class:`~drake_abs.lcp.matrix_class.MatrixClass` codes, or -1 when the
            check was skipped (``on_bad_matrix="attempt"``).
        pivots: (B,) principal pivot steps of the crossover (0 where it did not run; see
            :mod:`drake_abs.lcp.pivoting`).
        polished: (B,) True where the answer came from the crossover (the interior point alone
            did not converge); such an answer passed the same residual test as any other.
        dlam_dq: (B, d, d) implicit Jacobian, or None unless ``jacobians=True``. It does not
            exist at a vertex answer with a contact where ``lam_i = slack_i = 0``: such a
            problem gets NaN Jacobians and is flagged ``NUMERICAL_FAILURE``.
        dlam_dmu: derivative with respect to mu in the form it was given: (B, d) for a scalar or
            one-per-problem mu, (B, d, d) for one mu per contact; None unless ``jacobians=True``.
            Derivatives are of the requested target; for ``mu`` below the exact floor the
            floor is what was solved.
    """

    lam: np.ndarray
    slack: np.ndarray
    mu: np.ndarray
    mu_target: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    status: np.ndarray
    residual: np.ndarray
    regularization: np.ndarray
    matrix_class: np.ndarray
    pivots: np.ndarray
    polished: np.ndarray
    dlam_dq: np.ndarray | None = None
    dlam_dmu: np.ndarray | None = None
    tol: float = 1e-12


def _normalise_mu(mu, B: int, d: int, single: bool) -> tuple[np.ndarray, str]:
    arr = as_finite_array(mu, "mu", ndim=(0, 1, 2))
    if np.any(arr < 0):
        raise ValueError("mu must be >= 0 (0 is the exact LCP; larger mu is more smoothing)")
    if arr.ndim == 0:
        return np.full((B, d), float(arr)), "scalar"
    if single:
        if arr.shape != (d,):
            raise ValueError(
                f"mu for a single problem must be a scalar or one per contact, shape (d,) = "
                f"({d},); got {arr.shape}"
            )
        return arr[None, :].copy(), "per_contact"
    if arr.ndim == 1:
        if arr.shape != (B,):
            raise ValueError(
                f"mu for a batch must be a scalar, one per problem (B,) = ({B},), or one per "
                f"contact (B, d) = ({B}, {d}); got {arr.shape}"
            )
        return np.repeat(arr[:, None], d, axis=1), "per_problem"
    if arr.shape != (B, d):
        raise ValueError(
            f"mu for a batch must be a scalar, one per problem (B,) = ({B},), or one per contact "
            f"(B, d) = ({B}, {d}); got {arr.shape}"
        )
    return arr.copy(), "per_contact"


def apply_matrix_policy(
    F: np.ndarray, on_bad_matrix: OnBadMatrix, B: int = 1
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Classify F ((d, d) or (B, d, d)) and apply the ``on_bad_matrix`` policy of
    :func:`solve_lcp`; returns (F, possibly regularised; delta (B,); classes (B,))."""
    shared = F.ndim == 2
    if on_bad_matrix == "attempt":
        return F, np.zeros(B), np.full(B, -1, dtype=np.int8)
    if on_bad_matrix == "trusted":  # the caller verified F (e.g. LCS at construction)
        return F, np.zeros(B), np.full(B, MatrixClass.PSD, dtype=np.int8)
    classes, min_eig = classify_matrix(F)
    # Only a matrix shown not to be P is refused or regularised. One that could be neither
    # shown P nor shown not P (UNVERIFIED: d > 10, indefinite symmetric part, no cheap
    # certificate) is attempted as a possibly non-monotone LCP, and its answers are verified
    # like every other (module docstring): a P-matrix of any size is never refused.
    bad = classes == MatrixClass.NOT_P
    delta = np.zeros(classes.shape)
    if np.any(bad):
        worst = float(np.min(np.where(bad, min_eig, np.inf)))
        if on_bad_matrix == "raise":
            raise ValueError(
                "F must be positive semidefinite or a P-matrix: the symmetric part of F has "
                f"smallest eigenvalue {worst:.3e} and F has a non-positive principal minor (not "
                "a P-matrix). Pass on_bad_matrix='regularize' to add a multiple of the "
                "identity, or 'attempt' to try anyway with convergence reported per problem."
            )
        # regularise: make the symmetric part positive definite with a small margin.
        scale = np.max(np.abs(F), axis=(-2, -1))
        delta = np.where(bad, -min_eig + 1e-8 * np.maximum(scale, 1.0), 0.0)
        F = F + delta[..., None, None] * np.eye(F.shape[-1])
        warnings.warn(
            f"F is neither positive semidefinite nor a P-matrix in {int(np.sum(bad))} "
            f"problem(s); regularised to F + delta I with delta up to {float(np.max(delta)):.3e} "
            f"(smallest symmetric-part eigenvalue was {worst:.3e})",
            LCPRegularizationWarning,
            stacklevel=3,
        )
    if shared:
        return F, np.full(B, float(delta)), np.full(B, int(classes), dtype=np.int8)
    return F, delta, classes.astype(np.int8)


#: The solver options' defaults (see :func:`solve_lcp`).
#: Whether a problem that did not converge from the default start is solved again from the
#: separated start (:func:`separated_start`). On by default; benchmarks turn it off to measure
#: the default start alone.
SECOND_START = True

#: Whether problems that the interior point (with its second starts) did not solve go through the
#: crossover of :func:`_crossover` (principal pivoting, :mod:`drake_abs.lcp.pivoting`). On by
#: default; benchmarks and tests turn it off to measure the interior point alone. It runs only
#: with ``SECOND_START``: turning the second starts off measures the default start alone.
POLISH = True
#: Pivot budget of each crossover attempt, ``PIVOTS_PER_CONTACT * d + PIVOTS_EXTRA``.
PIVOTS_PER_CONTACT = 4
PIVOTS_EXTRA = 20
#: Relative roundoff allowed in the crossover's sign test, per contact (times d, times eps).
SIGN_TEST_ULPS = 8.0

SOLVER_DEFAULTS = {"tol": 1e-12, "max_iterations": 100, "exact_tol": 1e-15}


def check_solver_options(tol: float, max_iterations: int, exact_tol: float) -> None:
    """Raise ``ValueError`` naming the option unless tol > 0, max_iterations >= 1 (an integer)
    and 0 < exact_tol < 1."""
    if not (np.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a positive finite number; got {tol!r}")
    if not isinstance(max_iterations, int | np.integer) or max_iterations < 1:
        raise ValueError(f"max_iterations must be an integer >= 1; got {max_iterations!r}")
    if not (np.isfinite(exact_tol) and 0 < exact_tol < 1):
        raise ValueError(f"exact_tol must be a finite number in (0, 1); got {exact_tol!r}")


def solve_lcp(
    F,
    q,
    mu=0.0,
    *,
    jacobians: bool = False,
    tol: float = SOLVER_DEFAULTS["tol"],
    max_iterations: int = SOLVER_DEFAULTS["max_iterations"],
    exact_tol: float = SOLVER_DEFAULTS["exact_tol"],
    strict: bool = False,
    on_bad_matrix: OnBadMatrix = "raise",
    warm_start: tuple[np.ndarray, np.ndarray] | None = None,
) -> LCPResult:
    """Solve the mu-softened LCP ``lam >= 0, s = F lam + q >= 0, lam_i s_i = mu_i``.

    Args:
        F: (d, d), shared by the batch, or (B, d, d), one per problem.
        q: (d,) for one problem or (B, d) for a batch of B.
        mu: central-path value, >= 0; **larger is smoother** and 0 is the exact LCP. A scalar,
            one per problem (B,), or one per contact: (d,) for one problem, (B, d) for a batch.
        jacobians: also return ``dlam_dq`` and ``dlam_dmu`` (docs/math.md section 4).
        tol: relative tolerance on each row's primal residual and on ``lam_i s_i`` against
            ``mu_i`` (see the module docstring for the exact measure).
        max_iterations: iteration limit of each start (the default start, the second starts
            and the crossover's check run each get it); problems that fail every start are
            flagged, not hidden.
        exact_tol: relative accuracy of exact contacts: targets are floored at
            ``(exact_tol * c)^2`` with ``c = max|q_i| / sqrt(F_ii)`` (see the module docstring).
        strict: raise :class:`LCPConvergenceError` instead of warning when a problem does not
            converge.
        on_bad_matrix: what to do when F is shown not to be a P-matrix (and is not PSD; see
            :mod:`~drake_abs.lcp.matrix_class`): ``"raise"`` a ``ValueError``, ``"regularize"``
            (add ``delta I`` and warn with delta), ``"attempt"`` (skip the check and solve as a
            possibly non-monotone LCP; convergence is still reported honestly), or
            ``"trusted"`` (skip the check: the caller has verified that F is PSD or a
            P-matrix, as :class:`~drake_abs.LCS` does once). A matrix that is neither shown P
            nor shown not P (``MatrixClass.UNVERIFIED``, d > 10) is attempted under every
            policy but ``"trusted"``, with its answers verified.
        warm_start: optional ``(lam0, s0)`` of the same shape as q, strictly positive.

    Returns:
        :class:`LCPResult`. A problem whose iterate became non-finite keeps its last finite
        iterate and is flagged ``NUMERICAL_FAILURE``; so is one whose solution is not
        representable in the original units (its entries may then be inf or 0, with
        ``converged = False`` and ``residual = inf``).
    """
    check_solver_options(tol, max_iterations, exact_tol)
    if on_bad_matrix not in ("raise", "regularize", "attempt", "trusted"):
        raise ValueError(
            "on_bad_matrix must be 'raise', 'regularize', 'attempt' or 'trusted'; "
            f"got {on_bad_matrix!r}"
        )
    q = as_finite_array(q, "q", ndim=(1, 2))
    single = q.ndim == 1
    Q = q[None, :] if single else q
    B, d = Q.shape
    if d == 0:
        raise ValueError("q must have at least one contact (shape (d,) or (B, d) with d >= 1)")
    F = as_finite_array(F, "F", ndim=(2, 3))
    if F.ndim == 2:
        if F.shape != (d, d):
            raise ValueError(f"F must have shape (d, d) = ({d}, {d}) to match q; got {F.shape}")
    else:
        if single:
            raise ValueError(
                f"F of shape {F.shape} is a batch, but q of shape {q.shape} is one problem; "
                "pass q as (B, d)"
            )
        if F.shape != (B, d, d):
            raise ValueError(
                f"F must have shape (d, d) or (B, d, d) = ({B}, {d}, {d}); got {F.shape}"
            )
    mu_full, mu_form = _normalise_mu(mu, B, d, single)
    F, delta, classes = apply_matrix_policy(F, on_bad_matrix, B)
    monotone = (classes == MatrixClass.PSD) | (classes == MatrixClass.P_MATRIX) | (delta > 0)

    lam0 = s0 = None
    if warm_start is not None:
        lam0 = as_finite_array(warm_start[0], "warm_start[0]")
        s0 = as_finite_array(warm_start[1], "warm_start[1]")
        for name, arr in (("warm_start[0]", lam0), ("warm_start[1]", s0)):
            if arr.shape != q.shape:
                raise ValueError(f"{name} must have the shape of q, {q.shape}; got {arr.shape}")
        lam0, s0 = lam0.reshape(Q.shape), s0.reshape(Q.shape)
        if np.any(lam0 <= 0) or np.any(s0 <= 0):
            raise ValueError("warm_start (lam0, s0) must be strictly positive")
    result = _solve(
        F, Q, mu_full, monotone, jacobians=jacobians, tol=tol, max_iterations=max_iterations,
        exact_tol=exact_tol, strict=strict, per_contact_mu=mu_form == "per_contact",
        regularization=np.broadcast_to(delta, (B,)).copy(), matrix_class=classes,
        warm_start=None if lam0 is None else (lam0, s0),
    )  # fmt: skip
    return _squeeze(result) if single else result


def solve_lcp_trusted(
    F: np.ndarray,
    q: np.ndarray,
    mu: np.ndarray,
    *,
    jacobians: bool = False,
    tol: float = SOLVER_DEFAULTS["tol"],
    max_iterations: int = SOLVER_DEFAULTS["max_iterations"],
    exact_tol: float = SOLVER_DEFAULTS["exact_tol"],
    strict: bool = False,
    monotone: bool = False,
) -> LCPResult:
    """:func:`solve_lcp` for callers inside the package whose arrays are already in the batch
    form: F (d, d) shared or (B, d, d), q (B, d) and mu (B, d) (one per contact, >= 0),
    float64, finite, with options already validated (the LCS and rigid-body steps, every time
    step). No shape, finiteness or matrix check is made. F is treated as possibly non-monotone
    (as ``on_bad_matrix="attempt"``) unless ``monotone`` says the caller has verified it is PSD
    or a P-matrix (as :class:`~drake_abs.LCS` does once, ``on_bad_matrix="trusted"``): the same
    iterations, flags and warnings as :func:`solve_lcp`, without its per-call checks.
    ``dlam_dmu`` is (B, d, d)."""
    B = q.shape[0]
    matrix_class = MatrixClass.PSD if monotone else -1
    return _solve(
        F, q, mu, np.full(B, monotone), jacobians=jacobians, tol=tol,
        max_iterations=max_iterations, exact_tol=exact_tol, strict=strict, per_contact_mu=True,
        regularization=np.zeros(B), matrix_class=np.full(B, matrix_class, dtype=np.int8),
        warm_start=None,
    )  # fmt: skip


def _solve(
    F, Q, mu_full, monotone, *, jacobians, tol, max_iterations, exact_tol, strict,
    per_contact_mu, regularization, matrix_class, warm_start,
) -> LCPResult:  # fmt: skip
    """The solve proper, on validated batch arrays: F (d, d) shared or (B, d, d), Q (B, d),
    mu_full (B, d), monotone (B,)."""
    B = Q.shape[0]
    shared = F.ndim == 2
    F3 = np.ascontiguousarray(F[None] if shared else F)
    warm = warm_start is not None
    lam0, s0 = warm_start if warm else (Q, Q)  # unused placeholders unless warm-started
    # scaling, iterations and unscaling in one compiled call. A solution the scaled iterations
    # found can still over- or underflow in original units (|q| near 1e155, F_ii near 1e-320):
    # such problems come back with finite = False and are flagged, never passed as valid.
    Q = np.ascontiguousarray(Q)
    mu_full = np.ascontiguousarray(mu_full)
    monotone = np.ascontiguousarray(monotone)
    out = solve(F3, shared, Q, mu_full, exact_tol, float(tol), int(max_iterations), monotone,
                np.ascontiguousarray(lam0), np.ascontiguousarray(s0), warm)  # fmt: skip
    status, iterations, residual, lam_out, s_out, mu_out, mu_target, finite = out
    for retry in _RETRIES if SECOND_START else ():  # kept only where they converge (docstring)
        failed = np.flatnonzero(status != LCPStatus.CONVERGED)
        if not failed.size:
            break
        sub_F = F3 if shared else F3[failed]
        args = (sub_F, shared, Q[failed], mu_full[failed], exact_tol, float(tol))
        lam_r, s_r, spent = retry(*args, int(max_iterations), monotone[failed])
        again = solve(*args, int(max_iterations), monotone[failed], lam_r, s_r, True)
        took = again[0] == LCPStatus.CONVERGED
        total = iterations[failed] + spent + again[1]  # the work of every start
        for arr, new in zip(out, again, strict=True):
            arr[failed[took]] = new[took]
        iterations[failed] = total
    pivots = np.zeros(B, dtype=np.int64)
    polished = np.zeros(B, dtype=bool)
    if SECOND_START and POLISH:  # the crossover is a retry too: off with the second starts
        _crossover(F3, shared, Q, mu_full, exact_tol, float(tol), int(max_iterations), monotone,
                   out, pivots, polished)  # fmt: skip
    dlam_dq = dlam_dmu = None
    if jacobians:
        # A contact with lam_i = s_i = 0 (a degenerate vertex answer, :func:`_check_vertices`)
        # gives K a zero row: the Jacobians do not exist there. Such problems get NaN Jacobians,
        # so the check below flags them, and a stand-in point keeps the division out of K.
        undefined = np.any(lam_out + s_out <= 0.0, axis=1)
        lam_j, s_j = lam_out, s_out
        if undefined.any():
            lam_j, s_j = lam_out.copy(), s_out.copy()
            lam_j[undefined] = s_j[undefined] = 1.0
        with np.errstate(all="ignore"):
            dlam_dq, dlam_dmu_pc = implicit_jacobians(F, lam_j, s_j)
        dlam_dq[undefined] = dlam_dmu_pc[undefined] = np.nan
        dlam_dmu = dlam_dmu_pc if per_contact_mu else dlam_dmu_pc.sum(axis=-1)
        for arr in (dlam_dq, dlam_dmu):  # per problem (an explicit width: B may be 0)
            finite &= np.all(np.isfinite(arr.reshape(B, math.prod(arr.shape[1:]))), axis=1)
    if not finite.all():
        status[~finite] = LCPStatus.NUMERICAL_FAILURE
        residual[~finite] = np.inf
    converged = status == LCPStatus.CONVERGED
    result = LCPResult(
        lam=lam_out,
        slack=s_out,
        mu=mu_out,
        mu_target=mu_target,
        iterations=iterations,
        converged=converged,
        status=status,
        residual=residual,
        regularization=regularization,
        matrix_class=matrix_class,
        pivots=pivots,
        polished=polished,
        dlam_dq=dlam_dq,
        dlam_dmu=dlam_dmu,
        tol=tol,
    )
    _report(result, strict, max_iterations)
    return result


def separated_start(F3, shared: bool, Q, mu) -> tuple[np.ndarray, np.ndarray]:
    """The retry's starting point ``(lam0, s0)`` (original units) for the problems Q (B, d):
    every contact separating. In the kernel's scaled units (the same power-of-two D and c),
    ``s0 = max(q, 1e-2)`` and ``lam0 = max(mu, 1e-4) / s0``. Problems the default start
    (``lam = s = 1``) loses, such as a frictional contact at rest above the ground (its friction
    rows' q = 0: degenerate, and the iterates drift along the cone's unbounded direction), start
    here next to the answer."""
    D, qs, c = _scales(F3, shared, Q)
    s0 = np.maximum(qs, 1e-2)
    with np.errstate(over="ignore"):
        lam0 = np.maximum(mu / c**2, 1e-4) / s0
    return np.ascontiguousarray(lam0 * c / D), np.ascontiguousarray(s0 * D * c)


def _scales(F3, shared: bool, Q) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's scaling (module docstring, step 1): D (B, d), the scaled q (B, d) and c
    (B, 1), powers of two."""
    diag = np.diagonal(F3, axis1=-2, axis2=-1)
    D = np.where(diag > 0, np.exp2(np.round(0.5 * np.log2(np.where(diag > 0, diag, 1.0)))), 1.0)
    D = np.broadcast_to(D[0] if shared else D, Q.shape)
    qs = Q / D
    top = np.abs(qs).max(axis=1, keepdims=True)
    c = np.where(top > 0, np.exp2(np.round(np.log2(np.where(top > 0, top, 1.0)))), 1.0)
    return D, qs / c, c


def _separated_retry(F3, shared, Q, mu, exact_tol, tol, max_iterations, monotone):
    lam0, s0 = separated_start(F3, shared, Q, mu)
    return lam0, s0, np.zeros(Q.shape[0], dtype=np.int64)


def _continuation_retry(F3, shared, Q, mu, exact_tol, tol, max_iterations, monotone):
    """Start from the iterate of the same problems solved at a larger mu: 100 times the target,
    and at least 1e-4 in the kernel's scaled units (where the central path is smooth and the
    default start finds it); the iterate is used whether or not that solve converged."""
    _, _, c = _scales(F3, shared, Q)
    mu_big = np.maximum(100.0 * mu, 1e-4 * c**2)
    out = solve(F3, shared, Q, mu_big, exact_tol, tol, max_iterations, monotone, Q, Q, False)
    lam, s = out[3], out[4]
    bad = ~np.all(np.isfinite(lam) & np.isfinite(s) & (lam > 0) & (s > 0), axis=1)
    if bad.any():  # no usable iterate: the separated start instead
        lam[bad], s[bad] = (a[bad] for a in separated_start(F3, shared, Q, mu))
    return np.ascontiguousarray(lam), np.ascontiguousarray(s), out[1]


_RETRIES = (_separated_retry, _continuation_retry)


def _crossover(F3, shared, Q, mu_full, exact_tol, tol, max_iterations, monotone, out, pivots,
               polished) -> None:  # fmt: skip
    """Crossover for the problems of ``out`` (the kernel's output tuple, updated in place) that
    did not converge (docs/math.md section 3b).

    For each: guess the active set from its last iterate (and, failing that, from ``q < 0``),
    correct it by principal pivoting to an exact solution of the mu = 0 LCP
    (:func:`~drake_abs.lcp.pivoting.solve_by_pivoting`), place a strictly positive point next to
    it whose products are the requested targets (:func:`~drake_abs.lcp.pivoting.central_start`)
    and run the compiled iterations from there. The answer replaces the old one only if those
    iterations meet the usual test ``residual <= tol``: for mu = 0 that is a check of the exact
    solution at the exact floor (0 iterations when it passes at once); for mu > 0 the exact
    solution is only a starting point for the centring steps to mu, attempted and verified the
    same way. The problems still unsolved then get a second candidate, from the active set where
    Lemke's method ends (:func:`~drake_abs.lcp.lemke.lemke_active_set`), verified the same way.
    ``pivots`` (B,) receives the pivot steps spent, ``polished`` (B,) marks answers that were
    replaced.
    """
    status = out[0]
    d = Q.shape[1]
    budget = PIVOTS_PER_CONTACT * d + PIVOTS_EXTRA
    eta = SIGN_TEST_ULPS * d * np.finfo(float).eps

    def principal(b, k, D):
        guesses = [active_guess(out[3][b], out[4][b], D[k]), Q[b] < 0]
        return solve_by_pivoting(F3[0] if shared else F3[b], Q[b], guesses, max_pivots=budget,
                                 eta=eta)  # fmt: skip

    def lemke(b, k, D):
        Fb = F3[0] if shared else F3[b]
        guess, spent = lemke_active_set(Fb, Q[b], max_pivots=budget)
        if guess is None:
            return None, spent
        found, more = solve_by_pivoting(Fb, Q[b], [guess], max_pivots=budget, eta=eta)
        return found, spent + more

    for candidate in (principal, lemke):
        failed = np.flatnonzero(status != LCPStatus.CONVERGED)
        if not failed.size:
            return
        D, _, _ = _scales(F3 if shared else F3[failed], shared, Q[failed])
        rows, starts, vertices, only_vertex = [], [], [], []
        for k, b in enumerate(failed):
            found, spent = candidate(b, k, D)
            pivots[b] += spent
            if found is None or not found.ok:
                continue
            lam0, s0 = central_start(found.lam, found.w, out[6][b])
            vertex = (np.maximum(found.lam, 0.0), np.maximum(found.w, 0.0))
            if np.all(np.isfinite(lam0) & np.isfinite(s0) & (lam0 > 0) & (s0 > 0)):
                rows.append(b)
                starts.append((lam0, s0))
                vertices.append(vertex)
            else:  # no usable start next to it (under- or overflow): the vertex alone
                only_vertex.append((b, vertex))
        if rows:
            _verify(F3, shared, Q, mu_full, exact_tol, tol, max_iterations, monotone, out,
                    polished, np.asarray(rows), starts, vertices)  # fmt: skip
        if only_vertex:
            _check_vertices(F3, shared, Q, mu_full, exact_tol, tol, out, polished,
                            np.asarray([b for b, _ in only_vertex]),
                            [v for _, v in only_vertex])  # fmt: skip


def _verify(F3, shared, Q, mu_full, exact_tol, tol, max_iterations, monotone, out, polished,
            rows, starts, vertices) -> None:  # fmt: skip
    """Run the compiled iterations on the problems ``rows`` from ``starts`` ((lam0, s0) each);
    an answer that converges replaces the one in ``out`` and is marked ``polished``.

    A problem whose iterations do not converge from its start is then checked at its exact
    vertex itself (``vertices``: (lam, w) each, ``lam_i w_i = 0``, exact zeros allowed): the
    compiled residual test with no iteration (:func:`_check_vertices`)."""
    lam0 = np.ascontiguousarray(np.stack([a for a, _ in starts]))
    s0 = np.ascontiguousarray(np.stack([b for _, b in starts]))
    sub_F = F3 if shared else F3[rows]
    again = solve(sub_F, shared, np.ascontiguousarray(Q[rows]),
                  np.ascontiguousarray(mu_full[rows]), exact_tol, tol, max_iterations,
                  np.ascontiguousarray(monotone[rows]), lam0, s0, True)  # fmt: skip
    took = (again[0] == LCPStatus.CONVERGED) & again[7]
    total = out[1][rows] + again[1]
    for arr, new in zip(out, again, strict=True):
        arr[rows[took]] = new[took]
    out[1][rows] = total
    polished[rows[took]] = True
    left = np.flatnonzero(~took)
    if left.size:
        _check_vertices(F3, shared, Q, mu_full, exact_tol, tol, out, polished, rows[left],
                        [vertices[k] for k in left])  # fmt: skip


def _check_vertices(F3, shared, Q, mu_full, exact_tol, tol, out, polished, rows,
                    vertices) -> None:  # fmt: skip
    """Accept an exact vertex ``(lam, w)`` of the crossover as the answer of problem ``rows[k]``
    when it passes the solver's own test, ``residual <= tol`` of the module docstring, evaluated
    by the compiled kernel at that point with no iteration.

    This is for the exact LCPs that have no interior point next to their solution, so that no
    strictly positive iterate can pass the test: Pang's isolated-solution problem (Siconos LCP
    collection, d = 3: ``F = [[0, -1, -1], [1, 0, 0], [-1, 0, 0]], q = (0, -1, 1)``, unique
    solution ``lam = (1, 0, 0), w = 0``), whose first row ``w_1 = -lam_2 - lam_3`` forces
    ``lam_2 = lam_3 = w_1 = 0`` exactly: at any positive point the row's backward error is 1.
    At the vertex the row residuals are roundoff and every ``lam_i w_i = 0``, which the test
    accepts only when every target is at the exact floor (``|0 - mu_i| <= tol mu_i + gap_atol_i``
    holds for ``mu_i = exact_tol^2`` and fails for any requested mu above it): a smoothed
    (mu > 0) problem is never answered by a vertex. Such an answer has exact zeros in ``lam``
    and ``slack`` (and ``mu = 0``); at a contact where both vanish the implicit Jacobians do not
    exist, and a solve with ``jacobians=True`` flags that problem ``NUMERICAL_FAILURE``."""
    lam0 = np.ascontiguousarray(np.stack([a for a, _ in vertices]))
    s0 = np.ascontiguousarray(np.stack([b for _, b in vertices]))
    sub_F = F3 if shared else F3[rows]
    monotone = np.zeros(rows.size, dtype=bool)  # unused: no iteration is taken
    check = solve(sub_F, shared, np.ascontiguousarray(Q[rows]),
                  np.ascontiguousarray(mu_full[rows]), exact_tol, tol, 0, monotone, lam0, s0,
                  True)  # fmt: skip
    lam, s, prod, target = check[3], check[4], check[5], check[6]
    representable = np.all(
        np.isfinite(lam) & np.isfinite(s) & np.isfinite(prod) & np.isfinite(target)
        & (lam >= 0) & (s >= 0), axis=1,
    )  # fmt: skip
    took = (check[0] == LCPStatus.CONVERGED) & representable
    check[7][:] = representable  # the kernel's flag asks for lam, s > 0: zeros are exact here
    for k, (arr, new) in enumerate(zip(out, check, strict=True)):
        if k != 1:  # out[1] is the iterations: the vertex check takes none
            arr[rows[took]] = new[took]
    polished[rows[took]] = True


def _report(result: LCPResult, strict: bool, max_iterations: int) -> None:
    if result.converged.all():
        return
    bad = ~result.converged
    n_fail = int(np.sum(result.status == LCPStatus.NUMERICAL_FAILURE))
    msg = (
        f"{int(bad.sum())} of {bad.size} LCP solve(s) did not converge: worst residual "
        f"{float(np.max(result.residual[bad])):.3e} against tol {result.tol:.1e} "
        f"({int(bad.sum()) - n_fail} hit max_iterations = {max_iterations}, {n_fail} numerical "
        "failure(s)); their `converged` flags are False"
    )
    if strict:
        raise LCPConvergenceError(msg)
    warnings.warn(msg, LCPConvergenceWarning, stacklevel=4)


def _squeeze(r: LCPResult) -> LCPResult:
    """The single-problem view: every per-problem field without its leading batch axis."""
    fields = {f.name: getattr(r, f.name) for f in dataclasses.fields(r) if f.name != "tol"}
    return dataclasses.replace(r, **{k: None if v is None else v[0] for k, v in fields.items()})
