"""Rigid bodies with contact, time-stepping, as a mu-softened LCP (docs/math.md section 6; Zhang et
al. 2023, eq. 2.2, Zhang et al. (model-based FOPG), eqs. 1.3-1.5), with the full step Jacobian:
the step's entry point, :func:`contact_step`.

For one step of length h, with inverse mass matrix W = M(q)^-1, the velocity without contact
``v_free = v + h W (tau(u) - n(q, v))``, normal Jacobians J_n (nc, nv), tangent Jacobians J_t
(k rows per frictional contact), signed distances phi and ``qdot = N(q) v``:

    v+ = v_free + W (J_n^T gamma + J_t^T beta)                 (impulses, N s)
    q+ = q + h N(q) v+
    normal:    phi + h J_n v+ >= 0            perp  gamma >= 0   (m)
    friction:  J_t v+ + E omega + eps beta >= 0  perp  beta >= 0   (m/s; eps: see FrictionCone)
    cone:      alpha gamma - E^T beta >= 0    perp  omega >= 0   (N s)

Substituting v+ gives ``s = F lam + z`` in ``lam = (gamma, beta, omega)`` with

    F = [[h Jn W Jn^T, h Jn W Jt^T, 0], [Jt W Jn^T, Jt W Jt^T, E], [diag(alpha), -E^T, 0]]
    z = [phi + h Jn v_free, Jt v_free, 0]

Frictionless scenes give a positive semidefinite F (monotone LCP). With friction F is copositive
but not P (zero diagonal in the omega block, non-symmetric cone rows): the interior point runs
without the P-matrix check (``on_bad_matrix="attempt"``) and reports per problem whether it
converged; it never returns an unconverged solve as valid.

Smoothing: the smoothing sees the normal rows (distances z_n, compliance block F_nn) and gives one
mu per contact (**larger is smoother**); that contact's friction and cone rows get mu / h. Divided
by h, the normal row is a velocity-level complementarity like the friction rows, so this is one
central-path value kappa = mu / h for every velocity-level pair of the contact (the uniform
relaxation Dojo uses). Barrier smoothing applied everywhere therefore also softens stick-slip
(a sliding body creeps to a stop); ABS smooths only while a contact closes in. In the ``total``
gradient mode mu is differentiated through z_n (not through F_nn).

Jacobians: docs/math.md section 4, the chain rule of :mod:`drake_abs.contact.step_jacobians`.

The step's parts, one module each:

- :mod:`drake_abs.contact.step_data`: its inputs (the dynamics quantities and their
  derivatives) and its result;
- :mod:`drake_abs.contact.cone`: the friction cone (the row layout above, the formulation) and
  the Anitescu generator rows;
- :mod:`drake_abs.contact.stewart_trinkle`: the LCP above, assembled, solved and integrated;
- :mod:`drake_abs.contact.anitescu`: the Anitescu formulation (docs/math.md section 6b);
- :mod:`drake_abs.contact.step_jacobians`: the chain rule to dx+/dx, dx+/du and the model
  parameters' columns;
- :mod:`drake_abs.contact.compliance`: the soft-contact option (MuJoCo's solref and solimp),
  which adds a regulariser to the normal rows' diagonal and replaces their constant.
"""

from __future__ import annotations

import numpy as np

from drake_abs.contact.anitescu import anitescu_step
from drake_abs.contact.compliance import SoftRows
from drake_abs.contact.cone import FORMULATIONS, FrictionCone
from drake_abs.contact.lcs import GradientMode, check_gradient_mode
from drake_abs.contact.smoothing import Exact, Smoothing
from drake_abs.contact.step_data import ContactStepResult, ParameterDerivatives, StepQuantities
from drake_abs.contact.stewart_trinkle import stewart_trinkle_step
from drake_abs.lcp.ipm import check_solver_options

# the step, its solver defaults and the friction formulations it dispatches on (defined with
# the cone: drake_abs.contact.cone)
__all__ = ["CONTACT_SOLVER_DEFAULTS", "FORMULATIONS", "contact_step"]


#: Solver defaults for contact steps. Sticking makes the linearised-cone LCP degenerate
#: (beta_j = xi_j = 0) and its friction split non-unique (opposing directions can carry equal,
#: cancelling impulses), where interior points converge linearly. The exact floor trades
#: convergence at rest against Jacobian accuracy at a sticking contact; measured (resting box;
#: rolling ball's step Jacobian against FD, scale 100): exact_tol 1e-9: 28 iterations, error
#: 0.6; 1e-12: 68 iterations, error 2e-6; 1e-15 (the solver default): no convergence at rest
#: within 200 iterations. Hence exact_tol = 1e-12 and a budget of 200 iterations.
CONTACT_SOLVER_DEFAULTS = {"exact_tol": 1e-12, "max_iterations": 200}


def contact_step(
    quant: StepQuantities,
    cone: FrictionCone,
    h: float,
    smoothing: Smoothing | None = None,
    *,
    gradient: GradientMode = "total",
    strict: bool = False,
    parameters: ParameterDerivatives | None = None,
    compliance: SoftRows | None = None,
    **solver_options,
) -> ContactStepResult:
    """Advance a batch of rigid-body states one step (see the module docstring).

    Jacobians are computed when ``quant`` carries derivatives; with ``parameters`` (which needs
    them), also ``dx_dtheta`` and ``dlam_dtheta``. ``compliance`` (one entry per normal row:
    :class:`~drake_abs.contact.compliance.SoftRows`) makes its soft rows MuJoCo's soft contact,
    a regularised LCP (:mod:`drake_abs.contact.compliance`); None: hard. ``solver_options`` go to
    :func:`drake_abs.solve_lcp` (tol, max_iterations, exact_tol; defaults in
    :data:`CONTACT_SOLVER_DEFAULTS`).
    """
    if parameters is not None and not quant.has_derivatives:
        raise ValueError("parameter derivatives need quantities with derivatives")
    check_gradient_mode(gradient)
    if not (np.isfinite(h) and h > 0):
        raise ValueError(f"h must be a finite number > 0; got {h!r}")
    smoothing = Exact() if smoothing is None else smoothing
    nc, nt, nf = cone.sizes()
    if quant.phi.shape[1] != nc or quant.Jt.shape[1] != nt:
        raise ValueError(
            f"quantities do not match the friction cone: phi has {quant.phi.shape[1]} contacts "
            f"and Jt {quant.Jt.shape[1]} rows; the cone expects {nc} and {nt}"
        )
    if nc == 0:
        return _free_step(quant, h, parameters)
    options = {**CONTACT_SOLVER_DEFAULTS, **solver_options}
    unknown = set(options) - set(CONTACT_SOLVER_DEFAULTS) - {"tol"}
    if unknown:
        raise ValueError(
            f"unknown solver option(s) {sorted(unknown)}: expected tol, max_iterations, exact_tol"
        )
    options.setdefault("tol", 1e-12)
    check_solver_options(options["tol"], options["max_iterations"], options["exact_tol"])
    if compliance is not None and compliance.soft.shape != (nc,):
        raise ValueError(
            f"compliance must have one entry per normal row ({nc}); got {compliance.soft.shape}"
        )
    if cone.formulation == "anitescu" and nf > 0:
        return anitescu_step(
            quant, cone, h, smoothing, gradient, strict, parameters, options, compliance
        )
    return stewart_trinkle_step(
        quant, cone, h, smoothing, gradient, strict, parameters, options, compliance=compliance
    )


def _free_step(
    quant: StepQuantities, h: float, par: ParameterDerivatives | None = None
) -> ContactStepResult:
    """No active contact: v+ = v_free, q+ = q + h N v+ (no LCP is solved). With ``par``, the
    theta columns ride along (only the free velocity can depend on them here)."""
    B, nq = quant.q.shape
    v_next = quant.v_free.copy()
    q_next = quant.q + h * np.einsum("bqn,bn->bq", quant.N, v_next)
    empty = np.zeros((B, 0))
    jac = dict(dx_dx=None, dx_du=None, dlam_dx=None, dlam_du=None)
    if quant.has_derivatives:
        P = quant.dv_free.shape[-1]
        nx = nq + quant.v.shape[1]
        dv, dN = quant.dv_free, quant.dN
        if par is not None:  # theta columns after p: dN does not depend on theta
            T = par.dphi.shape[-1]
            dv_t = np.zeros((B, nx - nq, T)) if par.dv_free is None else par.dv_free
            dv = np.concatenate([dv, dv_t], axis=-1)
        dq = np.zeros((B, nq, dv.shape[-1]))
        dq[:, :, :nq] = np.eye(nq)
        dq += h * np.einsum("bqn,bnp->bqp", quant.N, dv)
        dq[..., : dN.shape[-1]] += h * np.einsum("bqnp,bn->bqp", dN, v_next)
        dx = np.concatenate([dq, dv], axis=1)
        jac = dict(
            dx_dx=dx[:, :, :nx],
            dx_du=dx[:, :, nx:P],
            dlam_dx=np.zeros((B, 0, nx)),
            dlam_du=np.zeros((B, 0, P - nx)),
        )
        if par is not None:
            jac.update(dx_dtheta=dx[:, :, P:], dlam_dtheta=np.zeros((B, 0, dx.shape[-1] - P)))
    return ContactStepResult(q_next, v_next, empty, empty, np.ones(B, dtype=bool), lcp=None, **jac)
