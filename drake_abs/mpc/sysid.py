"""Least-squares identification of a linear prediction model (Zuliani et al. 2025, section 7).

From transitions (x_t, u_t, x_{t+1}) we fit, in deviations from a reference (x_ref, u_ref),

    x_{t+1} - x_ref  ~=  A (x_t - x_ref) + B (u_t - u_ref)          [+ c with ``intercept=True``]

by ordinary least squares over all transitions (``numpy.linalg.lstsq``), one regression for all
nx output rows at once. Without the intercept the reference is an equilibrium of the model,
which is what :class:`drake_abs.mpc.qp_mpc.MpcSpec` assumes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_finite_array, check_shape


@dataclass(frozen=True)
class LinearModel:
    """An identified model in deviations from (x_ref, u_ref).

    Attributes:
        A: (nx, nx); B: (nx, nu); c: (nx,) intercept (zero unless fitted).
        x_ref: (nx,), u_ref: (nu,) the reference the deviations are taken from.
        residual_rms: (nx,) root-mean-square one-step prediction error per state component.
        samples: number of transitions used; rank: numerical rank of the regressor matrix
            (nx + nu (+ 1) when every parameter is identifiable).
    """

    A: np.ndarray
    B: np.ndarray
    c: np.ndarray
    x_ref: np.ndarray
    u_ref: np.ndarray
    residual_rms: np.ndarray
    samples: int
    rank: int

    def predict(self, x, u) -> np.ndarray:
        """x_ref + A (x - x_ref) + B (u - u_ref) + c for x (..., nx), u (..., nu)."""
        x = np.asarray(x, dtype=float)
        u = np.asarray(u, dtype=float)
        return self.x_ref + (x - self.x_ref) @ self.A.T + (u - self.u_ref) @ self.B.T + self.c


def identify_linear_model(
    x, u, x_next, x_ref=None, u_ref=None, *, intercept: bool = False
) -> LinearModel:
    """Fit (A, B) by least squares.

    Args:
        x: (M, nx) states; u: (M, nu) inputs; x_next: (M, nx) successor states (any number of
            trajectories stacked; M transitions in all).
        x_ref, u_ref: (nx,), (nu,) reference (default zero).
        intercept: also fit a constant c.

    Raises:
        ValueError: non-finite data, mismatched shapes, or fewer transitions than unknowns per
            row (nx + nu (+ 1)).
    """
    x = as_finite_array(x, "x", ndim=(2,))
    u = as_finite_array(u, "u", ndim=(2,))
    x_next = as_finite_array(x_next, "x_next", ndim=(2,))
    M, nx = x.shape
    nu = u.shape[1]
    check_shape(u, (M, nu), "u", "(M, nu)")
    check_shape(x_next, (M, nx), "x_next", "(M, nx)")
    x_ref = np.zeros(nx) if x_ref is None else as_finite_array(x_ref, "x_ref", ndim=(1,))
    u_ref = np.zeros(nu) if u_ref is None else as_finite_array(u_ref, "u_ref", ndim=(1,))
    check_shape(x_ref, (nx,), "x_ref", "(nx,)")
    check_shape(u_ref, (nu,), "u_ref", "(nu,)")
    unknowns = nx + nu + int(intercept)
    if M < unknowns:
        raise ValueError(f"need at least {unknowns} transitions to identify (A, B); got {M}")
    cols = [x - x_ref, u - u_ref] + ([np.ones((M, 1))] if intercept else [])
    Phi = np.hstack(cols)
    Y = x_next - x_ref
    theta, _, rank, _ = np.linalg.lstsq(Phi, Y, rcond=None)
    A = theta[:nx].T.copy()
    B = theta[nx : nx + nu].T.copy()
    c = theta[nx + nu].copy() if intercept else np.zeros(nx)
    residual = Y - Phi @ theta
    return LinearModel(
        A=A,
        B=B,
        c=c,
        x_ref=x_ref.copy(),
        u_ref=u_ref.copy(),
        residual_rms=np.sqrt(np.mean(residual**2, axis=0)),
        samples=M,
        rank=int(rank),
    )
