"""Rigid bodies with contact, time-stepping, as a mu-softened LCP (docs/math.md section 6; Zhang et
al. 2023,
eq. 2.2, Zhang et al. (model-based FOPG), eqs. 1.3-1.5), with the full step Jacobian.

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

Smoothing: the policy sees the normal rows (distances z_n, compliance block F_nn) and gives one
mu per contact (**larger is smoother**); that contact's friction and cone rows get mu / h. Divided
by h, the normal row is a velocity-level complementarity like the friction rows, so this is one
central-path value kappa = mu / h for every velocity-level pair of the contact (the uniform
relaxation Dojo uses). Barrier smoothing applied everywhere therefore also softens stick-slip
(a sliding body creeps to a stop); ABS smooths only while a contact closes in. In the ``total``
gradient mode mu is differentiated through z_n (not through F_nn).

Jacobians (docs/math.md section 4, chain rule): with p = (q, v, u) and ``f = G^T lam``
(G = [Jn; Jt]),

    d lam / dp = (d lam / d z) (dz/dp + (dF/dp) lam)
    (dz/dp + (dF/dp) lam)_top = [dphi; 0] + S (dG v+ + G (dv_free + dW f + W dG^T lam))
    d v+ / dp = dv_free + dW f + W (dG^T lam + G^T d lam)
    d q+ / dp = [I 0 0] + h (dN v+ + N d v+)

(S = diag(h on normal rows, 1 on tangent rows)); the derivatives of W, J, phi, N and v_free with
respect to q, v and u come from the caller (e.g. Drake AutoDiffXd).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numba as nb
import numpy as np

from drake_abs.contact.lcs import GradientMode, check_gradient_mode
from drake_abs.contact.smoothing import Exact, SmoothingPolicy
from drake_abs.contact.unconverged import exact_fallback
from drake_abs.lcp.ipm import LCPResult, check_solver_options, solve_lcp_trusted

#: Solver defaults for contact steps. Sticking makes the linearised-cone LCP degenerate
#: (beta_j = xi_j = 0) and its friction split non-unique (opposing directions can carry equal,
#: cancelling impulses), where interior points converge linearly. The exact floor trades
#: convergence at rest against Jacobian accuracy at a sticking contact; measured (resting box;
#: rolling ball's step Jacobian against FD, scale 100): exact_tol 1e-9: 28 iterations, error
#: 0.6; 1e-12: 68 iterations, error 2e-6; 1e-15 (the solver default): no convergence at rest
#: within 200 iterations. Hence exact_tol = 1e-12 and a budget of 200 iterations.
CONTACT_SOLVER_DEFAULTS = {"exact_tol": 1e-12, "max_iterations": 200}

#: the friction formulations a :class:`FrictionCone` offers
FORMULATIONS = ("stewart_trinkle", "anitescu")


@dataclass(frozen=True)
class FrictionCone:
    """Which contacts have friction and how the cone is linearised.

    Attributes:
        coefficients: (nc,) friction coefficient per contact; NaN for a frictionless contact.
        directions: k, the number of tangent directions of each frictional contact's cone.
        regularization: epsilon, a tangential compliance relative to the mean diagonal of
            ``Jt W Jt^T``: the friction rows' slack becomes ``Jt v+ + E omega + eps_abs beta``.
            It makes the friction impulses unique at a sticking contact (without it opposite
            directions can carry equal, cancelling impulses: a continuum of solutions that
            interior points converge to slowly or not at all). Its effect is a slip velocity
            of at most eps times the tangential velocity change the impulse causes; measured on
            the resting box it took failures at rest from 16 of 100 steps to 0 and left the
            trajectory unchanged to 1e-6 m. Its weight is held constant when differentiating.
            Under ``"anitescu"`` it applies to every generator row, relative to that row's own
            diagonal (it makes the generator split unique at a sticking contact; being local,
            it lets pruning leave an exact step unchanged).
        formulation: how the friction cone enters the LCP (docs/math.md section 6b):

            - ``"stewart_trinkle"`` (default; the papers' eqs.): normal, tangent and cone rows as
              in the module docstring. Exact Coulomb friction on the linearised cone, but the
              LCP is not monotone (not P, not PSD), so the interior point may fail on it,
              mostly under smoothing at sticking contacts (measured: benchmarks/
              bench_convergence.py).
            - ``"anitescu"``: one row per cone generator ``n + alpha t_j`` (the convex
              relaxation): the LCP matrix is ``h D W D^T`` (positive semidefinite), a monotone
              LCP that the interior point solves at every mu. Its artefact: a *sliding* contact
              separates at ``alpha |v_t|`` (a lift of about ``alpha |v_t| h`` per step, where
              Stewart-Trinkle keeps it on the ground); sticking, rolling and the sliding
              deceleration are Coulomb's. Step outputs keep the Stewart-Trinkle layout
              (gamma, beta, omega) with omega = 0; there ``beta_j = alpha b_j`` are the
              generators' tangential parts, so ``sum_j beta_j = alpha gamma`` always (a sticking
              contact carries cancelling pairs): only the net ``sum_j beta_j t_j`` (the step's
              ``friction_impulse``) is physical, not the sum of the betas.
    """

    coefficients: np.ndarray
    directions: int = 4
    regularization: float = 1e-8
    formulation: str = "stewart_trinkle"
    _frictional: np.ndarray = field(init=False, repr=False, compare=False)
    _row_contact: np.ndarray = field(init=False, repr=False, compare=False)
    _mu_f: np.ndarray = field(init=False, repr=False, compare=False)
    _generators: GeneratorMap | None = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        coeff = np.asarray(self.coefficients, dtype=float).reshape(-1)
        frictional = ~np.isnan(coeff)
        if np.any(coeff[frictional] < 0) or np.any(np.isinf(coeff)):
            raise ValueError(f"friction coefficients must be >= 0 or NaN; got {coeff}")
        if not (np.isfinite(self.regularization) and self.regularization >= 0):
            raise ValueError(f"regularization must be >= 0; got {self.regularization!r}")
        if self.formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {FORMULATIONS}; got {self.formulation!r}")
        if int(self.directions) < 2 and frictional.any():
            raise ValueError(
                f"directions must be >= 2 for frictional contacts; got {self.directions}"
            )
        object.__setattr__(self, "coefficients", coeff)
        object.__setattr__(self, "directions", int(self.directions))
        fr = np.flatnonzero(frictional)
        object.__setattr__(self, "_frictional", fr)
        rows = np.concatenate([np.arange(coeff.size), np.repeat(fr, int(self.directions)), fr])
        object.__setattr__(self, "_row_contact", rows.astype(np.int64))
        object.__setattr__(self, "_mu_f", coeff[fr])
        object.__setattr__(self, "_generators", None)

    @property
    def frictional(self) -> np.ndarray:
        """Indices of the frictional contacts (nf,)."""
        return self._frictional

    @property
    def friction_coefficients(self) -> np.ndarray:
        """The coefficients of the frictional contacts (nf,), in the order of ``frictional``."""
        return self._mu_f

    @property
    def row_contact(self) -> np.ndarray:
        """The contact each LCP row belongs to, shape (d,); normal rows, then k tangent rows per
        frictional contact, then one cone row per frictional contact."""
        return self._row_contact

    def sizes(self) -> tuple[int, int, int]:
        """``(nc, nt, nf)``: contacts, tangent rows (k per frictional contact), cone rows."""
        nc = self.coefficients.size
        nf = self._frictional.size
        return nc, nf * self.directions, nf

    def with_formulation(self, formulation: str) -> FrictionCone:
        """The same cone under another friction formulation."""
        if formulation == self.formulation:
            return self
        return FrictionCone(self.coefficients, self.directions, self.regularization, formulation)

    @property
    def generators(self) -> GeneratorMap:
        """The Anitescu generator rows of this cone (built once)."""
        if self._generators is None:
            object.__setattr__(self, "_generators", GeneratorMap.of(self))
        return self._generators


@dataclass(frozen=True)
class GeneratorMap:
    """The rows of the Anitescu formulation (docs/math.md section 6b) of a cone with nc
    contacts: one generator per frictionless contact (its normal) and k per frictional contact
    (``n + alpha t_j``, j = 1..k), in contact order; ng generators in all.

    Attributes:
        contact: (ng,) the contact of each generator.
        tangent: (ng,) its row among the cone's tangent rows (-1 for a normal).
        alpha: (ng,) its friction coefficient (0 for a normal).
        friction: (ng,) the index of its contact among the frictional ones (-1 for a normal).
        to_lam: (d, ng) maps generator impulses to the Stewart-Trinkle layout
            (gamma_c = sum of the contact's generator impulses; beta_j = alpha x the impulse of
            generator j; omega = 0).
        average: (nc, ng) each contact's mean over its generators (z_n = average z_g when the
            contact's tangent directions sum to zero, as evenly spread ones do).
        share: (ng, nc) 1/k_c: a contact's mu split evenly over its k_c generators, so that
            summed over them the complementarity products equal the contact's mu.
        rows_cone: the generator rows as a frictionless cone (with this cone's regularization).
    """

    contact: np.ndarray
    tangent: np.ndarray
    alpha: np.ndarray
    friction: np.ndarray
    to_lam: np.ndarray
    average: np.ndarray
    share: np.ndarray
    rows_cone: FrictionCone

    @classmethod
    def of(cls, cone: FrictionCone) -> GeneratorMap:
        nc, nt, nf = cone.sizes()
        k = cone.directions
        order = {c: f for f, c in enumerate(cone.frictional)}
        contact, tangent, alpha, friction = [], [], [], []
        for c in range(nc):
            if c in order:
                f = order[c]
                contact += [c] * k
                tangent += list(range(f * k, (f + 1) * k))
                alpha += [cone.friction_coefficients[f]] * k
                friction += [f] * k
            else:
                contact.append(c)
                tangent.append(-1)
                alpha.append(0.0)
                friction.append(-1)
        contact, tangent = np.array(contact), np.array(tangent)
        alpha, friction = np.array(alpha, dtype=float), np.array(friction)
        ng = contact.size
        to_lam = np.zeros((nc + nt + nf, ng))
        to_lam[contact, np.arange(ng)] = 1.0
        fr = tangent >= 0
        to_lam[nc + tangent[fr], np.flatnonzero(fr)] = alpha[fr]
        member = np.zeros((nc, ng))
        member[contact, np.arange(ng)] = 1.0
        count = member.sum(axis=1)
        rows_cone = FrictionCone(np.full(ng, np.nan), k, cone.regularization)
        return cls(
            contact, tangent, alpha, friction, to_lam, member / count[:, None], member.T / count,
            rows_cone,
        )  # fmt: skip

    @property
    def size(self) -> int:
        return self.contact.size


class _GeneratorSmoothing(SmoothingPolicy):
    """A contact-level smoothing policy seen from the generator rows: each contact's mu comes
    from its mean generator distance and compliance (``average``), and is shared evenly by its
    generators (``share``)."""

    def __init__(self, inner: SmoothingPolicy, generators: GeneratorMap):
        self.inner = inner
        self.g = generators

    @property
    def is_constant(self) -> bool:
        return self.inner.is_constant

    @property
    def is_exact(self) -> bool:
        return self.inner.is_exact

    def _contact_level(self, z, F):
        A = self.g.average
        return z @ A.T, A @ F @ A.T

    def mu(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self.inner.mu(*self._contact_level(z, F)) @ self.g.share.T

    def dmu_dz(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        dmu = self.inner.dmu_dz(*self._contact_level(z, F))  # (B, nc, nc)
        return self.g.share @ dmu @ self.g.average

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return self.inner.parameter_names

    def dmu_dparameters(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        dmu = self.inner.dmu_dparameters(*self._contact_level(z, F))  # (B, nc, S)
        return np.einsum("gc,bcs->bgs", self.g.share, dmu)


@dataclass(frozen=True)
class StepQuantities:
    """One step's dynamics for a batch of B states (SI units).

    Values: ``q`` (B, nq), ``v`` (B, nv), ``W`` (B, nv, nv) inverse mass matrix, ``v_free``
    (B, nv), ``phi`` (B, nc) in m, ``Jn`` (B, nc, nv), ``Jt`` (B, nt, nv) with k consecutive rows
    per frictional contact, ``N`` (B, nq, nv).

    Derivatives with respect to p = (q, v, u), P = nq + nv + nu columns (all None, or all given):
    ``dv_free`` (B, nv, P), ``dphi`` (B, nc, P), ``dJn`` (B, nc, nv, P), ``dJt`` (B, nt, nv, P),
    ``dN`` (B, nq, nv, P), and the derivative of W either as the array ``dW`` (B, nv, nv, P) or
    as the product ``dW_times(f) = dW . f`` (a function of f (B, nv) returning (B, nv, P)): the
    step only needs dW applied to the generalised impulse, which a provider can evaluate
    without forming dW (``d(W f) = -W dM(W f)``, one inverse-dynamics derivative).

    The geometric derivatives may be narrow: ``dphi``, ``dJn`` and ``dJt`` may carry only their
    first K <= P columns (one K for the three), and ``dN`` only its first K_N <= P; the columns
    left out are zero. A rigid-body provider's distances, Jacobians and N depend on q alone, so
    K = nq (and K_N = 0 where N is constant) saves storing and reading zeros.
    """

    q: np.ndarray
    v: np.ndarray
    W: np.ndarray
    v_free: np.ndarray
    phi: np.ndarray
    Jn: np.ndarray
    Jt: np.ndarray
    N: np.ndarray
    dW: np.ndarray | None = None
    dv_free: np.ndarray | None = None
    dphi: np.ndarray | None = None
    dJn: np.ndarray | None = None
    dJt: np.ndarray | None = None
    dN: np.ndarray | None = None
    dW_times: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self):
        if self.dv_free is None:
            return
        P = self.dv_free.shape[-1]
        K = self.dphi.shape[-1]
        if self.dJn.shape[-1] != K or self.dJt.shape[-1] != K or K > P or self.dN.shape[-1] > P:
            raise ValueError(
                f"dphi, dJn, dJt must share their column count K <= P = {P}, and dN have at most "
                f"P columns; got {self.dphi.shape[-1]}, {self.dJn.shape[-1]}, "
                f"{self.dJt.shape[-1]} and {self.dN.shape[-1]}"
            )

    @property
    def has_derivatives(self) -> bool:
        return self.dv_free is not None

    def full(self, name: str) -> np.ndarray:
        """The derivative field ``name`` (``dphi``, ``dJn``, ``dJt``, ``dN``, ...) with all P
        columns (a narrow one padded with its zero columns)."""
        d = getattr(self, name)
        P = self.dv_free.shape[-1]
        if d.shape[-1] == P:
            return d
        out = np.zeros(d.shape[:-1] + (P,))
        out[..., : d.shape[-1]] = d
        return out

    def dW_dot(self, f: np.ndarray) -> np.ndarray:
        """``dW . f`` (B, nv, P): the derivative of ``W(q) f`` for a fixed f (B, nv)."""
        if self.dW is not None:
            return np.einsum("bnmp,bm->bnp", self.dW, f)
        if self.dW_times is None:
            raise ValueError("these quantities carry no derivative of W (dW or dW_times)")
        return self.dW_times(f)


@dataclass(frozen=True)
class ParameterDerivatives:
    """Derivatives of one step's quantities with respect to T model parameters theta, for a
    batch of B states: the theta block, kept apart from the (q, v, u) columns of
    :class:`StepQuantities` so that the two can never be mixed.

    Attributes:
        dphi: (B, nc, T) derivative of the contact distances (e.g. -1 for the ground height).
        dfriction: (nf, T) derivative of the friction coefficients of the cone's frictional
            contacts, in the cone's order (e.g. 1 in the column of that contact's coefficient).
        dW: (B, nv, nv, T) derivative of the inverse mass matrix (e.g. for body masses), or
            None where no parameter moves it.
        dv_free: (B, nv, T) derivative of the free velocity, or None likewise.
        dJn: (B, nc, nv, T) derivative of the normal rows' Jacobian (e.g. a contact point's
            offset moves it), or None where no parameter moves it.
        dJt: (B, nt, nv, T) derivative of the tangent rows' Jacobian (e.g. a contact sphere's
            radius moves its witness point, and with it the rolling part of the tangential
            velocity), or None likewise. Under Anitescu both move the generator rows
            ``n + alpha t`` (as do the friction coefficients themselves).
        smoothing_from: the first of the trailing columns that are the smoothing policy's
            numeric parameters (:meth:`SmoothingPolicy.dmu_dparameters`: they move mu at fixed
            distances, and nothing else), or None when there are none. Their entries in the
            arrays above are zero.
    """

    dphi: np.ndarray
    dfriction: np.ndarray
    dW: np.ndarray | None = None
    dv_free: np.ndarray | None = None
    dJn: np.ndarray | None = None
    dJt: np.ndarray | None = None
    smoothing_from: int | None = None


@dataclass(frozen=True)
class ContactStepResult:
    """One batched rigid-body step.

    Attributes:
        q_next, v_next: (B, nq), (B, nv).
        lam: (B, d) LCP variables (gamma (nc), beta (nt), omega (nf)); impulses in N s.
        mu: (B, nc) central-path value per contact (normal rows, m N s).
        converged: (B,) solver flags.
        dx_dx: (B, nq + nv, nq + nv), dx_du: (B, nq + nv, nu), dlam_dx, dlam_du: Jacobians
            (None unless the quantities carry derivatives).
        lcp: the solver's result (None when no contact was active: no LCP was solved).
        dx_dtheta: (B, nq + nv, T), dlam_dtheta: (B, d, T): derivatives with respect to the
            model parameters of ``parameters`` (None unless asked for).
    """

    q_next: np.ndarray
    v_next: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    converged: np.ndarray
    dx_dx: np.ndarray | None
    dx_du: np.ndarray | None
    dlam_dx: np.ndarray | None
    dlam_du: np.ndarray | None
    lcp: LCPResult | None
    dx_dtheta: np.ndarray | None = None
    dlam_dtheta: np.ndarray | None = None


def assemble_lcp(
    quant: StepQuantities, cone: FrictionCone, h: float, *, regularize_normal: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The LCP ``(F (B, d, d), z (B, d))`` of one step, and the row scale S (nc + nt,).

    The cone's regularization applies to the tangent rows (relative to their mean diagonal), or
    with ``regularize_normal`` (the Anitescu generator rows) to every normal row, relative to
    its own diagonal."""
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
    return F, z, S


@nb.njit(cache=True)
def _assemble(W, v_free, phi, Jn, Jt, fr, coeff, k, reg, h, reg_from):
    """Compiled body of :func:`assemble_lcp` (the F and z of the module docstring)."""
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


def contact_step(
    quant: StepQuantities,
    cone: FrictionCone,
    h: float,
    smoothing: SmoothingPolicy | None = None,
    *,
    gradient: GradientMode = "total",
    strict: bool = False,
    parameters: ParameterDerivatives | None = None,
    **solver_options,
) -> ContactStepResult:
    """Advance a batch of rigid-body states one step (see the module docstring).

    Jacobians are computed when ``quant`` carries derivatives; with ``parameters`` (which needs
    them), also ``dx_dtheta`` and ``dlam_dtheta``. ``solver_options`` go to
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
    if cone.formulation == "anitescu" and nf > 0:
        return _anitescu_step(quant, cone, h, smoothing, gradient, strict, parameters, options)
    return _lcp_step(quant, cone, h, smoothing, gradient, strict, parameters, options)


def _lcp_step(
    quant, cone, h, smoothing, gradient, strict, parameters, options, regularize_normal=False
) -> ContactStepResult:
    """Assemble, smooth, solve (with the exact fallback), integrate and differentiate one
    batched step whose LCP rows are the cone's (Stewart-Trinkle, or Anitescu generators passed
    as a frictionless cone with ``regularize_normal``)."""
    nc, nt, nf = cone.sizes()
    F, z, S = assemble_lcp(quant, cone, h, regularize_normal=regularize_normal)
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
        out = _step_jacobians(
            quant, cone, h, F, z, S, G, lam, f, v_next, lcp, smoothing, gradient, parameters
        )
    return ContactStepResult(
        q_next=q_next,
        v_next=v_next,
        lam=lam,
        mu=lcp.mu[:, :nc],
        converged=lcp.converged,
        lcp=lcp,
        **out,
    )


def _anitescu_step(quant, cone, h, smoothing, gradient, strict, par, options):
    """The step under the Anitescu formulation (docs/math.md section 6b): the generator rows
    ``D = Jn[c] + alpha Jt[j]`` as a frictionless LCP (positive semidefinite ``h D W D^T``,
    regularized), its results mapped back to the Stewart-Trinkle layout."""
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
        _check_parameter_shapes(par, cone, B)
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
    r = _lcp_step(
        quant_g, cone_g, h, _GeneratorSmoothing(smoothing, g), gradient, strict, par_g, options,
        regularize_normal=True,
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


def expand_mu(mu_n: np.ndarray, cone: FrictionCone, h: float) -> np.ndarray:
    """Per-row values (B, d, ...) from per-contact values (B, nc, ...): each row takes its
    contact's value, divided by h on friction and cone rows. For mu (B, nc) and for its
    derivative d mu_n / d z_n (B, nc, nc), giving d mu_rows / d z_n (B, d, nc)."""
    rows = mu_n[:, cone.row_contact]
    rows[:, cone.sizes()[0] :] /= h
    return rows


def _step_jacobians(quant, cone, h, F, z, S, G, lam, f, v_next, lcp, smoothing, gradient, par):
    """The chain rule of the module docstring: dx+/d(x, u) and dlam/d(x, u); with ``par``, the
    theta columns (:func:`_parameter_blocks`) appended to the same chain, giving dx+/dtheta and
    dlam/dtheta."""
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
    # mu's own derivative: only where mu depends on the state (for a constant policy dmu_dz is
    # 0, and the total derivative is the frozen one)
    total = gradient == "total" and not smoothing.is_constant
    if total:
        # dz_n/dp: the distance and free-velocity part (mu's dependence on F is held)
        dzn = h * np.einsum("brn,bnp->brp", quant.Jn, quant.dv_free)
        dzn[..., : quant.dphi.shape[-1]] += quant.dphi
        dzn[..., : quant.dJn.shape[-1]] += h * np.einsum("brnp,bn->brp", quant.dJn, quant.v_free)
    if par is not None:  # theta columns after p
        inner_t, dz_t, dzn_t = _parameter_blocks(quant, cone, h, S, G, lam, f, v_next, par)
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


def _parameter_blocks(quant, cone, h, S, G, lam, f, v_next, par):
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
    _check_parameter_shapes(par, cone, B)
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


def _check_parameter_shapes(par: ParameterDerivatives, cone: FrictionCone, B: int) -> None:
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
