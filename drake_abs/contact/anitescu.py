"""The Anitescu formulation of the rigid-body contact step (docs/math.md section 6b): one row per
cone generator ``D = n + alpha t_j`` (the convex relaxation of the linearised cone), solved as
the frictionless LCP of those rows (:mod:`drake_abs.contact.stewart_trinkle`; its matrix
``h D W D^T`` is positive semidefinite, regularized: a monotone LCP), its results mapped back to
the Stewart-Trinkle layout (gamma, beta, omega) with omega = 0
(:class:`~drake_abs.contact.cone.GeneratorMap`).
"""

from __future__ import annotations

import numpy as np

from drake_abs.contact.compliance import SoftRows
from drake_abs.contact.cone import FrictionCone, GeneratorSmoothing
from drake_abs.contact.lcs import GradientMode
from drake_abs.contact.smoothing import Smoothing
from drake_abs.contact.step_data import ContactStepResult, ParameterDerivatives, StepQuantities
from drake_abs.contact.step_jacobians import check_parameter_shapes
from drake_abs.contact.stewart_trinkle import stewart_trinkle_step


def anitescu_step(
    quant: StepQuantities,
    cone: FrictionCone,
    h: float,
    smoothing: Smoothing,
    gradient: GradientMode,
    strict: bool,
    par: ParameterDerivatives | None,
    options: dict[str, float],
    compliance: SoftRows | None = None,
) -> ContactStepResult:
    """The step under the Anitescu formulation (docs/math.md section 6b): the generator rows
    ``D = Jn[c] + alpha Jt[j]`` as a frictionless LCP (positive semidefinite ``h D W D^T``,
    regularized), its results mapped back to the Stewart-Trinkle layout. The arguments are
    those of :func:`drake_abs.contact.contact_lcp.contact_step` (``par``: its ``parameters``),
    checked there, with ``options`` its complete solver options; ``compliance`` (per normal
    row) is shared by each contact's generators (their weights are set for that by
    :meth:`~drake_abs.contact.compliance.ContactCompliance.rows`)."""
    g = cone.generators
    ng = g.size
    fr = g.tangent >= 0
    tangent = np.where(fr, g.tangent, 0)

    def rows(Jn, Jt):  # generator rows of a normal and a tangent Jacobian (values or derivatives)
        a = g.alpha.reshape((1, ng) + (1,) * (Jn.ndim - 2))
        return Jn[:, g.contact] + a * Jt[:, tangent] * fr.reshape(a.shape)

    B, nv = quant.v.shape
    nc, nt, _ = cone.sizes()
    derivs = {}
    if quant.has_derivatives:
        derivs = dict(
            dW=quant.dW,
            dv_free=quant.dv_free,
            dphi=quant.dphi[:, g.contact],
            dJn=rows(quant.dJn, quant.dJt),
            dJt=np.zeros((B, 0) + quant.dJt.shape[2:]),
            dN=quant.dN,
            dW_times=quant.dW_times,
        )
    quant_g = StepQuantities(
        q=quant.q,
        v=quant.v,
        W=quant.W,
        v_free=quant.v_free,
        phi=quant.phi[:, g.contact],
        Jn=rows(quant.Jn, quant.Jt),
        Jt=np.zeros((B, 0, nv)),
        N=quant.N,
        **derivs,
    )
    cone_g = g.rows_cone
    par_g = None
    if par is not None:
        T = par.dphi.shape[-1]
        check_parameter_shapes(par, cone, B)
        # d D_j / d theta = t_j d alpha / d theta: the generators move with the coefficients,
        # and with the rows themselves, d n_c + alpha d t_j (e.g. a contact's radius or offset)
        dalpha = np.zeros((ng, T))
        dalpha[fr] = par.dfriction[g.friction[fr]]
        dJn = quant.Jt[:, tangent, :, None] * (dalpha * fr[:, None])[None, :, None, :]
        if par.dJn is not None or par.dJt is not None:
            dJn_c = np.zeros((B, nc) + dJn.shape[2:]) if par.dJn is None else par.dJn
            dJt_c = np.zeros((B, nt) + dJn.shape[2:]) if par.dJt is None else par.dJt
            dJn = dJn + rows(dJn_c, dJt_c)
        par_g = ParameterDerivatives(
            par.dphi[:, g.contact], np.zeros((0, T)), par.dW, par.dv_free, dJn=dJn,
            smoothing_from=par.smoothing_from,
        )  # fmt: skip
    r = stewart_trinkle_step(
        quant_g, cone_g, h, GeneratorSmoothing(smoothing, g), gradient, strict, par_g, options,
        regularize_normal=True,
        compliance=None if compliance is None else compliance.take(g.contact),
        soft_dmu=None if par_g is None else dalpha,  # a generator's mu moves its R
    )  # fmt: skip
    L = g.to_lam
    lam_g = r.lam

    def to_lam(d):  # (B, ng, P) -> (B, d, P)
        return None if d is None else L @ d

    dlam_dtheta = None
    if r.dlam_dtheta is not None:
        dlam_dtheta = L @ r.dlam_dtheta
        # beta_j = alpha lam_g[j]: its coefficient's derivative times the generator impulse
        dlam_dtheta[:, nc + g.tangent[fr]] += lam_g[:, fr, None] * dalpha[fr][None]
    return ContactStepResult(
        q_next=r.q_next,
        v_next=r.v_next,
        lam=lam_g @ L.T,
        mu=r.mu @ (g.share > 0),  # a contact's mu: the sum of its generators' shares
        converged=r.converged,
        dx_dx=r.dx_dx,
        dx_du=r.dx_du,
        dlam_dx=to_lam(r.dlam_dx),
        dlam_du=to_lam(r.dlam_du),
        lcp=r.lcp,
        dx_dtheta=r.dx_dtheta,
        dlam_dtheta=dlam_dtheta,
    )
