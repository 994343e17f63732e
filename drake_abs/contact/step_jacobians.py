"""The Jacobians of one rigid-body contact step (:mod:`drake_abs.contact.contact_lcp`), by the
chain rule (docs/math.md section 4): dx+/dx, dx+/du, dlam/dx and dlam/du, and with model
parameters theta (:class:`~drake_abs.contact.step_data.ParameterDerivatives`) dx+/dtheta and
dlam/dtheta, from the solver's d lam / d z (and d lam / d mu) and the caller's derivatives of the
step's quantities.

With p = (q, v, u) and ``f = G^T lam`` (G = [Jn; Jt]),

    d lam / dp = (d lam / d z) (dz/dp + (dF/dp) lam)
    (dz/dp + (dF/dp) lam)_top = [dphi; 0] + S (dG v+ + G (dv_free + dW f + W dG^T lam))
    d v+ / dp = dv_free + dW f + W (dG^T lam + G^T d lam)
    d q+ / dp = [I 0 0] + h (dN v+ + N d v+)

(S = diag(h on normal rows, 1 on tangent rows)); the derivatives of W, J, phi, N and v_free with
respect to q, v and u come from the caller (e.g. Drake AutoDiffXd).

Shapes: B states, nq positions, nv velocities, P = nq + nv + nu columns of p, T columns of
theta, d = nc + nt + nf LCP rows (:meth:`~drake_abs.contact.cone.FrictionCone.sizes`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from drake_abs.contact.compliance import RowTerms
from drake_abs.contact.cone import FrictionCone, expand_mu
from drake_abs.contact.lcs import GradientMode
from drake_abs.contact.smoothing import Smoothing
from drake_abs.contact.step_data import ParameterDerivatives, StepQuantities
from drake_abs.lcp.ipm import LCPResult


def step_jacobians(
    quant: StepQuantities,
    cone: FrictionCone,
    h: float,
    F: np.ndarray,
    z: np.ndarray,
    S: np.ndarray,
    G: np.ndarray,
    lam: np.ndarray,
    f: np.ndarray,
    v_next: np.ndarray,
    lcp: LCPResult,
    smoothing: Smoothing,
    gradient: GradientMode,
    par: ParameterDerivatives | None,
    soft: RowTerms | None = None,
    soft_dmu: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """The chain rule of this module's docstring: dx+/d(x, u) and dlam/d(x, u); with ``par``, the
    theta columns (:func:`parameter_blocks`) appended to the same chain, giving dx+/dtheta and
    dlam/dtheta.

    The step's solve: its LCP F (B, d, d), z (B, d) and row scale S (nc + nt,)
    (:func:`~drake_abs.contact.stewart_trinkle.assemble_lcp`), the rows G = [Jn; Jt]
    (B, nc + nt, nv), the solution lam (B, d) with the solver's Jacobians (``lcp``), the
    generalised impulse f = G^T lam (B, nv) and v+ (B, nv). ``soft``: the compliance terms of
    the normal rows (:class:`~drake_abs.contact.compliance.RowTerms`), whose own derivatives
    (through phi and J v, and with ``par`` through the friction coefficients: ``soft_dmu``
    (nc, T) per normal row, default from ``par.dfriction``) are added to the hard rows' (None:
    hard contact).

    Returns:
        ``dx_dx`` (B, nq + nv, nq + nv), ``dx_du`` (B, nq + nv, nu), ``dlam_dx`` (B, d, nq + nv)
        and ``dlam_du`` (B, d, nu); with ``par`` also ``dx_dtheta`` (B, nq + nv, T) and
        ``dlam_dtheta`` (B, d, T).
    """
    nc, nt, nf = cone.sizes()
    B, nq = quant.q.shape
    nv = quant.v.shape[1]
    P = quant.dv_free.shape[-1]
    lam_v = lam[:, : nc + nt]
    inner, dz_eff = _chain_in(
        quant.W, G, quant.dJn, quant.dJt, lam_v, v_next, S, quant.dphi, quant.dv_free,
        quant.dW_dot(f), z.shape[1],
    )  # fmt: skip
    dN = quant.dN
    # mu's own derivative: only where mu depends on the state (for a constant smoothing dmu_dz is
    # 0, and the total derivative is the frozen one)
    total = gradient == "total" and not smoothing.is_constant
    if total:
        # dz_n/dp: the distance and free-velocity part (mu's dependence on F is held)
        dzn = h * np.einsum("brn,bnp->brp", quant.Jn, quant.dv_free)
        dzn[..., : quant.dphi.shape[-1]] += quant.dphi
        dzn[..., : quant.dJn.shape[-1]] += h * np.einsum("brnp,bn->brp", quant.dJn, quant.v_free)
    if soft is not None:  # compliance: R and c move with phi and J v
        dphi, dJv = _soft_inputs(quant)
        dz_eff[:, :nc] += soft.extra_derivative(dphi, dJv, lam[:, :nc], h)
        if total:
            dzn += soft.extra_derivative(dphi, dJv, None, h)
    if par is not None:  # theta columns after p
        inner_t, dz_t, dzn_t = parameter_blocks(quant, cone, h, S, G, lam, f, v_next, par)
        if soft is not None:
            dJv_t = 0.0 * par.dphi
            if par.dJn is not None:
                dJv_t = np.einsum("bint,bn->bit", par.dJn, quant.v)
            dz_t[:, :nc] += soft.extra_derivative(par.dphi, dJv_t, lam[:, :nc], h)
            if soft_dmu is None:  # each normal row's friction coefficient, from the cone's
                soft_dmu = np.zeros((nc, par.dphi.shape[-1]))
                soft_dmu[cone.frictional] = par.dfriction
            dz_t[:, :nc] += soft.friction_derivative(soft_dmu, lam[:, :nc], h)
            dzn_t = dzn_t + soft.extra_derivative(par.dphi, dJv_t, None, h)
        inner = np.concatenate([inner, inner_t], axis=-1)
        dz_eff = np.concatenate([dz_eff, dz_t], axis=-1)
        if total:
            dzn = np.concatenate([dzn, dzn_t], axis=-1)
    dlam = lcp.dlam_dq @ dz_eff  # (B, d, P [+ T])
    if total:
        dmu_rows = expand_mu(smoothing.dmu_dz(z[:, :nc], F[:, :nc, :nc]), cone, h)
        dlam = dlam + lcp.dlam_dmu @ (dmu_rows @ dzn)
    if par is not None and par.smoothing_from is not None:  # mu's own parameters, z held
        dmu_s = expand_mu(smoothing.dmu_dparameters(z[:, :nc], F[:, :nc, :nc]), cone, h)
        dlam[:, :, P + par.smoothing_from :] += lcp.dlam_dmu @ dmu_s
    dx = _chain_out(inner, quant.W, G, dlam, quant.N, dN, v_next, h)  # (B, nq + nv, P [+ T])
    nx = nq + nv
    out = dict(
        dx_dx=dx[:, :, :nx], dx_du=dx[:, :, nx:P], dlam_dx=dlam[:, :, :nx], dlam_du=dlam[:, :, nx:P]
    )
    if par is not None:
        out.update(dx_dtheta=dx[:, :, P:], dlam_dtheta=dlam[:, :, P:])
    return out


def _soft_inputs(quant: StepQuantities) -> tuple[np.ndarray, np.ndarray]:
    """The normal rows' dphi and d(J_n v) with respect to p = (q, v, u), all P columns
    (B, nc, P): ``d(J_n v) = dJ_n v + J_n dv``."""
    nq, nv = quant.q.shape[1], quant.v.shape[1]
    dphi = quant.full("dphi")
    dJv = np.einsum("bnvp,bv->bnp", quant.full("dJn"), quant.v)
    dJv[:, :, nq : nq + nv] += quant.Jn
    return dphi, dJv


def parameter_blocks(
    quant: StepQuantities,
    cone: FrictionCone,
    h: float,
    S: np.ndarray,
    G: np.ndarray,
    lam: np.ndarray,
    f: np.ndarray,
    v_next: np.ndarray,
    par: ParameterDerivatives,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The theta columns' inputs to the chain rule: ``inner`` (B, nv, T), the velocity change at
    fixed impulses; ``dz`` (B, d, T), the LCP offsets' derivative with F's applied to lam; and
    ``dzn`` (B, nc, T), the normal distances' derivative (for mu in the total mode).

    theta moves the normal rows' offsets (``dphi``), the cone rows' matrix entries
    (``F[cone f, gamma f] = alpha_f``, so ``(dF lam)_f = dalpha_f gamma_f``), through W and
    v_free (masses, joint damping) the velocity rows, and through G (a contact's radius or
    offset) the rows themselves: ``inner = dv_free + dW f + W dG^T lam`` with ``f = G^T lam``,
    entering as ``S (G inner + dG v+)`` (S: h on normal rows, 1 on tangent rows). N does not
    depend on these parameters."""
    nc, nt, nf = cone.sizes()
    B, d = lam.shape
    T = par.dphi.shape[-1]
    check_parameter_shapes(par, cone, B)
    r = nc + nt
    inner = np.zeros((B, quant.W.shape[-1], T))
    if par.dv_free is not None:
        inner += par.dv_free
    if par.dW is not None:
        inner += np.einsum("bnmt,bm->bnt", par.dW, f)
    if par.dJn is not None:  # W dJn^T gamma
        inner += quant.W @ np.einsum("bint,bi->bnt", par.dJn, lam[:, :nc])
    if par.dJt is not None:  # W dJt^T beta
        inner += quant.W @ np.einsum("bint,bi->bnt", par.dJt, lam[:, nc:r])
    dz = np.zeros((B, d, T))
    dz[:, :nc] = par.dphi
    dz[:, :r] += S[None, :, None] * np.einsum("bin,bnt->bit", G, inner)
    if par.dJt is not None:  # the tangent rows move: S_t dJt v+ (z_t = Jt v_free holds no phi)
        dz[:, nc:r] += S[None, nc:r, None] * np.einsum("bint,bn->bit", par.dJt, v_next)
    dz[:, r:] = lam[:, cone.frictional, None] * par.dfriction[None]
    dzn = par.dphi.copy()
    if par.dv_free is not None:
        dzn += h * np.einsum("bin,bnt->bit", quant.Jn, par.dv_free)
    if par.dJn is not None:  # the rows themselves move: h dJn v+ (and h dJn v_free for mu)
        dz[:, :nc] += S[None, :nc, None] * np.einsum("bint,bn->bit", par.dJn, v_next)
        dzn += h * np.einsum("bint,bn->bit", par.dJn, quant.v_free)
    return inner, dz, dzn


def check_parameter_shapes(par: ParameterDerivatives, cone: FrictionCone, B: int) -> None:
    """Raises a ValueError unless ``par`` fits ``cone`` and a batch of B states: dphi
    (B, nc, T), dfriction (nf, T), dJn (B, nc, nv, T) and dJt (B, nt, nv, T) where given."""
    nc, nt, nf = cone.sizes()
    T = par.dphi.shape[-1]
    if par.dphi.shape != (B, nc, T) or par.dfriction.shape != (nf, T):
        raise ValueError(
            f"parameter derivatives must be dphi (B, nc, T) = ({B}, {nc}, T) and dfriction "
            f"(nf, T) = ({nf}, T); got {par.dphi.shape} and {par.dfriction.shape}"
        )
    for name, rows in (("dJn", nc), ("dJt", nt)):
        d = getattr(par, name)
        if d is not None and (d.ndim != 4 or d.shape[:2] != (B, rows) or d.shape[-1] != T):
            raise ValueError(
                f"parameter derivative {name} must have shape (B, {rows}, nv, T) = "
                f"({B}, {rows}, nv, {T}); got {d.shape}"
            )


@nb.njit(cache=True)
def _chain_in(W, G, dJn, dJt, lam_v, v_next, S, dphi, dv_free, dWf, d):
    """``inner = dv_free + dW f + W dG^T lam`` (B, nv, P) and ``dz_eff`` (B, d, P), the
    derivative of the LCP's q with F's derivative applied to lam (rows past nc + nt are 0).
    dG is the stack of dJn (B, nc, nv, P) and dJt (B, nt, nv, P), read in place."""
    B, nc, nv, K = dJn.shape  # K <= P: dG's columns past K are zero (and dphi's past its own)
    P = dv_free.shape[-1]
    Kp = dphi.shape[-1]
    r = nc + dJt.shape[1]
    inner = np.empty((B, nv, P))
    dz = np.zeros((B, d, P))
    dGl = np.empty((nv, K))
    for b in range(B):
        for n in range(nv):
            for p in range(K):
                acc = 0.0
                for i in range(nc):
                    acc += dJn[b, i, n, p] * lam_v[b, i]
                for i in range(nc, r):
                    acc += dJt[b, i - nc, n, p] * lam_v[b, i]
                dGl[n, p] = acc
        for n in range(nv):
            for p in range(P):
                acc = dv_free[b, n, p] + dWf[b, n, p]
                if p < K:
                    for m in range(nv):
                        acc += W[b, n, m] * dGl[m, p]
                inner[b, n, p] = acc
        for i in range(r):
            for p in range(P):
                acc = 0.0
                for n in range(nv):
                    acc += G[b, i, n] * inner[b, n, p]
                if p < K:
                    for n in range(nv):
                        dG = dJn[b, i, n, p] if i < nc else dJt[b, i - nc, n, p]
                        acc += dG * v_next[b, n]
                dz[b, i, p] = S[i] * acc + (dphi[b, i, p] if i < nc and p < Kp else 0.0)
    return inner, dz


@nb.njit(cache=True)
def _chain_out(inner, W, G, dlam, N, dN, v_next, h):
    """``dv+ = inner + W G^T dlam`` and ``dq+ = [I 0 0] + h (dN v+ + N dv+)``, stacked (B, nq +
    nv, P)."""
    B, nv, P = inner.shape
    r = G.shape[1]
    nq = N.shape[1]
    KN = dN.shape[-1]  # dN's columns past KN are zero
    dx = np.zeros((B, nq + nv, P))
    tmp = np.empty((nv, P))
    for b in range(B):
        for n in range(nv):
            for p in range(P):
                acc = 0.0
                for i in range(r):
                    acc += G[b, i, n] * dlam[b, i, p]
                tmp[n, p] = acc
        for n in range(nv):
            for p in range(P):
                acc = inner[b, n, p]
                for m in range(nv):
                    acc += W[b, n, m] * tmp[m, p]
                dx[b, nq + n, p] = acc
        for i in range(nq):
            for p in range(P):
                acc = 0.0
                for n in range(nv):
                    acc += N[b, i, n] * dx[b, nq + n, p]
                if p < KN:
                    for n in range(nv):
                        acc += dN[b, i, n, p] * v_next[b, n]
                dx[b, i, p] = h * acc + (1.0 if p == i else 0.0)
    return dx
