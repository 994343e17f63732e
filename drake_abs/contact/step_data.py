"""The data of one batched rigid-body contact step, in SI units: its inputs and its result.

The step is :func:`drake_abs.contact.contact_lcp.contact_step`. Its inputs are the dynamics of B
states with their derivatives in p = (q, v, u) (:class:`StepQuantities`) and in the model
parameters theta (:class:`ParameterDerivatives`); its output is a :class:`ContactStepResult`.
Shapes are given in each class.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drake_abs.lcp.ipm import LCPResult


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
        smoothing_from: the first of the trailing columns that are the smoothing's
            numeric parameters
            (:meth:`~drake_abs.contact.smoothing.Smoothing.dmu_dparameters`: they move mu
            at fixed distances, and nothing else), or None when there are none. Their entries in
            the arrays above are zero.
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
