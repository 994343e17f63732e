"""The mu-softened linear complementarity system (docs/math.md section 1 and 4).

    x+ = A x + B u + C lam + c
    z  = D x + E u + d,        s = z + F lam,        lam >= 0, s >= 0, lam_i s_i = mu_i

:meth:`LCS.step` is the single implementation of one step: the batched core, rollouts and the
Drake system (``drake_abs.systems.LcsPlant``) all call it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from drake_abs._validation import as_finite_array, check_shape
from drake_abs.contact.smoothing import Exact, Smoothing
from drake_abs.contact.step import Step
from drake_abs.contact.unconverged import exact_fallback
from drake_abs.lcp.ipm import (
    SOLVER_DEFAULTS,
    OnBadMatrix,
    apply_matrix_policy,
    check_solver_options,
    solve_lcp_trusted,
)
from drake_abs.lcp.matrix_class import MatrixClass

#: How a step differentiates a state-dependent mu, ``"total"`` (the default everywhere: the true
#: derivative of the step) or ``"frozen"`` (mu held constant, Zhang et al. 2023, Algorithm 1; biased
#: where mu varies with the state, exact for Exact and Fixed smoothing).
GradientMode = Literal["frozen", "total"]


def check_gradient_mode(gradient, name: str = "gradient") -> None:
    """Raise ``ValueError`` naming ``name`` unless ``gradient`` is ``"frozen"`` or ``"total"``."""
    if gradient not in ("frozen", "total"):
        raise ValueError(f"{name} must be 'frozen' or 'total'; got {gradient!r}")


@dataclass(frozen=True)
class LCS:
    """A linear complementarity system with state dimension dx, input du and d contacts.

    Matrices: A (dx, dx), B (dx, du), C (dx, d), c (dx,), D (d, dx), E (d, du), F (d, d),
    d (d,). F is checked once at construction (positive semidefinite or P-matrix, see
    :mod:`drake_abs.lcp.matrix_class`) according to ``on_bad_matrix``.

    ``time_step`` (s) is the step h the matrices were built for (a discretised system's
    matrices contain h): the one place a Drake system (:class:`drake_abs.systems.LcsPlant`)
    reads its update period from. None for an LCS that is not a time discretisation.

    The matrices are also the model parameters of the step (:attr:`parameter_names`):
    ``step(..., parameters=True)`` differentiates with respect to every entry.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    c: np.ndarray
    D: np.ndarray
    E: np.ndarray
    F: np.ndarray
    d: np.ndarray
    on_bad_matrix: OnBadMatrix = "raise"
    solver_options: dict = field(default_factory=dict)
    time_step: float | None = None

    def __post_init__(self):
        if self.time_step is not None:
            h = self.time_step
            if isinstance(h, bool) or not isinstance(h, int | float) or not (0 < h < np.inf):
                raise ValueError(
                    f"LCS.time_step must be a finite number > 0 (s) or None; got {h!r}"
                )
            object.__setattr__(self, "time_step", float(h))
        arrays = {}
        for name in "ABCcDEFd":
            want = (1,) if name in "cd" else (2,)
            # a private copy: the LCS freezes its matrices, never the caller's arrays
            arrays[name] = as_finite_array(getattr(self, name), f"LCS.{name}", ndim=want).copy()
        nx = arrays["A"].shape[0]
        nu = arrays["B"].shape[1]
        nc = arrays["F"].shape[0]
        forms = {
            "A": ((nx, nx), "(dx, dx)"),
            "B": ((nx, nu), "(dx, du)"),
            "C": ((nx, nc), "(dx, d)"),
            "c": ((nx,), "(dx,)"),
            "D": ((nc, nx), "(d, dx)"),
            "E": ((nc, nu), "(d, du)"),
            "F": ((nc, nc), "(d, d)"),
            "d": ((nc,), "(d,)"),
        }
        for name, (shape, form) in forms.items():
            check_shape(arrays[name], shape, f"LCS.{name}", form)
        unknown = set(self.solver_options) - {"tol", "max_iterations", "exact_tol"}
        if unknown:
            raise ValueError(
                "LCS.solver_options may set tol, max_iterations and exact_tol; "
                f"got {sorted(unknown)}"
            )
        check_solver_options(**{**SOLVER_DEFAULTS, **self.solver_options})
        # One matrix check here, so that every step can skip it.
        arrays["F"], _, classes = apply_matrix_policy(arrays["F"], self.on_bad_matrix)
        # verified: PSD, a P-matrix, or regularised to a positive definite symmetric part; a
        # matrix no cheap test could classify (d > 10) is attempted and its answers verified
        verified = self.on_bad_matrix != "attempt" and int(classes[0]) != MatrixClass.UNVERIFIED
        object.__setattr__(self, "_step_check", "trusted" if verified else "attempt")
        for name, arr in arrays.items():
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def dims(self) -> tuple[int, int, int]:
        """``(dx, du, d)``."""
        return self.A.shape[0], self.B.shape[1], self.F.shape[0]

    #: The matrices in the order of :attr:`parameter_names`.
    MATRICES = ("A", "B", "C", "c", "D", "E", "F", "d")

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Every matrix entry, matrix by matrix in :data:`MATRICES` order, row-major:
        ``"A[0,0]", "A[0,1]", ..., "c[0]", ..., "d[d-1]"``."""
        names = []
        for name in self.MATRICES:
            M = getattr(self, name)
            if M.ndim == 1:
                names += [f"{name}[{i}]" for i in range(M.shape[0])]
            else:
                names += [f"{name}[{i},{j}]" for i in range(M.shape[0]) for j in range(M.shape[1])]
        return tuple(names)

    def parameter_values(self) -> np.ndarray:
        """The matrices' entries (T,), in the order of :attr:`parameter_names`."""
        return np.concatenate([getattr(self, name).ravel() for name in self.MATRICES])

    def with_parameters(self, values) -> LCS:
        """The same system with the matrix entries ``values`` (T,) (checked as at construction)."""
        values = np.asarray(values, dtype=float).reshape(-1)
        sizes = [getattr(self, name).size for name in self.MATRICES]
        if values.shape != (sum(sizes),):
            raise ValueError(
                f"LCS.with_parameters: values must have shape ({sum(sizes)},) (the entries of "
                f"{', '.join(self.MATRICES)}); got {values.shape}"
            )
        parts = np.split(values, np.cumsum(sizes)[:-1])
        new = {
            n: v.reshape(getattr(self, n).shape) for n, v in zip(self.MATRICES, parts, strict=True)
        }
        return replace(self, **new)

    def contact_distance(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``z = D x + E u + d`` for batched x (B, dx), u (B, du); returns (B, d)."""
        return x @ self.D.T + u @ self.E.T + self.d

    def _inputs(self, x, u) -> tuple[np.ndarray, np.ndarray, bool]:
        nx, nu, _ = self.dims
        x = as_finite_array(x, "x", ndim=(1, 2))
        single = x.ndim == 1
        X = x[None] if single else x
        if X.shape[1] != nx:
            raise ValueError(f"x must have shape (dx,) or (B, dx) with dx = {nx}; got {x.shape}")
        u = as_finite_array(u, "u", ndim=(1, 2))
        U = np.broadcast_to(u, (X.shape[0], nu)) if u.shape in ((nu,), (1, nu)) else u
        if U.shape != (X.shape[0], nu):
            raise ValueError(
                f"u must have shape (du,) or (B, du) = ({X.shape[0]}, {nu}) to match x; "
                f"got {u.shape}"
            )
        return X, U, single

    def step(
        self,
        x,
        u,
        smoothing: Smoothing | None = None,
        *,
        gradient: GradientMode = "total",
        jacobians: bool = True,
        strict: bool = False,
        parameters: bool = False,
        smoothing_parameters: bool = False,
    ) -> Step:
        """Advance a batch of states one step.

        Args:
            x: (dx,) or (B, dx) states.
            u: (du,) or (B, du) inputs (one input broadcasts over the batch).
            smoothing: mu per contact (default :class:`Exact`); larger mu is smoother.
            gradient: ``"total"`` (default) also differentiates mu(z) through z: the derivative
                of the step as computed. ``"frozen"`` treats mu as a constant (Zhang et al. 2023,
                Algorithm 1): biased wherever mu depends on the state.
            jacobians: compute dx+/dx, dx+/du and the impulse (lam) and mu Jacobians.
            strict: raise instead of warning when the LCP solve does not converge.
            parameters: also ``dx_dtheta`` (B, dx, T) and ``dimpulse_dtheta`` (B, d, T) with
                respect to every matrix entry (:attr:`parameter_names`; F enters as
                ``s = z + F lam``, so ``dlam/dF_ij = dlam/dq_i lam_j``).
            smoothing_parameters: also (after the matrices' columns, if any) the columns of
                the smoothing's numeric parameters (``"smoothing.<name>"``), at fixed z:
                in both gradient modes, since they set mu's value rather than its dependence
                on the state.

        Returns:
            a :class:`~drake_abs.contact.step.Step`; ``impulse`` is lam (B, d).
        """
        check_gradient_mode(gradient)
        if (parameters or smoothing_parameters) and not jacobians:
            raise ValueError("parameters=True and smoothing_parameters=True need jacobians=True")
        smoothing = Exact() if smoothing is None else smoothing
        X, U, single = self._inputs(x, u)
        z = self.contact_distance(X, U)
        mu = smoothing.mu(z, self.F)
        mu = np.asarray(mu, dtype=float)
        if mu.shape != z.shape or not (np.all(mu >= 0) and np.all(np.isfinite(mu))):
            raise ValueError(
                f"smoothing {smoothing!r} must return a finite mu >= 0 of shape {z.shape}; got "
                f"shape {mu.shape}, min {float(np.min(mu)) if mu.size else None}"
            )
        monotone = self._step_check == "trusted"
        options = self.solver_options
        lcp = solve_lcp_trusted(
            self.F, z, mu, jacobians=jacobians, strict=strict, monotone=monotone, **options
        )
        lcp = exact_fallback(self.F, z, mu, lcp, jacobians=jacobians, monotone=monotone, **options)
        x_next = X @ self.A.T + U @ self.B.T + lcp.lam @ self.C.T + self.c
        jac = {}
        if jacobians:
            dlam_dz = lcp.dlam_dq
            dmu_dz = smoothing.dmu_dz(z, self.F) if gradient == "total" else None
            if dmu_dz is not None:
                dlam_dz = dlam_dz + lcp.dlam_dmu @ dmu_dz
            dlam_dx = dlam_dz @ self.D
            dlam_du = dlam_dz @ self.E
            jac = {
                "dx_dx": self.A + self.C @ dlam_dx,
                "dx_du": self.B + self.C @ dlam_du,
                "dimpulse_dx": dlam_dx,
                "dimpulse_du": dlam_du,
            }
            if dmu_dz is None:
                jac["dmu_dx"], jac["dmu_du"] = np.zeros(dlam_dx.shape), np.zeros(dlam_du.shape)
            else:
                jac["dmu_dx"], jac["dmu_du"] = dmu_dz @ self.D, dmu_dz @ self.E
            if parameters or smoothing_parameters:
                names, dx_dt, dlam_dt, dmu_dt = self._parameter_jacobians(
                    X, U, z, lcp, smoothing, dmu_dz, parameters, smoothing_parameters
                )
                jac.update(
                    dx_dtheta=dx_dt, dimpulse_dtheta=dlam_dt, dmu_dtheta=dmu_dt, theta_names=names
                )
        out = Step(
            x_next=x_next,
            converged=lcp.converged,
            iterations=lcp.iterations,
            impulse=lcp.lam,
            mu=lcp.mu,
            lcp=lcp,
            **jac,
        )
        return out.first() if single else out

    def _parameter_jacobians(self, X, U, z, lcp, smoothing, dmu_dz, model, smooth):
        """The theta columns of one batched step: (names, dx+/dtheta (B, dx, T), dlam/dtheta
        (B, d, T)). dmu_dz is None in the frozen mode (mu's dependence on z and F held)."""
        nx, nu, nc = self.dims
        Bn = X.shape[0]
        lam = lcp.lam
        direct, dz, dmu, names = [], [], [], []
        if model:
            names += self.parameter_names
            Ix, Ic = np.eye(nx), np.eye(nc)

            def outer(I, v):  # d(M v)/dM for every entry of M: (B, rows, rows * len(v))
                return np.einsum("ik,bj->bikj", I, v).reshape(Bn, I.shape[0], -1)

            blocks = {  # matrix: (d x+ directly, d z, d q of the LCP beyond z)
                "A": (outer(Ix, X), None),
                "B": (outer(Ix, U), None),
                "C": (outer(Ix, lam), None),
                "c": (np.broadcast_to(Ix, (Bn, nx, nx)), None),
                "D": (None, outer(Ic, X)),
                "E": (None, outer(Ic, U)),
                "F": (None, None),
                "d": (None, np.broadcast_to(Ic, (Bn, nc, nc))),
            }
            for name in self.MATRICES:
                size = getattr(self, name).size
                dx_direct, dz_m = blocks[name]
                direct.append(dx_direct if dx_direct is not None else np.zeros((Bn, nx, size)))
                if name == "F":  # s = z + F lam: the LCP's q moves by dF lam, z does not
                    q_shift = outer(Ic, lam)
                    dz.append(q_shift)
                    dmu_F = np.zeros((Bn, nc, size))
                    if dmu_dz is not None:  # mu may read F's diagonal (GaussianMatched)
                        diagonal = smoothing.dmu_dF_diagonal(z, self.F)  # (B, d, d)
                        dmu_F[:, :, np.arange(nc) * (nc + 1)] = diagonal
                    dmu.append(dmu_F)
                else:
                    dz_m = dz_m if dz_m is not None else np.zeros((Bn, nc, size))
                    dz.append(dz_m)
                    dmu.append(dmu_dz @ dz_m if dmu_dz is not None else np.zeros(dz_m.shape))
        if smooth:
            names += tuple(f"smoothing.{n}" for n in smoothing.parameter_names)
            dmu_s = smoothing.dmu_dparameters(z, self.F)
            direct.append(np.zeros((Bn, nx, dmu_s.shape[-1])))
            dz.append(np.zeros(dmu_s.shape))
            dmu.append(dmu_s)
        dz_all = np.concatenate(dz, axis=-1)
        dmu_all = np.concatenate(dmu, axis=-1)
        dlam = lcp.dlam_dq @ dz_all + lcp.dlam_dmu @ dmu_all
        dx = np.concatenate(direct, axis=-1) + self.C @ dlam
        return tuple(names), dx, dlam, dmu_all


@dataclass(frozen=True)
class LcsStepper:
    """An LCS with its smoothing and gradient mode: a batched stepper
    (:class:`drake_abs.engine.Stepper`) for the closed-loop engine.

    Args:
        lcs: the system.
        smoothing: mu per contact (default :class:`Exact`); larger mu is smoother.
        gradient: ``"total"`` (default) or ``"frozen"`` (see :meth:`LCS.step`).
    """

    lcs: LCS
    smoothing: Smoothing | None = None
    gradient: GradientMode = "total"

    def __post_init__(self):
        check_gradient_mode(self.gradient)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The model parameters, every entry of the LCS's matrices (:attr:`LCS.parameter_names`)."""
        return self.lcs.parameter_names

    def step(
        self,
        x,
        u,
        *,
        jacobians: bool = True,
        parameters: bool = False,
        smoothing_parameters: bool = False,
    ) -> Step:
        """``LCS.step`` with this stepper's smoothing and gradient mode (``parameters``: the
        matrices' entries; ``smoothing_parameters``: the smoothing's, after them)."""
        return self.lcs.step(
            x,
            u,
            self.smoothing,
            gradient=self.gradient,
            jacobians=jacobians,
            parameters=parameters,
            smoothing_parameters=smoothing_parameters,
        )
