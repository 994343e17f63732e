"""Implicit-function-theorem Jacobians of the softened LCP solution (docs/math.md section 4;
Zhang et al. 2023, Theorem A.3).

At a solution, ``G(lam; q, F, mu) = lam o (q + F lam) - mu = 0`` with
``K = dG/dlam = diag(s) + diag(lam) F``. Because ``K = diag(lam) (F + diag(s / lam))``,

    d lam / d q   = -K^-1 diag(lam) = -(F + diag(s / lam))^-1
    d lam / d mu  =  K^-1 = (F + diag(s / lam))^-1 diag(1 / lam)      (mu one per contact)
    d lam / d F_ij = (d lam / d q_i) lam_j

K is inverted with its rows equilibrated (see :func:`equilibrated_newton_inverse`), the same
matrix the interior-point iterations factor.

Why the solver's last factorisation is not reused: the iterations factor K at the iterate
*before* their final step, and the implicit function theorem needs K at the solution; the two
differ by the whole last step, so the old factors would give Jacobians off by that much.
Factoring K once more at the solution is the valid reuse, and that is what this module does;
doing it inside the compiled kernel instead would save only the call overhead. Measured on the
frictional box (B = 256, d = 4, total gradient mode): the inverse at the solution takes 52 to
62 us of a 1.43 ms step with Jacobians (4 %); the step without Jacobians takes 0.99 ms.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from drake_abs.lcp.ipm_kernel import gauss_jordan_inverse


def batched_inverse(M: np.ndarray) -> np.ndarray:
    """Inverse of a stack of square matrices (..., d, d), with closed forms for d = 1 and 2.

    Members that are singular to working precision get the Moore-Penrose pseudo-inverse instead
    (non-P LCP matrices can make the Newton matrix singular); callers that need a true inverse
    must check their own residuals, as the interior-point solver does.
    """
    d = M.shape[-1]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if d == 1:
            out = 1.0 / M
        elif d == 2:
            a, b = M[..., 0, 0], M[..., 0, 1]
            c, e = M[..., 1, 0], M[..., 1, 1]
            det = a * e - b * c
            out = np.empty_like(M)
            out[..., 0, 0] = e / det
            out[..., 0, 1] = -b / det
            out[..., 1, 0] = -c / det
            out[..., 1, 1] = a / det
        else:
            try:
                out = np.linalg.inv(M)
            except np.linalg.LinAlgError:
                out = np.full_like(M, np.nan)
                flat, flat_out = M.reshape(-1, d, d), out.reshape(-1, d, d)
                for i, Mi in enumerate(flat):
                    try:
                        flat_out[i] = np.linalg.inv(Mi)
                    except np.linalg.LinAlgError:
                        pass
    singular = ~np.all(np.isfinite(out), axis=(-2, -1))
    if np.any(singular):
        out[singular] = np.linalg.pinv(np.where(np.isfinite(M[singular]), M[singular], 0.0))
    return out


def implicit_jacobians(
    F: np.ndarray, lam: np.ndarray, slack: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of the softened LCP solution at a point on the central path.

    Args:
        F: (d, d) shared or (B, d, d) per problem.
        lam: impulses (B, d), strictly positive.
        slack: ``s = F lam + q`` (B, d), strictly positive.

    Returns:
        ``(dlam_dq, dlam_dmu)``, each (B, d, d); ``dlam_dmu`` is with respect to a per-contact mu
        (sum its last axis for the derivative with respect to one scalar mu).
    """
    Kinv, w = equilibrated_newton_inverse(F, lam, slack)
    dlam_dmu = Kinv * w[..., None, :]  # K^-1 = (diag(w) K)^-1 diag(w)
    return dlam_dmu * -lam[..., None, :], dlam_dmu


#: Largest d whose equilibrated inverse is compiled (Gauss-Jordan); LAPACK above.
_COMPILED_UP_TO = 32


@nb.njit(cache=True)
def _equilibrated_inverse_small(F3, shared, lam, slack):
    """``(diag(w) K)^-1`` (B, d, d) and w (B, d) for a batch of small problems (F3 (1 or B, d,
    d)) by Gauss-Jordan with partial pivoting; ``ok`` (B,) is False where the matrix is
    singular (those rows are left to the pseudo-inverse path)."""
    B, d = lam.shape
    out = np.zeros((B, d, d))
    w = np.empty((B, d))
    ok = np.ones(B, dtype=np.bool_)
    K = np.empty((d, d))
    aug = np.empty((d, 2 * d))
    for b in range(B):
        F = F3[0] if shared else F3[b]
        for i in range(d):
            w[b, i] = 1.0 / (slack[b, i] + lam[b, i])
            for j in range(d):
                K[i, j] = lam[b, i] * w[b, i] * F[i, j]
            K[i, i] += slack[b, i] * w[b, i]
        ok[b] = gauss_jordan_inverse(K, out[b], aug)
    return out, w, ok


def equilibrated_newton_inverse(
    F: np.ndarray, lam: np.ndarray, slack: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of ``diag(w) K`` with ``K = diag(s) + diag(lam) F`` and ``w = 1 / (s + lam)``.

    Row equilibration keeps every row O(1) whether a contact is far (s >> lam) or deep
    (lam >> s), so partial pivoting stays reliable when ``s / lam`` spans many decades. Returns
    ``((diag(w) K)^-1, w)``; then ``K^-1 = (diag(w) K)^-1 diag(w)``. Shapes (B, d, d), (B, d).
    """
    d = lam.shape[-1]
    if lam.ndim == 2 and d <= _COMPILED_UP_TO:  # a batch of small problems: compiled
        F3 = np.ascontiguousarray(F[None] if F.ndim == 2 else F, dtype=float)
        Kinv, w, ok = _equilibrated_inverse_small(F3, F.ndim == 2, lam, slack)
        if not ok.all():  # singular: the pseudo-inverse path below, for those rows only
            bad = ~ok
            Fb = F if F.ndim == 2 else F[bad]
            Kinv[bad] = _equilibrated_inverse_numpy(Fb, lam[bad], slack[bad], w[bad])
        return Kinv, w
    w = 1.0 / (slack + lam)
    return _equilibrated_inverse_numpy(F, lam, slack, w), w


def _equilibrated_inverse_numpy(F, lam, slack, w) -> np.ndarray:
    """``(diag(w) K)^-1`` by :func:`batched_inverse` (closed form at d = 1, pseudo-inverse
    where singular)."""
    if lam.shape[-1] == 1:  # one contact: a scalar per problem
        Fd = F[..., 0, :] if F.ndim == lam.ndim + 1 else F[0]
        with np.errstate(divide="ignore"):
            inv = 1.0 / ((slack + lam * Fd) * w)
        return np.where(np.isfinite(inv), inv, 0.0)[..., None]  # pseudo-inverse of 0 is 0
    K = F * (lam * w)[..., :, None]
    idx = np.arange(lam.shape[-1])
    K[..., idx, idx] += slack * w
    return batched_inverse(K)


def dlam_dF(dlam_dq: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """``d lam_k / d F_ij`` as an array (..., d, d, d) indexed [k, i, j], from ``dlam_dq``
    (..., d, d) and ``lam`` (..., d): perturbing F_ij acts on the solution like perturbing q_i
    by lam_j."""
    return dlam_dq[..., :, :, None] * lam[..., None, None, :]
