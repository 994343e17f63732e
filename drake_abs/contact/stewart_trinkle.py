"""The Stewart-Trinkle formulation of the rigid-body contact step (docs/math.md sections 6 and
6b; the papers' equations): the normal, tangent and cone rows of a friction cone as one LCP.

The rows of a :class:`~drake_abs.contact.cone.FrictionCone` give ``s = F lam + z`` in
``lam = (gamma, beta, omega)``, with F (B, d, d) and z (B, d) as in the docstring of
:mod:`drake_abs.contact.contact_lcp`: assembled (:func:`assemble_lcp`), then smoothed, solved
(with the exact fallback), integrated and differentiated (:func:`stewart_trinkle_step`).

With friction F is copositive but not P (solved without the P-matrix check). A frictionless cone
leaves the normal rows alone, ``F = h Jn W Jn^T`` (positive semidefinite: a monotone LCP); the
Anitescu formulation (:mod:`drake_abs.contact.anitescu`) solves its generator rows so.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from drake_abs.contact.compliance import SoftRows
from drake_abs.contact.cone import PINNED_STIFFNESS, FrictionCone, expand_mu
from drake_abs.contact.lcs import GradientMode
from drake_abs.contact.smoothing import Smoothing
from drake_abs.contact.step_data import ContactStepResult, ParameterDerivatives, StepQuantities
from drake_abs.contact.step_jacobians import step_jacobians
from drake_abs.contact.unconverged import exact_fallback
from drake_abs.lcp.ipm import solve_lcp_trusted


def assemble_lcp(
    quant: StepQuantities, cone: FrictionCone, h: float, *, regularize_normal: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The LCP ``(F (B, d, d), z (B, d))`` of one step, and the row scale S (nc + nt,).

    The cone's regularization applies to the tangent rows (relative to their mean diagonal), or
    with ``regularize_normal`` (the Anitescu generator rows) to every normal row, relative to
    its own diagonal. A pinned contact's normal row (its ``Jn`` row 0) gets the diagonal
    :data:`~drake_abs.contact.cone.PINNED_STIFFNESS`: ``kappa gamma + phi >= 0 perp gamma >= 0``
    (:class:`~drake_abs.contact.cone.FrictionCone`)."""
    fr = cone.frictional
    F, z, S = _assemble(
        np.asarray(quant.W, dtype=float),
        np.asarray(quant.v_free, dtype=float),
        np.asarray(quant.phi, dtype=float),
        np.asarray(quant.Jn, dtype=float),
        np.asarray(quant.Jt, dtype=float),
        fr,
        cone.friction_coefficients,
        cone.directions,
        float(cone.regularization),
        float(h),
        0 if regularize_normal else cone.sizes()[0],
    )
    if cone.pinned.any():
        pinned = np.flatnonzero(cone.pinned)
        F[:, pinned, pinned] += PINNED_STIFFNESS
    return F, z, S


@nb.njit(cache=True)
def _assemble(W, v_free, phi, Jn, Jt, fr, coeff, k, reg, h, reg_from):
    """Compiled body of :func:`assemble_lcp` (the F and z of
    :mod:`drake_abs.contact.contact_lcp`)."""
    B, nv = v_free.shape
    nc = phi.shape[1]
    nt = Jt.shape[1]
    nf = fr.shape[0]
    r = nc + nt
    d = r + nf
    F = np.zeros((B, d, d))
    z = np.zeros((B, d))
    S = np.ones(r)
    S[:nc] = h
    G = np.empty((r, nv))
    WG = np.empty((nv, r))
    for b in range(B):
        G[:nc] = Jn[b]
        G[nc:] = Jt[b]
        for n in range(nv):
            for j in range(r):
                acc = 0.0
                for m in range(nv):
                    acc += W[b, n, m] * G[j, m]
                WG[n, j] = acc
        for i in range(r):
            scale = h if i < nc else 1.0
            for j in range(r):
                acc = 0.0
                for n in range(nv):
                    acc += G[i, n] * WG[n, j]
                F[b, i, j] = scale * acc
            acc = 0.0
            for n in range(nv):
                acc += G[i, n] * v_free[b, n]
            z[b, i] = scale * acc + (phi[b, i] if i < nc else 0.0)
        for f in range(nf):
            for m in range(k):
                row = nc + f * k + m
                F[b, row, r + f] = 1.0
                F[b, r + f, row] = -1.0
            F[b, r + f, fr[f]] = coeff[f]
        if reg > 0.0 and reg_from == 0:  # generator rows: each relative to its own diagonal
            for i in range(r):  # (local: a pruned contact changes no other row)
                F[b, i, i] += reg * F[b, i, i]
        elif reg > 0.0 and r > reg_from:  # the tangent rows, relative to their mean diagonal
            mean = 0.0
            for i in range(reg_from, r):
                mean += F[b, i, i]
            weight = reg * mean / (r - reg_from)
            for i in range(reg_from, r):
                F[b, i, i] += weight
    return F, z, S


def stewart_trinkle_step(
    quant: StepQuantities,
    cone: FrictionCone,
    h: float,
    smoothing: Smoothing,
    gradient: GradientMode,
    strict: bool,
    parameters: ParameterDerivatives | None,
    options: dict[str, float],
    regularize_normal: bool = False,
    compliance: SoftRows | None = None,
    soft_dmu: np.ndarray | None = None,
) -> ContactStepResult:
    """Assemble, smooth, solve (with the exact fallback), integrate and differentiate one
    batched step whose LCP rows are the cone's (Stewart-Trinkle, or Anitescu generators passed
    as a frictionless cone with ``regularize_normal``). The arguments are those of
    :func:`drake_abs.contact.contact_lcp.contact_step`, checked there, with ``options`` its
    complete solver options; ``compliance`` (per normal row) regularises its soft rows
    (:mod:`drake_abs.contact.compliance`); ``soft_dmu`` (nc, T): the derivative of each normal
    row's friction coefficient in the model parameters, where the cone does not hold it (the
    Anitescu generators; default: from ``parameters.dfriction``)."""
    nc, nt, nf = cone.sizes()
    F, z, S = assemble_lcp(quant, cone, h, regularize_normal=regularize_normal)
    soft = None
    if compliance is not None:  # MuJoCo's soft rows: F_ii += h R_i, z_i = c_i + h J_i v_free
        Jv = np.einsum("bin,bn->bi", quant.Jn, quant.v)
        soft = compliance.terms(quant.phi, Jv, h)
        soft.apply(F, z, quant.phi, h)
    Fnn = F[:, :nc, :nc]
    mu_n = smoothing.mu(z[:, :nc], Fnn)
    mu = expand_mu(mu_n, cone, h)
    jac = quant.has_derivatives
    # without friction rows F = h G W G^T (+ a positive diagonal) is positive semidefinite by
    # construction (W = M^-1 is SPD): a monotone LCP (Anitescu generators, frictionless contact)
    monotone = nt == 0
    lcp = solve_lcp_trusted(F, z, mu, jacobians=jac, strict=strict, monotone=monotone, **options)
    lcp = exact_fallback(F, z, mu, lcp, jacobians=jac, monotone=monotone, **options)
    lam = lcp.lam
    lam_v = lam[:, : nc + nt]
    G = np.concatenate([quant.Jn, quant.Jt], axis=1)
    f, v_next, q_next = _integrate(
        quant.q, quant.W, quant.v_free, np.ascontiguousarray(G), quant.N, lam_v, h
    )
    out = dict(dx_dx=None, dx_du=None, dlam_dx=None, dlam_du=None)
    if jac:
        out = step_jacobians(
            quant, cone, h, F, z, S, G, lam, f, v_next, lcp, smoothing, gradient, parameters,
            soft, soft_dmu,
        )  # fmt: skip
    return ContactStepResult(
        q_next=q_next,
        v_next=v_next,
        lam=lam,
        mu=lcp.mu[:, :nc],
        converged=lcp.converged,
        lcp=lcp,
        **out,
    )


@nb.njit(cache=True)
def _integrate(q, W, v_free, G, N, lam_v, h):
    """``f = G^T lam``, ``v+ = v_free + W f``, ``q+ = q + h N v+`` for a batch."""
    B, nv = v_free.shape
    nq = q.shape[1]
    r = G.shape[1]
    f = np.zeros((B, nv))
    v_next = v_free.copy()
    q_next = q.copy()
    for b in range(B):
        for i in range(r):
            for n in range(nv):
                f[b, n] += G[b, i, n] * lam_v[b, i]
        for n in range(nv):
            acc = 0.0
            for m in range(nv):
                acc += W[b, n, m] * f[b, m]
            v_next[b, n] += acc
        for i in range(nq):
            acc = 0.0
            for n in range(nv):
                acc += N[b, i, n] * v_next[b, n]
            q_next[b, i] += h * acc
    return f, v_next, q_next
