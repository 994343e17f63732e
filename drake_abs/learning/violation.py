"""The violation-implicit loss of Bianchini et al. (2022, eq. 4) for models whose prediction is
affine in the contact impulses, batched over data points, with its gradient in the parameters.

For one data point (input x, observed output y) and parameters theta the model supplies

- the prediction ``g(lam) = g0 + D lam`` ((ny,) from nl impulses; ``g0`` and ``D`` may depend
  on theta and x), and
- each impulse's complementarity partner ``phi`` (nl,), evaluated at the *observed* output
  (e.g. the gap at the end of the step computed from the observed velocity), independent of lam.

The loss is the smallest value over lam of ::

    J(lam) = ||y - g0 - D lam||^2 + (1 / eps) h(phi, lam),
    h(phi, lam) = sum_i 1/2 neg(phi_i)^2 + 1/2 neg(lam_i)^2 + pos(phi_i) pos(lam_i),

with ``pos(a) = max(a, 0)`` and ``neg(a) = -min(a, 0)``. h is zero exactly when ``lam`` and
``phi`` are complementary (``lam >= 0``, ``phi >= 0``, ``lam_i phi_i = 0``). **A larger eps
relaxes the complementarity** (the loss trusts the prediction term more); as eps -> 0 the
loss tends to the prediction loss through the complementarity solution.

For fixed ``phi``, ``J`` is convex in ``lam``: a convex quadratic plus, per impulse, the convex
``1/2 neg(lam_i)^2 + pos(phi_i) pos(lam_i)`` (``pos(phi_i) >= 0``). It is minimised here by
exact coordinate descent (each coordinate's one-dimensional minimiser is closed-form: the
negative branch, the positive branch, or 0), which converges for such separable nonsmooth
convex terms, to ``tol`` in J's optimality conditions, helped by exact solves on the current
sign pattern; the data points still short of their minimum after ``LCP_AFTER_SWEEPS`` sweeps
are solved as a monotone LCP (by drake-abs's own interior point, at mu = 0), then exactly on
that answer's sign pattern. The loss
and its gradient are evaluated at the minimiser, and every minimiser is checked against the
optimality conditions (``converged``). By the envelope theorem the gradient of the loss in
theta is the partial derivative of ``J`` at the minimiser (``lam`` held), whatever the
minimiser's own derivative: ::

    dl/dtheta = -2 (y - g)^T (dg0/dtheta + dD/dtheta lam)
                + (1 / eps) sum_i (-neg(phi_i) + pos(lam_i) [phi_i > 0]) dphi_i/dtheta.

Shapes: batch B, outputs ny, impulses nl, parameters T.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from drake_abs.lcp.ipm import solve_lcp

#: after this many coordinate-descent sweeps, the data points not yet at their minimum are
#: solved as an LCP (:func:`_solve_as_lcp`): coordinate descent crawls where impulses act along
#: dependent directions (several generators of one friction cone, more impulses than outputs)
LCP_AFTER_SWEEPS = 40


@dataclass(frozen=True)
class ViolationLoss:
    """The violation-implicit loss of a batch.

    Attributes:
        loss: (B,) the minimum of J per data point.
        grad: (B, T) its gradient in theta (None when no parameter derivatives were given).
        lam: (B, nl) the minimising impulses.
        prediction: (B,) the prediction term ``||y - g(lam)||^2`` at the minimiser.
        violation: (B,) ``h(phi, lam)`` at the minimiser (not divided by eps).
        sweeps: coordinate-descent sweeps taken.
        converged: (B,) the minimiser met the optimality test.
    """

    loss: np.ndarray
    grad: np.ndarray | None
    lam: np.ndarray
    prediction: np.ndarray
    violation: np.ndarray
    sweeps: int
    converged: np.ndarray


def pos(a: np.ndarray) -> np.ndarray:
    """The positive part ``max(a, 0)``."""
    return np.maximum(a, 0.0)


def neg(a: np.ndarray) -> np.ndarray:
    """The negative part ``-min(a, 0)`` (>= 0)."""
    return -np.minimum(a, 0.0)


def complementarity_violation(phi: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """``h(phi, lam)`` (B,) of the module docstring, summed over the last axis: zero exactly
    for a complementary pair."""
    return np.sum(0.5 * neg(phi) ** 2 + 0.5 * neg(lam) ** 2 + pos(phi) * pos(lam), axis=-1)


def violation_loss(
    y: np.ndarray,
    g0: np.ndarray,
    D: np.ndarray,
    phi: np.ndarray,
    eps: float,
    *,
    dg0: np.ndarray | None = None,
    dD: np.ndarray | None = None,
    dphi: np.ndarray | None = None,
    tol: float = 1e-12,
    max_sweeps: int = 500,
) -> ViolationLoss:
    """The violation-implicit loss (module docstring) of a batch and, when any of ``dg0``,
    ``dD``, ``dphi`` is given, its gradient in theta.

    Args:
        y: (B, ny) observed outputs. g0: (B, ny) prediction at lam = 0. D: (B, ny, nl).
        phi: (B, nl) complementarity partners at the observed outputs.
        eps: > 0, the weight of the violation term is 1 / eps (larger eps: looser
            complementarity).
        dg0: (B, ny, T), dD: (B, ny, nl, T), dphi: (B, nl, T): derivatives in theta (absent
            ones are zero).
        tol: optimality tolerance, relative to the size of the prediction term's gradient.
        max_sweeps: coordinate-descent sweeps allowed.
    """
    y, g0, D, phi = (np.asarray(a, dtype=float) for a in (y, g0, D, phi))
    if y.ndim != 2 or g0.shape != y.shape:
        raise ValueError(f"y and g0 must both have shape (B, ny); got {y.shape} and {g0.shape}")
    B, ny = y.shape
    if D.ndim != 3 or D.shape[:2] != (B, ny):
        raise ValueError(f"D must have shape (B, ny, nl) = ({B}, {ny}, nl); got {D.shape}")
    nl = D.shape[2]
    if phi.shape != (B, nl):
        raise ValueError(f"phi must have shape (B, nl) = ({B}, {nl}); got {phi.shape}")
    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a finite number > 0; got {eps!r}")
    for name, a in (("y", y), ("g0", g0), ("D", D), ("phi", phi)):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite")
    r0 = y - g0  # residual at lam = 0
    p = pos(phi) / eps  # the linear weight of a positive impulse
    w = 1.0 / eps  # the quadratic weight of a negative impulse
    col = np.einsum("bji,bji->bi", D, D)  # ||D_i||^2
    lam = np.zeros((B, nl))
    r = r0.copy()
    scale = (1.0 + np.sqrt(col.max(axis=1))) * (1.0 + np.sqrt(np.einsum("bj,bj->b", r0, r0)))
    scale = scale + p.max(axis=1, initial=0.0)
    converged = np.zeros(B, dtype=bool)
    sweeps = 0
    todo = np.arange(B)  # the data points still sweeping (the converged ones are left alone)
    while sweeps < max_sweeps:
        sweeps += 1
        Dt, rt, lt, ct, pt = D[todo], r[todo], lam[todo], col[todo], p[todo]
        for i in range(nl):
            Di = Dt[:, :, i]
            # J along coordinate i: ||r + D_i lam_i - D_i t||^2 + branch terms in t
            c = np.einsum("bj,bj->b", Di, rt) + ct[:, i] * lt[:, i]
            with np.errstate(divide="ignore", invalid="ignore"):
                t_pos = np.where(ct[:, i] > 0, (c - 0.5 * pt[:, i]) / ct[:, i], 0.0)
                t_neg = c / (ct[:, i] + 0.5 * w)
            t = np.where(t_pos > 0, t_pos, np.where(t_neg < 0, t_neg, 0.0))
            rt -= Di * (t - lt[:, i])[:, None]
            lt[:, i] = t
        r[todo], lam[todo] = rt, lt
        converged[todo] = _optimality(Dt, rt, lt, pt, w) <= tol * scale[todo]
        if converged.all():
            break
        # the sign pattern is usually right long before the values: solve on it (every few
        # sweeps: a pattern that is not yet right fails, and each attempt costs a solve)
        if nl > 1 and (sweeps <= 4 or sweeps % 8 == 0):
            for b in np.flatnonzero(~converged):
                # on the sign pattern with the negligible impulses dropped (coordinate descent
                # leaves a zero impulse at a tiny value, whose sign is noise), else as it is
                cleaned = np.where(np.abs(lam[b]) > 1e-9 * np.abs(lam[b]).max(), lam[b], 0.0)
                for pattern in (cleaned, lam[b]):
                    polished = _solve_on_pattern(D[b], r0[b], pattern, p[b], w)
                    if polished is None:
                        continue
                    r_b = r0[b] - D[b] @ polished
                    # kept only where it is optimal (a singular pattern's least-norm point
                    # need not be, and jumping to it would undo the sweeps)
                    if (
                        _optimality(D[b : b + 1], r_b[None], polished[None], p[b : b + 1], w)[0]
                        <= tol * scale[b]
                    ):
                        lam[b], r[b] = polished, r_b
                        break
            todo = np.flatnonzero(~converged)
            converged[todo] = (
                _optimality(D[todo], r[todo], lam[todo], p[todo], w) <= tol * scale[todo]
            )
            if converged.all():
                break
        todo = np.flatnonzero(~converged)
        if sweeps == LCP_AFTER_SWEEPS and todo.size:  # slow ones: the exact LCP (docstring)
            solved = _solve_as_lcp(D[todo], r0[todo], p[todo], w)
            if solved is not None:  # to machine precision on the LCP answer's sign pattern
                for k, b in enumerate(todo):
                    big = np.abs(solved[k]) > 1e-9 * np.abs(solved[k]).max()
                    polished = _solve_on_pattern(D[b], r0[b], np.where(big, solved[k], 0.0),
                                                 p[b], w)  # fmt: skip
                    if polished is not None:
                        solved[k] = polished
                r_s = r0[todo] - np.einsum("bji,bi->bj", D[todo], solved)
                ok = _optimality(D[todo], r_s, solved, p[todo], w) <= tol * scale[todo]
                rows = todo[ok]
                lam[rows], r[rows], converged[rows] = solved[ok], r_s[ok], True
                todo = np.flatnonzero(~converged)
                if not todo.size:
                    break
    prediction = np.einsum("bj,bj->b", r, r)
    violation = complementarity_violation(phi, lam)
    loss = prediction + violation / eps
    grad = None
    if dg0 is not None or dD is not None or dphi is not None:
        T = next(a.shape[-1] for a in (dg0, dD, dphi) if a is not None)
        grad = np.zeros((B, T))
        dg = np.zeros((B, ny, T))
        if dg0 is not None:
            dg += dg0
        if dD is not None:
            dg += np.einsum("bjit,bi->bjt", dD, lam)
        grad -= 2.0 * np.einsum("bj,bjt->bt", r, dg)
        if dphi is not None:
            dh_dphi = -neg(phi) + pos(lam) * (phi > 0)
            grad += np.einsum("bi,bit->bt", dh_dphi, dphi) / eps
    return ViolationLoss(loss, grad, lam, prediction, violation, sweeps, converged)


def _optimality(D, r, lam, p, w) -> np.ndarray:
    """(B,) the largest violation of the minimum's optimality conditions over the impulses:
    with ``g_i = -2 D_i^T r`` the gradient of the prediction term, ``g_i + p_i = 0`` for a
    positive impulse, ``g_i + w lam_i = 0`` for a negative one, ``-p_i <= g_i <= 0`` at 0."""
    g = -2.0 * np.einsum("bji,bj->bi", D, r)
    res = np.where(lam > 0, np.abs(g + p), np.where(lam < 0, np.abs(g + w * lam),
                                                     np.maximum(g, 0.0) + pos(-p - g)))  # fmt: skip
    return res.max(axis=1)


def _solve_as_lcp(D, r0, p, w) -> np.ndarray | None:
    """The minimisers (B, nl) of a batch as one LCP each: with ``lam = a - b``, ``a, b >= 0``,
    J is the convex quadratic ``||r0 - D a + D b||^2 + (w / 2) ||b||^2 + p . a`` (at a
    minimiser a and b are never both positive: lowering both lowers J), whose optimality
    conditions are the monotone LCP ``z = (a, b) >= 0 _|_ H z + f >= 0`` with
    ``H = 2 A^T A + diag(0, w I)``, ``A = [D, -D]``, ``f = (-2 D^T r0 + p, 2 D^T r0)``. Solved
    exactly (mu = 0) by :func:`drake_abs.lcp.solve_lcp`; None if it fails."""
    B, _, nl = D.shape
    A = np.concatenate([D, -D], axis=2)
    H = 2.0 * np.einsum("bji,bjk->bik", A, A)
    H[:, nl:, nl:] += w * np.eye(nl)
    Dr = np.einsum("bji,bj->bi", D, r0)
    f = np.concatenate([-2.0 * Dr + p, 2.0 * Dr], axis=1)
    with warnings.catch_warnings():  # a failed solve is reported by the caller's check
        warnings.simplefilter("ignore")
        res = solve_lcp(H, f, 0.0, on_bad_matrix="attempt")
    if not np.all(np.isfinite(res.lam)):
        return None
    return res.lam[:, :nl] - res.lam[:, nl:]


def _solve_on_pattern(D, r0, lam, p, w) -> np.ndarray | None:
    """The stationary point on the sign pattern of ``lam`` (one data point), or None if it
    leaves that pattern: ``(2 D_S^T D_S + w I_N) lam_S = 2 D_S^T r0 - p_P`` over the nonzero
    impulses S (P positive, N negative), zero elsewhere."""
    S = np.flatnonzero(lam != 0)
    if not S.size:
        return None
    DS = D[:, S]
    K = 2.0 * DS.T @ DS
    rhs = 2.0 * DS.T @ r0
    negative = lam[S] < 0
    K[np.diag_indices(S.size)] += np.where(negative, w, 0.0)
    rhs -= np.where(negative, 0.0, p[S])
    # K is singular when impulses act along dependent directions (e.g. a friction cone's
    # generators at a sticking contact): the stationary points are then an affine set, every
    # one a minimiser with the same prediction; the one nearest the current impulses is taken
    x = lam[S] + np.linalg.lstsq(K, rhs - K @ lam[S], rcond=None)[0]
    if not np.allclose(K @ x, rhs, rtol=1e-10, atol=1e-12 * (1.0 + np.abs(rhs).max())):
        return None
    if np.any((x > 0) == negative) or np.any(x == 0):
        return None
    out = np.zeros_like(lam)
    out[S] = x
    return out
