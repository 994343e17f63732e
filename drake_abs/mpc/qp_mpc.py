"""Differentiable QP-MPC (Zuliani et al. 2025, eq. 4, docs/math.md section 9): OSQP solve and KKT
Jacobians.

The problem, in deviations dx = x - x_ref, du = u - u_ref from the reference (an equilibrium of
the linear prediction model dx+ = A dx + B du), with horizon N::

    minimise   sum_{k=0}^{N-1} (dx_k' Q dx_k + du_k' R du_k) + dx_N' P dx_N
               + rho_q ||s||^2 + rho_l 1's
    subject to dx_{k+1} = A dx_k + B du_k,   dx_0 = x - x_ref            (k = 0..N-1)
               u_min <= u_ref + du_k <= u_max                              (k = 0..N-1)
               x_min - s_k <= (x_ref + dx_k)[c] <= x_max + s_k,  s_k >= 0   (k = 1..N)

over the components c of the state with a finite bound (state constraints softened by the
slack s with a linear plus a quadratic penalty; with ``soft_state_constraints=False`` they are
hard and there is no slack). The control applied is u = u_ref + du_0. (The term dx_0' Q dx_0 is
a constant and left out.)

Cost parameters theta = (p_Q, p_R, p_P), n_theta = nx + nu + nx (nx + 1) / 2
(docs/math.md section 9)::

    Q = diag(p_Q^2) + 1e-6 I,   R = diag(p_R^2) + 1e-6 I,   P = L L' + 1e-6 I

where L is lower triangular with the entries p_P in ``numpy.tril_indices(nx)`` order (row by
row: L[0,0], L[1,0], L[1,1], L[2,0], ...).

Decision vector, in this order: z = (w_0..w_{N-1}, dx_1..dx_N, s_1..s_N) with the inputs in
scaled units, du_k = S w_k, S diagonal (this only conditions the problem for OSQP: rotor speeds
in rad/s with R ~ 0.01 made ADMM take thousands of iterations; S_i is the distance from u_ref_i
to its nearest finite input bound, 9.4 rad/s for the quadcopter, or 1 without bounds). OSQP
solves min 1/2 z'Hz + h'z s.t. l <= Gz <= u with H = 2 blkdiag(S R S.., Q.., P, rho_q I),
warm-started from the previous solve and polished.

Jacobians (the solution's conservative Jacobian, Zuliani et al. 2025, Appendix A / Theorem 10): at
the
active set the KKT conditions H z + h + G_a' y_a = 0, G_a z = b_a are an equality system whose
differential gives dz. Only u_0 is needed, so we solve the adjoint (transposed) system once with
nu right-hand sides, K W = [E'; 0], K = [[H, G_a'], [G_a, 0]], E selecting w_0, and read off

    du_0/dx     = S W_y[first dynamics block]' A        (b = (A (x - x_ref), 0, ..) moves with x)
    du_0/dtheta = -S W_z' (dH/dtheta) z                 (only H depends on theta)

(reverse mode: one sparse LU and nu = 4 back-substitutions instead of nx + n_theta = 106
forward solves). ``method="osqp_adjoint"`` gets the same Jacobian from OSQP's own adjoint
derivative (one call per input component) as an independent path; it is slower (about 25 ms
against 1.5 ms) and, with OSQP 1.1.3, it agreed with ours and with central differences only while
no slack was positive (with positive slacks it was off by up to a few percent), so the KKT path
is the default.

Active set, the documented deterministic rule for weakly active constraints: a row is active
iff it is an equality row (the dynamics) or its multiplier is nonzero, ``|y_i| > tau`` with
tau = ``dual_tolerance`` * max(1, ||y||_inf) (OSQP's sign of y_i says which bound: y_i > 0
upper, y_i < 0 lower). A constraint that holds with equality but carries a zero multiplier
(weakly active) is therefore treated as inactive: the Jacobian is that of the branch on which
the constraint is released, an element of the conservative Jacobian. The number of weakly
active rows is reported (``MpcSolution.weakly_active``).

Failures: a solve that stops at the iteration limit (or only inaccurately solved) is retried
once from a cold start. A solution OSQP still reports as SOLVED_INACCURATE (ADMM stalled just
above the tolerance and polishing failed: seen about once in 10^5 solves of the quadcopter
experiment, residuals ~6e-6 against 1e-6) is applied, with its status in the record and the
Jacobian of its (clearly separated) active set: the hover input instead would be a far larger
error. Any other status (primal or dual infeasible, maximum iterations, non-convex, non-finite
result) gives ``fallback = True`` and the documented fallback control u = clip(u_ref, u_min,
u_max) (the reference input, e.g. hover, projected on the input box) with zero Jacobians; the
status is in the record. The control is never NaN.

Verification: OSQP's termination test is relative to the size of G z, so at an absurd (finite)
state, ``|x| ~ 1e15``, it reported SOLVED for an input 66 rad/s outside the hard box. Every solution
OSQP calls solved is therefore re-checked on the current data before it is used: all rows to
OSQP's own primal criterion (eps_abs + eps_rel max(||G z||, ||l, u||)), and the input box rows at
the scale of the input bounds alone (``eps_abs + eps_rel max(1, |bound|)``, in the scaled inputs w),
both with a factor ``VERIFY_FACTOR`` = 10 of slack (unpolished solutions of the quadcopter reach
about 1.1 times the tolerance). A solution that fails is FAILED (retried once from a cold start,
then the fallback). A state whose prediction A (x - x_ref) reaches OSQP's infinity (1e30) cannot
be posed (OSQP rejects the update and would return the previous problem's solution): it is
FAILED without a solve.
"""

from __future__ import annotations

import enum
import functools
import warnings
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import osqp
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from drake_abs._validation import as_count, as_finite_array, check_shape

REGULARIZATION = 1e-6
JacobianMethod = Literal["kkt", "osqp_adjoint"]


class MpcJacobianWarning(UserWarning):
    """The KKT matrix at the active set was singular (LICQ fails); a least-squares Jacobian was
    used."""


class MpcStatus(enum.IntEnum):
    """Outcome of one MPC solve (the integer is what the Drake system's status port carries)."""

    SOLVED = 0
    SOLVED_INACCURATE = 1
    MAX_ITER_REACHED = 2
    PRIMAL_INFEASIBLE = 3
    DUAL_INFEASIBLE = 4
    FAILED = 5  # non-convex, time limit, interrupted, unsolved, a non-finite solution, or one
    # that fails the re-check on the current data (module docstring, "Verification")


_OSQP_STATUS = {
    osqp.SolverStatus.OSQP_SOLVED: MpcStatus.SOLVED,
    osqp.SolverStatus.OSQP_SOLVED_INACCURATE: MpcStatus.SOLVED_INACCURATE,
    osqp.SolverStatus.OSQP_MAX_ITER_REACHED: MpcStatus.MAX_ITER_REACHED,
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE: MpcStatus.PRIMAL_INFEASIBLE,
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE_INACCURATE: MpcStatus.PRIMAL_INFEASIBLE,
    osqp.SolverStatus.OSQP_DUAL_INFEASIBLE: MpcStatus.DUAL_INFEASIBLE,
    osqp.SolverStatus.OSQP_DUAL_INFEASIBLE_INACCURATE: MpcStatus.DUAL_INFEASIBLE,
}

USABLE = (MpcStatus.SOLVED, MpcStatus.SOLVED_INACCURATE)  # statuses whose solution is applied

OSQP_INFINITY = 1e30  # OSQP treats bounds of at least this magnitude as infinite
VERIFY_FACTOR = 10.0  # slack on OSQP's tolerance when a returned solution is re-checked

#: The OSQP settings every :class:`QpMpc` starts from (its ``osqp_settings`` override them).
DEFAULT_OSQP_SETTINGS = {
    "eps_abs": 1e-6,
    "eps_rel": 1e-6,
    "max_iter": 20000,
    "polishing": True,
    "polish_refine_iter": 5,
    "warm_starting": True,
    "verbose": False,
}


# ---------------------------------------------------------------------------------------------
# theta <-> (Q, R, P)


@functools.lru_cache(maxsize=16)
def _tril(n: int) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = np.tril_indices(n)
    rows.flags.writeable = cols.flags.writeable = False
    return rows, cols


@dataclass(frozen=True)
class ThetaLayout:
    """Where p_Q, p_R and p_P sit in theta, for nx states and nu inputs."""

    nx: int
    nu: int

    @property
    def size(self) -> int:
        return self.nx + self.nu + self.nx * (self.nx + 1) // 2

    @property
    def q(self) -> slice:
        return slice(0, self.nx)

    @property
    def r(self) -> slice:
        return slice(self.nx, self.nx + self.nu)

    @property
    def p(self) -> slice:
        return slice(self.nx + self.nu, self.size)

    def tril(self) -> tuple[np.ndarray, np.ndarray]:
        """Row and column indices of the entries of L, in p_P order."""
        return _tril(self.nx)

    def lower_factor(self, theta: np.ndarray) -> np.ndarray:
        """L (nx, nx), lower triangular, from theta."""
        L = np.zeros((self.nx, self.nx))
        L[self.tril()] = theta[self.p]
        return L


def cost_matrices(theta, nx: int, nu: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Q (nx, nx), R (nu, nu), P (nx, nx)) of theta (docs/math.md section 9)."""
    layout = ThetaLayout(nx, nu)
    theta = as_finite_array(theta, "theta", ndim=(1,))
    check_shape(theta, (layout.size,), "theta", "(nx + nu + nx (nx + 1) / 2,)")
    Q = np.diag(theta[layout.q] ** 2) + REGULARIZATION * np.eye(nx)
    R = np.diag(theta[layout.r] ** 2) + REGULARIZATION * np.eye(nu)
    L = layout.lower_factor(theta)
    P = L @ L.T + REGULARIZATION * np.eye(nx)
    return Q, R, P


def theta_from_cost(q_diag, r_diag, P) -> np.ndarray:
    """theta with Q = diag(q_diag), R = diag(r_diag) and terminal cost P exactly: p_Q =
    sqrt(q_diag - 1e-6), p_R likewise, and L the Cholesky factor of P - 1e-6 I.

    Raises ``ValueError`` when a diagonal entry is below 1e-6 or P - 1e-6 I is not positive
    definite (such a matrix is not reachable by the parameterisation)."""
    q = as_finite_array(q_diag, "q_diag", ndim=(1,))
    r = as_finite_array(r_diag, "r_diag", ndim=(1,))
    P = as_finite_array(P, "P", ndim=(2,))
    check_shape(P, (q.size, q.size), "P", "(nx, nx)")
    for name, d in (("q_diag", q), ("r_diag", r)):
        if np.any(d < REGULARIZATION):
            raise ValueError(f"{name} entries must be >= {REGULARIZATION} (Q = diag(p^2) + 1e-6 I)")
    try:
        L = np.linalg.cholesky(0.5 * (P + P.T) - REGULARIZATION * np.eye(q.size))
    except np.linalg.LinAlgError as err:
        raise ValueError("P - 1e-6 I must be symmetric positive definite") from err
    layout = ThetaLayout(q.size, r.size)
    return np.concatenate(
        [np.sqrt(q - REGULARIZATION), np.sqrt(r - REGULARIZATION), L[layout.tril()]]
    )


def riccati_terminal_cost(A, B, Q, R) -> tuple[np.ndarray, np.ndarray]:
    """(P, K): the stabilising solution P of the discrete algebraic Riccati equation for
    x+ = A x + B u with stage cost x'Qx + u'Ru (scipy), and the LQR gain K, u = -K x."""
    P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    P = 0.5 * (P + P.T)
    K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    return P, K


# ---------------------------------------------------------------------------------------------
# the problem


def check_bounds(lo: np.ndarray, hi: np.ndarray, lo_name: str, hi_name: str) -> None:
    """Raise ``ValueError`` naming the bound unless lo <= hi componentwise, with -inf (lower) and
    +inf (upper) meaning "no bound". A lower bound of +inf or an upper bound of -inf would pin
    the variable at infinity, which no finite value satisfies (and OSQP rejects), so they are
    errors rather than an infeasible problem."""
    for name, v, bad, allowed in ((lo_name, lo, np.inf, "-inf"), (hi_name, hi, -np.inf, "+inf")):
        if np.any(v == bad):
            i = int(np.flatnonzero(v == bad)[0])
            raise ValueError(
                f"{name} entries must be finite or {allowed} (no bound); got {v[i]} at index {i}"
            )
    if np.any(lo > hi):
        raise ValueError(f"{lo_name} must be <= {hi_name} componentwise")


@dataclass(frozen=True)
class MpcSpec:
    """The MPC problem data (everything except x and theta).

    Attributes:
        A, B: (nx, nx), (nx, nu) linear prediction model in deviations from (x_ref, u_ref).
        horizon: N >= 1.
        x_ref, u_ref: (nx,), (nu,) reference state and input (u_ref: e.g. hover).
        u_min, u_max: (nu,) input box (absolute units; -inf in u_min / +inf in u_max for no
            bound; +inf in u_min or -inf in u_max is an error).
        x_min, x_max: (nx,) state box (absolute; -inf / +inf where a component is
            unconstrained, as for the inputs).
        slack_linear, slack_quadratic: rho_l, rho_q >= 0 of the slack penalty
            rho_q ||s||^2 + rho_l 1's (rho_q > 0 keeps the QP strictly convex).
        soft_state_constraints: soften the state box with slacks (default) or keep it hard.
    """

    A: np.ndarray
    B: np.ndarray
    horizon: int = 12
    x_ref: np.ndarray | None = None
    u_ref: np.ndarray | None = None
    u_min: np.ndarray | None = None
    u_max: np.ndarray | None = None
    x_min: np.ndarray | None = None
    x_max: np.ndarray | None = None
    slack_linear: float = 25.0
    slack_quadratic: float = 25.0
    soft_state_constraints: bool = True

    def __post_init__(self):
        A = as_finite_array(self.A, "A", ndim=(2,)).copy()
        B = as_finite_array(self.B, "B", ndim=(2,)).copy()
        nx, nu = B.shape
        check_shape(A, (nx, nx), "A", "(nx, nx)")
        horizon = as_count(self.horizon, "horizon", minimum=1)
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "B", B)
        object.__setattr__(self, "horizon", horizon)
        for name, n in (("x_ref", nx), ("u_ref", nu)):
            v = getattr(self, name)
            v = np.zeros(n) if v is None else as_finite_array(v, name, ndim=(1,)).copy()
            check_shape(v, (n,), name, "(nx,)" if n == nx else "(nu,)")
            object.__setattr__(self, name, v)
        for lo_name, hi_name, n in (("u_min", "u_max", nu), ("x_min", "x_max", nx)):
            lo, hi = getattr(self, lo_name), getattr(self, hi_name)
            lo = np.full(n, -np.inf) if lo is None else np.array(lo, dtype=float)
            hi = np.full(n, np.inf) if hi is None else np.array(hi, dtype=float)
            for name, v in ((lo_name, lo), (hi_name, hi)):
                check_shape(v, (n,), name, "(nx,)" if n == nx else "(nu,)")
                if np.any(np.isnan(v)):
                    raise ValueError(f"{name} contains NaN")
            check_bounds(lo, hi, lo_name, hi_name)
            object.__setattr__(self, lo_name, lo)
            object.__setattr__(self, hi_name, hi)
        for name in ("slack_linear", "slack_quadratic"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0; got {v!r}")
        if self.soft_state_constraints and self.slack_quadratic <= 0:
            raise ValueError("slack_quadratic must be > 0 with soft state constraints")

    @property
    def nx(self) -> int:
        return self.B.shape[0]

    @property
    def nu(self) -> int:
        return self.B.shape[1]

    @property
    def constrained_states(self) -> np.ndarray:
        """Indices of the state components with a finite bound."""
        return np.flatnonzero(np.isfinite(self.x_min) | np.isfinite(self.x_max))

    @property
    def fallback_input(self) -> np.ndarray:
        """The documented fallback control, u_ref projected on the input box."""
        return np.clip(self.u_ref, self.u_min, self.u_max)


@dataclass(frozen=True)
class MpcSolution:
    """One MPC solve. ``u0`` is always finite (the fallback when the QP was not solved).

    Attributes:
        u0: (nu,) control to apply (absolute units).
        status: :class:`MpcStatus`; ``fallback`` is True unless SOLVED or SOLVED_INACCURATE.
        fallback: whether u0 is the fallback control clip(u_ref, u_min, u_max).
        iterations: OSQP ADMM iterations.
        polished: whether OSQP's polishing succeeded.
        primal_residual: OSQP's primal residual.
        dual_residual: OSQP's dual residual.
        objective: the QP's optimal value (without the constant dx_0' Q dx_0); nan when not solved.
        u_plan: (N, nu) the predicted inputs, absolute (None when not solved).
        x_plan: (N + 1, nx) the predicted states, absolute, ``x_plan[0] = x`` (None when not
            solved).
        slack: (N, n_c) the predicted trajectory's slacks (None when not solved).
        du0_dx: (nu, nx) Jacobian of u0 (None unless requested; zero for a fallback control).
        du0_dtheta: (nu, n_theta) Jacobian of u0 (None unless requested; zero for a fallback
            control).
        active: number of active inequality rows; weakly_active: rows at a bound with a
            multiplier below the tolerance (treated as inactive).
    """

    u0: np.ndarray
    status: MpcStatus
    fallback: bool
    iterations: int
    polished: bool
    primal_residual: float
    dual_residual: float
    objective: float
    u_plan: np.ndarray | None = None
    x_plan: np.ndarray | None = None
    slack: np.ndarray | None = None
    du0_dx: np.ndarray | None = None
    du0_dtheta: np.ndarray | None = None
    active: int = 0
    weakly_active: int = 0


def _input_scale(spec: MpcSpec) -> np.ndarray:
    """S (nu,): per input, the distance from u_ref to its nearest finite bound (1 when both
    bounds are infinite or u_ref sits on one)."""
    gaps = np.stack([spec.u_max - spec.u_ref, spec.u_ref - spec.u_min])
    gaps = np.where(np.isfinite(gaps) & (gaps > 0), gaps, np.inf)
    S = gaps.min(axis=0)
    return np.where(np.isfinite(S), S, 1.0)


@dataclass
class _Structure:
    """Index bookkeeping of the QP (built once per spec)."""

    n: int  # variables
    m: int  # constraint rows
    nu_blk: int  # N nu
    nx_blk: int  # N nx
    ns: int  # slacks per stage
    G: sp.csc_matrix  # (m, n)
    lower: np.ndarray  # (m,) template
    upper: np.ndarray
    n_eq: int  # leading equality rows (dynamics)
    h: np.ndarray  # (n,) linear cost
    scale: np.ndarray  # (nu,) input scale S
    g_rows: np.ndarray  # G in coordinates
    g_cols: np.ndarray
    g_vals: np.ndarray
    p_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # triu pattern of H
    p_cols: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    p_indptr: np.ndarray = field(default_factory=lambda: np.zeros(0, int))


def _build_structure(spec: MpcSpec) -> _Structure:
    N, nx, nu = spec.horizon, spec.nx, spec.nu
    c = spec.constrained_states
    soft = spec.soft_state_constraints
    ns = c.size if soft else 0
    nu_blk, nx_blk = N * nu, N * nx
    n = nu_blk + nx_blk + N * ns
    iu, ix, isl = 0, nu_blk, nu_blk + nx_blk  # offsets of the blocks in z

    S = _input_scale(spec)

    def xcol(k):  # columns of dx_k, k = 1..N
        return ix + (k - 1) * nx

    # dynamics: dx_{k+1} - A dx_k - B du_k = (A dx_0 for k = 0, else 0)
    dyn = sp.lil_matrix((nx_blk, n))
    for k in range(N):
        rows = slice(k * nx, (k + 1) * nx)
        dyn[rows, xcol(k + 1) : xcol(k + 1) + nx] = np.eye(nx)
        if k >= 1:
            dyn[rows, xcol(k) : xcol(k) + nx] = -spec.A
        dyn[rows, iu + k * nu : iu + (k + 1) * nu] = -spec.B * S
    blocks = [dyn.tocsr()]
    lower = [np.zeros(nx_blk)]
    upper = [np.zeros(nx_blk)]
    # input box
    blocks.append(sp.hstack([sp.eye(nu_blk), sp.csr_matrix((nu_blk, n - nu_blk))]).tocsr())
    lower.append(np.tile((spec.u_min - spec.u_ref) / S, N))
    upper.append(np.tile((spec.u_max - spec.u_ref) / S, N))
    # state constraints on dx_1..dx_N, components c
    sel = sp.lil_matrix((N * c.size, n))
    for k in range(1, N + 1):
        for j, i in enumerate(c):
            sel[(k - 1) * c.size + j, xcol(k) + i] = 1.0
    sel = sel.tocsr()
    x_lo = np.tile(spec.x_min[c] - spec.x_ref[c], N)
    x_hi = np.tile(spec.x_max[c] - spec.x_ref[c], N)
    if soft and c.size:
        slack = sp.hstack([sp.csr_matrix((N * ns, isl)), sp.eye(N * ns)]).tocsr()
        blocks += [sel - slack, sel + slack, slack]
        lower += [np.full(N * ns, -np.inf), x_lo, np.zeros(N * ns)]
        upper += [x_hi, np.full(N * ns, np.inf), np.full(N * ns, np.inf)]
    elif c.size:
        blocks.append(sel)
        lower.append(x_lo)
        upper.append(x_hi)
    G = sp.vstack(blocks).tocsc()
    G.sort_indices()
    Gc = G.tocoo()
    h = np.zeros(n)
    h[isl:] = spec.slack_linear
    st = _Structure(
        n=n,
        m=G.shape[0],
        nu_blk=nu_blk,
        nx_blk=nx_blk,
        ns=ns,
        G=G,
        lower=np.concatenate(lower),
        upper=np.concatenate(upper),
        n_eq=nx_blk,
        h=h,
        scale=S,
        g_rows=Gc.row.astype(np.int64),
        g_cols=Gc.col.astype(np.int64),
        g_vals=Gc.data.copy(),
    )
    # sparsity pattern of triu(H): diagonal everywhere plus the full upper triangle of P's block
    pattern = np.eye(n, dtype=bool)
    pN = slice(xcol(N), xcol(N) + nx)
    pattern[pN, pN] = np.triu(np.ones((nx, nx), dtype=bool))
    Pcsc = sp.csc_matrix(pattern.astype(float))
    Pcsc.sort_indices()
    st.p_indptr = Pcsc.indptr.copy()
    st.p_rows = Pcsc.indices.copy()
    st.p_cols = np.repeat(np.arange(n), np.diff(Pcsc.indptr))
    return st


class QpMpc:
    """The QP-MPC of :class:`MpcSpec`, solved by one warm-started OSQP instance.

    Args:
        spec: the problem data.
        theta: initial cost parameters (n_theta,); default: Q = R = I (p = 1), P = I.
        osqp_settings: overrides of :data:`DEFAULT_OSQP_SETTINGS` (OSQP 1.x names, e.g.
            ``polishing``, ``eps_abs``, ``max_iter``).
        dual_tolerance: relative multiplier threshold of the active-set rule (module docstring).
    """

    def __init__(
        self,
        spec: MpcSpec,
        theta=None,
        *,
        osqp_settings: dict | None = None,
        dual_tolerance: float = 1e-9,
    ):
        if not isinstance(spec, MpcSpec):
            raise ValueError(f"spec must be an MpcSpec; got {type(spec).__name__}")
        if not (np.isfinite(dual_tolerance) and dual_tolerance >= 0):
            raise ValueError(f"dual_tolerance must be finite and >= 0; got {dual_tolerance!r}")
        self.spec = spec
        self.layout = ThetaLayout(spec.nx, spec.nu)
        self.dual_tolerance = float(dual_tolerance)
        self.settings = {**DEFAULT_OSQP_SETTINGS, **(osqp_settings or {})}
        self._st = _build_structure(spec)
        if theta is None:
            theta = np.concatenate(
                [np.ones(spec.nx + spec.nu), np.eye(spec.nx)[self.layout.tril()]]
            )
        self._theta = None
        self._H = None
        self._set_theta_arrays(self._check_theta(theta))
        st = self._st
        P = sp.csc_matrix((self._px, st.p_rows, st.p_indptr), shape=(st.n, st.n))
        self._osqp = osqp.OSQP()
        self._osqp.setup(P, st.h.copy(), st.G, st.lower.copy(), st.upper.copy(), **self.settings)
        self.solves = 0  # QP solves so far
        self.retries = 0  # of which retried from a cold start

    # -- parameters -----------------------------------------------------------------------

    @property
    def n_theta(self) -> int:
        return self.layout.size

    @property
    def theta(self) -> np.ndarray:
        return self._theta.copy()

    def _check_theta(self, theta) -> np.ndarray:
        theta = as_finite_array(theta, "theta", ndim=(1,))
        check_shape(theta, (self.n_theta,), "theta", "(n_theta,)")
        return theta

    def _set_theta_arrays(self, theta: np.ndarray) -> None:
        spec, st = self.spec, self._st
        N, nx, nu = spec.horizon, spec.nx, spec.nu
        Q, R, P = cost_matrices(theta, nx, nu)
        d = np.empty(st.n)
        d[: st.nu_blk] = np.tile(np.diag(R) * st.scale**2, N)
        d[st.nu_blk : st.nu_blk + (N - 1) * nx] = np.tile(np.diag(Q), N - 1)
        d[st.nu_blk + (N - 1) * nx : st.nu_blk + st.nx_blk] = np.diag(P)
        d[st.nu_blk + st.nx_blk :] = spec.slack_quadratic
        H = sp.diags(2.0 * d).tolil()
        pN = slice(st.nu_blk + (N - 1) * nx, st.nu_blk + st.nx_blk)
        H[pN, pN] = 2.0 * P
        H = H.tocoo()
        self._h_coo = (H.row.astype(np.int64), H.col.astype(np.int64), H.data.copy())
        Hd_triu = np.zeros(st.p_rows.size)
        diag_mask = st.p_rows == st.p_cols
        Hd_triu[diag_mask] = 2.0 * d[st.p_rows[diag_mask]]
        off = ~diag_mask
        o = pN.start
        Hd_triu[off] = 2.0 * P[st.p_rows[off] - o, st.p_cols[off] - o]
        self._px = Hd_triu
        self._theta = theta.copy()
        self._Q, self._R, self._P = Q, R, P

    def set_theta(self, theta) -> None:
        """Change the cost parameters (n_theta,) (raises ``ValueError`` if not finite/shaped)."""
        theta = self._check_theta(theta)
        if self._theta is not None and np.array_equal(theta, self._theta):
            return
        self._set_theta_arrays(theta)
        self._osqp.update(Px=self._px)

    # -- solve ----------------------------------------------------------------------------

    def solve(
        self,
        x,
        theta=None,
        *,
        jacobians: bool = False,
        method: JacobianMethod = "kkt",
    ) -> MpcSolution:
        """Solve the QP at state ``x`` (nx,) (absolute units), with ``theta`` (n_theta,) if
        given (else the current parameters).

        Args:
            jacobians: also compute du0/dx (nu, nx) and du0/dtheta (nu, n_theta).
            method: ``"kkt"`` (the adjoint KKT solve of the module docstring) or
                ``"osqp_adjoint"`` (OSQP's adjoint derivative, one call per input component).

        Raises:
            ValueError: non-finite or misshaped ``x`` or ``theta``; unknown ``method``.
        """
        spec, st = self.spec, self._st
        x = as_finite_array(x, "x", ndim=(1,))
        check_shape(x, (spec.nx,), "x", "(nx,)")
        if method not in ("kkt", "osqp_adjoint"):
            raise ValueError(f"method must be 'kkt' or 'osqp_adjoint'; got {method!r}")
        if theta is not None:
            self.set_theta(theta)
        dx0 = x - spec.x_ref
        lower, upper = st.lower.copy(), st.upper.copy()
        with np.errstate(over="ignore", invalid="ignore"):
            b = spec.A @ dx0
        if not np.all(np.abs(b) < OSQP_INFINITY):
            # OSQP reads |values| >= 1e30 as infinite and rejects the update: solving anyway
            # would return the previous problem's solution, so nothing is solved
            zeros = (np.zeros((spec.nu, spec.nx)), np.zeros((spec.nu, self.n_theta)))
            return MpcSolution(
                u0=spec.fallback_input.copy(),
                status=MpcStatus.FAILED,
                fallback=True,
                iterations=0,
                polished=False,
                primal_residual=float("nan"),
                dual_residual=float("nan"),
                objective=float("nan"),
                du0_dx=zeros[0] if jacobians else None,
                du0_dtheta=zeros[1] if jacobians else None,
            )
        lower[: spec.nx] = upper[: spec.nx] = b
        self._osqp.update(l=lower, u=upper)
        res = self._osqp.solve(raise_error=False)
        self.solves += 1
        status = self._checked_status(res, lower, upper)
        if status in (MpcStatus.SOLVED_INACCURATE, MpcStatus.MAX_ITER_REACHED, MpcStatus.FAILED):
            # one retry from a cold start: a warm start from a distant state can stall ADMM
            self._osqp.warm_start(x=np.zeros(st.n), y=np.zeros(st.m))
            res = self._osqp.solve(raise_error=False)
            self.retries += 1
            status = self._checked_status(res, lower, upper)
        info = res.info
        z = np.asarray(res.x, dtype=float)
        y = np.asarray(res.y, dtype=float)
        common = {
            "iterations": int(info.iter),
            "polished": int(info.status_polish) == 1,
            "primal_residual": float(info.prim_res),
            "dual_residual": float(info.dual_res),
        }
        if status not in USABLE:
            self._osqp.warm_start(x=np.zeros(st.n), y=np.zeros(st.m))  # drop a bad iterate
            zeros = (np.zeros((spec.nu, spec.nx)), np.zeros((spec.nu, self.n_theta)))
            return MpcSolution(
                u0=spec.fallback_input.copy(),
                status=status,
                fallback=True,
                objective=float("nan"),
                du0_dx=zeros[0] if jacobians else None,
                du0_dtheta=zeros[1] if jacobians else None,
                **common,
            )
        N, nx, nu = spec.horizon, spec.nx, spec.nu
        du = z[: st.nu_blk].reshape(N, nu) * st.scale
        dxs = z[st.nu_blk : st.nu_blk + st.nx_blk].reshape(N, nx)
        u_plan = du + spec.u_ref
        x_plan = np.vstack([x, dxs + spec.x_ref])
        slack = z[st.nu_blk + st.nx_blk :].reshape(N, st.ns)
        active, weak, act_count = self._active_set(z, y, lower, upper)
        du0_dx = du0_dtheta = None
        if jacobians:
            if method == "kkt" or status != MpcStatus.SOLVED:  # OSQP's adjoint needs SOLVED
                du0_dx, du0_dtheta = self._kkt_jacobians(z, active)
            else:
                du0_dx, du0_dtheta = self._osqp_adjoint_jacobians(z)
        return MpcSolution(
            u0=u_plan[0].copy(),
            status=status,
            fallback=False,
            objective=float(info.obj_val),
            u_plan=u_plan,
            x_plan=x_plan,
            slack=slack,
            du0_dx=du0_dx,
            du0_dtheta=du0_dtheta,
            active=act_count,
            weakly_active=weak,
            **common,
        )

    def _checked_status(self, res, lower: np.ndarray, upper: np.ndarray) -> MpcStatus:
        """OSQP's status of ``res``, demoted to FAILED when a solution it calls solved is not
        finite or does not satisfy the current problem's constraints (module docstring:
        "Verification")."""
        status = _OSQP_STATUS.get(res.info.status_val, MpcStatus.FAILED)
        if status not in USABLE:
            return status
        z = np.asarray(res.x, dtype=float)
        y = np.asarray(res.y, dtype=float)
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(y))):
            return MpcStatus.FAILED
        st = self._st
        eps_abs, eps_rel = float(self.settings["eps_abs"]), float(self.settings["eps_rel"])
        gz = st.G @ z
        excess = np.maximum(lower - gz, 0.0) + np.maximum(gz - upper, 0.0)
        # every row, to OSQP's own primal criterion on the current data (a stale solution of a
        # previous problem fails its dynamics rows)
        finite = np.concatenate([lower[np.isfinite(lower)], upper[np.isfinite(upper)]])
        size = max(
            float(np.max(np.abs(gz), initial=0.0)), float(np.max(np.abs(finite), initial=0.0))
        )
        if np.max(excess, initial=0.0) > VERIFY_FACTOR * (eps_abs + eps_rel * size):
            return MpcStatus.FAILED
        # the hard input box, at the scale of its own bounds (not of the state, which can make
        # OSQP's relative criterion arbitrarily loose)
        box = slice(st.n_eq, st.n_eq + st.nu_blk)
        bounds = np.concatenate([lower[box], upper[box]])
        size = max(1.0, float(np.max(np.abs(bounds[np.isfinite(bounds)]), initial=0.0)))
        if np.max(excess[box], initial=0.0) > VERIFY_FACTOR * (eps_abs + eps_rel * size):
            return MpcStatus.FAILED
        return status

    def _active_set(self, z, y, lower, upper) -> tuple[np.ndarray, int, int]:
        """Indices of the active rows (equalities first, then by row), the number of weakly
        active rows, and the number of active inequality rows."""
        st = self._st
        tau = self.dual_tolerance * max(1.0, float(np.max(np.abs(y))) if y.size else 1.0)
        is_eq = np.zeros(st.m, dtype=bool)
        is_eq[: st.n_eq] = True
        strong = (np.abs(y) > tau) & ~is_eq
        gz = st.G @ z
        scale = 1e-7 * (1.0 + np.abs(gz))
        at_bound = (np.abs(gz - lower) <= scale) | (np.abs(gz - upper) <= scale)
        weak = int(np.sum(at_bound & ~strong & ~is_eq))
        rows = np.flatnonzero(is_eq | strong)
        return rows, weak, int(np.sum(strong))

    def _kkt_jacobians(self, z: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        spec, st = self.spec, self._st
        nx, nu = spec.nx, spec.nu
        # K = [[H, G_a'], [G_a, 0]] assembled from coordinate lists
        position = np.full(st.m, -1)
        position[active] = st.n + np.arange(active.size)
        keep = position[st.g_rows] >= 0
        gr, gc, gv = position[st.g_rows[keep]], st.g_cols[keep], st.g_vals[keep]
        hr, hc, hv = self._h_coo
        size = st.n + active.size
        K = sp.csc_matrix(
            (
                np.concatenate([hv, gv, gv]),
                (np.concatenate([hr, gr, gc]), np.concatenate([hc, gc, gr])),
            ),
            shape=(size, size),
        )
        rhs = np.zeros((size, nu))
        rhs[:nu, :nu] = np.eye(nu)
        try:
            W = spla.splu(K).solve(rhs)
        except RuntimeError:  # singular: LICQ fails at this active set
            warnings.warn(
                "MPC KKT matrix is singular at the active set (LICQ fails); using the "
                "least-squares solution for the Jacobian",
                MpcJacobianWarning,
                stacklevel=3,
            )
            W = np.linalg.lstsq(K.toarray(), rhs, rcond=None)[0]
        Wz, Wy = W[: st.n], W[st.n :]
        du0_dx = Wy[:nx].T @ spec.A  # first dynamics block: b = A (x - x_ref)
        S = st.scale[:, None]  # du_0 = S w_0
        return S * du0_dx, S * self._theta_gradient_from_adjoint(Wz, z)

    def _theta_gradient_from_adjoint(self, Wz: np.ndarray, z: np.ndarray) -> np.ndarray:
        """-Wz' (dH/dtheta) z for Wz (n, k): (k, n_theta)."""
        spec, st, lay = self.spec, self._st, self.layout
        N, nx, nu = spec.horizon, spec.nx, spec.nu
        th = self._theta
        k = Wz.shape[1]
        out = np.zeros((k, self.n_theta))
        Wu = Wz[: st.nu_blk].reshape(N, nu, k)
        zu = z[: st.nu_blk].reshape(N, nu)
        out[:, lay.r] = -4.0 * th[lay.r] * st.scale**2 * np.einsum("tjo,tj->oj", Wu, zu)
        Wx = Wz[st.nu_blk : st.nu_blk + st.nx_blk].reshape(N, nx, k)
        zx = z[st.nu_blk : st.nu_blk + st.nx_blk].reshape(N, nx)
        out[:, lay.q] = -4.0 * th[lay.q] * np.einsum("tjo,tj->oj", Wx[:-1], zx[:-1])
        L = lay.lower_factor(th)
        w, zN = Wx[-1], zx[-1]  # (nx, k), (nx,)
        Lz, Lw = L.T @ zN, L.T @ w
        grad_L = -2.0 * (np.einsum("ao,b->oab", w, Lz) + np.einsum("a,bo->oab", zN, Lw))
        rows, cols = lay.tril()
        out[:, lay.p] = grad_L[:, rows, cols]
        return out

    def _osqp_adjoint_jacobians(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        spec, st = self.spec, self._st
        nx, nu = spec.nx, spec.nu
        du0_dx = np.zeros((nu, nx))
        sym = np.zeros((nu, st.n, st.n))
        for i in range(nu):
            e = np.zeros(st.n)
            e[i] = 1.0
            self._osqp.adjoint_derivative_compute(dx=e)
            dP, _ = self._osqp.adjoint_derivative_get_mat(as_dense=True, dP_as_triu=False)
            _, dl, du = self._osqp.adjoint_derivative_get_vec()
            du0_dx[i] = (dl[:nx] + du[:nx]) @ spec.A
            sym[i] = np.asarray(dP)
        S = st.scale[:, None]
        # d u0_i / dH (symmetric gradient) -> theta, through the same structure as the KKT path:
        # a symmetric gradient S equals -1/2 (W z' + z W'), so (-W' dH z) = sum(S * dH).
        return S * du0_dx, S * self._theta_gradient_from_symmetric(sym)

    def _theta_gradient_from_symmetric(self, S: np.ndarray) -> np.ndarray:
        """sum_ab S[o, a, b] dH_ab / dtheta for symmetric S (k, n, n): (k, n_theta)."""
        spec, st, lay = self.spec, self._st, self.layout
        N, nx, nu = spec.horizon, spec.nx, spec.nu
        th = self._theta
        k = S.shape[0]
        out = np.zeros((k, self.n_theta))
        diag = np.einsum("oii->oi", S)
        du = diag[:, : st.nu_blk].reshape(k, N, nu).sum(axis=1)
        dq = diag[:, st.nu_blk : st.nu_blk + (N - 1) * nx].reshape(k, N - 1, nx).sum(axis=1)
        out[:, lay.r] = 4.0 * th[lay.r] * st.scale**2 * du
        out[:, lay.q] = 4.0 * th[lay.q] * dq
        o = st.nu_blk + (N - 1) * nx
        SN = S[:, o : o + nx, o : o + nx]
        L = lay.lower_factor(th)
        grad_L = 2.0 * np.einsum("oab,bc->oac", SN + SN.transpose(0, 2, 1), L)
        rows, cols = lay.tril()
        out[:, lay.p] = grad_L[:, rows, cols]
        return out
