"""The QP-MPC as a policy of the closed-loop engine: ``u = MPC(x; theta)``, the first input of the
plan, with theta the cost parameters (Zuliani et al. 2025, eq. 2 and 8b).

:class:`MpcPolicy` follows :class:`drake_abs.engine.PullbackPolicy`: one QP solve per state gives
the input and, when the engine differentiates, the KKT Jacobians du0/dx (nu, nx) and
du0/dtheta (nu, n_theta) of that same solve, kept for the reverse pass. A solve that fails uses
the documented fallback control, a constant: its Jacobians are zero (it is counted, see
:attr:`MpcPolicy.solutions`).
"""

from __future__ import annotations

import numpy as np

from drake_abs._validation import as_finite_array, check_shape
from drake_abs.mpc.qp_mpc import JacobianMethod, MpcSolution, QpMpc


class MpcPolicy:
    """The MPC ``controller`` as a batched, differentiable policy.

    Args:
        controller: the MPC; its warm start carries over from one solve to the next, so states
            are solved in the order given (one rollout at a time for M > 1: row by row).
        method: how the solve's Jacobians are formed (``"kkt"`` or ``"osqp_adjoint"``).

    Attributes:
        solutions: every :class:`~drake_abs.mpc.qp_mpc.MpcSolution` since the last
            :meth:`clear` (status, fallback, iterations of each solve).
    """

    def __init__(self, controller: QpMpc, method: JacobianMethod = "kkt"):
        if not isinstance(controller, QpMpc):
            raise TypeError(f"controller must be a QpMpc; got {type(controller).__name__}")
        self.controller = controller
        self.method = method
        self.nx, self.nu = controller.spec.nx, controller.spec.nu
        self.solutions: list[MpcSolution] = []

    @property
    def n_params(self) -> int:
        return self.controller.n_theta

    def clear(self) -> None:
        """Forget the recorded solutions."""
        self.solutions = []

    def _solve(self, theta, x, jacobians: bool) -> list[MpcSolution]:
        theta = as_finite_array(theta, "theta", ndim=(1,))
        check_shape(theta, (self.n_params,), "theta", "(n_theta,)")
        x = as_finite_array(x, "x", ndim=(2,))
        if x.shape[1] != self.nx:
            raise ValueError(f"x must have shape (M, nx) = (M, {self.nx}); got {x.shape}")
        out = [
            self.controller.solve(xm, theta, jacobians=jacobians, method=self.method) for xm in x
        ]
        self.solutions += out
        return out

    def act(self, theta, x) -> np.ndarray:
        """u0 (M, nu) at states x (M, nx) (M = 0 gives an empty (0, nu))."""
        sols = self._solve(theta, x, False)
        return _stack([s.u0 for s in sols], (self.nu,))

    def jacobians(self, theta, x) -> tuple[np.ndarray, np.ndarray]:
        """(du0/dx (M, nu, nx), du0/dtheta (M, nu, n_theta)) by solving at x."""
        sols = self._solve(theta, x, True)
        return (
            _stack([s.du0_dx for s in sols], (self.nu, self.nx)),
            _stack([s.du0_dtheta for s in sols], (self.nu, self.n_params)),
        )

    def vjp(self, theta, x, g_u) -> tuple[np.ndarray, np.ndarray]:
        """(g_u du0/dx (M, nx), g_u du0/dtheta (M, n_theta)) by solving at x; g_u (M, nu)."""
        return self._products(self._solve(theta, x, True), g_u)

    def pullback(self, theta, x):
        """u0 (M, nu) and the vector-Jacobian product of the same solves (no second solve)."""
        sols = self._solve(theta, x, True)
        return _stack([s.u0 for s in sols], (self.nu,)), lambda g_u: self._products(sols, g_u)

    def _products(self, sols: list[MpcSolution], g_u) -> tuple[np.ndarray, np.ndarray]:
        try:
            g_u = np.asarray(g_u, dtype=float)  # not checked finite: a dropped rollout is NaN
        except (TypeError, ValueError) as err:
            raise ValueError(
                f"g_u must be a real numeric array (M, nu); got {type(g_u).__name__}"
            ) from err
        check_shape(g_u, (len(sols), self.nu), "g_u", "(M, nu)")
        g_x = _stack([g @ s.du0_dx for g, s in zip(g_u, sols, strict=True)], (self.nx,))
        g_th = _stack([g @ s.du0_dtheta for g, s in zip(g_u, sols, strict=True)], (self.n_params,))
        return g_x, g_th


def _stack(rows: list[np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
    """The rows stacked to (M, *shape); an empty (0, *shape) array for M = 0."""
    return np.stack(rows) if rows else np.zeros((0, *shape))
