"""Task rewards with their gradients, batched over rollouts (docs/math.md section 7).

A reward gives, for states x (M, nx) and inputs u (M, nu):

- ``stage(x, u)`` -> (r (M,), dr/dx (M, nx), dr/du (M, nu)), summed over t = 0 .. H-1;
- ``terminal(x)`` -> (r_T (M,), dr_T/dx (M, nx)), added at t = H.

Rewards are maximised: costs enter with a minus sign.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.engine.protocols import Reward

__all__ = ["QuadraticReward", "Reward"]


@dataclass(frozen=True)
class QuadraticReward:
    """``r = -(x - x_goal)^T Q (x - x_goal) - u^T R u`` per step and
    ``r_T = -(x_H - x_goal)^T Q_final (x_H - x_goal)`` at the end.

    Args:
        Q: (nx, nx) stage state weight (symmetric PSD).
        R: (nu, nu) input weight (symmetric PSD).
        x_goal: (nx,) target state.
        Q_final: (nx, nx) terminal weight (default zero).
    """

    Q: np.ndarray
    R: np.ndarray
    x_goal: np.ndarray
    Q_final: np.ndarray | None = None

    def __post_init__(self):
        Q = as_finite_array(self.Q, "Q", ndim=(2,))
        R = as_finite_array(self.R, "R", ndim=(2,))
        g = as_finite_array(self.x_goal, "x_goal", ndim=(1,))
        nx, nu = g.size, R.shape[0]
        Qf = np.zeros((nx, nx)) if self.Q_final is None else self.Q_final
        Qf = as_finite_array(Qf, "Q_final", ndim=(2,))
        for name, M, n in (("Q", Q, nx), ("R", R, nu), ("Q_final", Qf, nx)):
            if M.shape != (n, n) or not np.allclose(M, M.T):
                raise ValueError(f"{name} must be symmetric with shape ({n}, {n}); got {M.shape}")
        object.__setattr__(self, "Q", Q)
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "x_goal", g)
        object.__setattr__(self, "Q_final", Qf)

    @property
    def nx(self) -> int:
        return self.x_goal.size

    @property
    def nu(self) -> int:
        return self.R.shape[0]

    def stage(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        e = x - self.x_goal
        Qe, Ru = e @ self.Q, u @ self.R
        return -np.einsum("mi,mi->m", e, Qe) - np.einsum("mi,mi->m", u, Ru), -2 * Qe, -2 * Ru

    def terminal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        e = x - self.x_goal
        Qe = e @ self.Q_final
        return -np.einsum("mi,mi->m", e, Qe), -2 * Qe
