"""Batched open-loop rollouts of an LCS with the analytic chain rule through every step.

Forward-mode accumulation of the per-step implicit Jacobians (docs/math.md section 4):

    dx_{t+1}/dx_0   = (dx+/dx)_t  dx_t/dx_0
    dx_{t+1}/du_k   = (dx+/dx)_t  dx_t/du_k   (k < t),     (dx+/du)_t  for k = t
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.contact.lcs import LCS, GradientMode
from drake_abs.contact.smoothing import SmoothingPolicy
from drake_abs.contact.unconverged import (
    UnconvergedPolicy,
    apply_unconverged_policy,
    check_unconverged_policy,
)


@dataclass(frozen=True)
class Rollout:
    """Trajectories of B rollouts of N steps.

    Attributes:
        x: (B, N + 1, dx) states, x[:, 0] the initial states.
        lam: (B, N, d) contact impulses of each step.
        mu: (B, N, d) central-path values reached.
        converged: (B, N) solver flags of each step.
        used: (B,) rollouts whose Jacobians may be used (all under ``on_unconverged="flag"``;
            those whose every step converged under ``"drop"``).
        dxN_dx0: (B, dx, dx) Jacobian of the final state w.r.t. the initial state (NaN for a
            dropped rollout).
        dxN_du: (B, N, dx, du) Jacobian of the final state w.r.t. each step's input (likewise).
    """

    x: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    converged: np.ndarray
    used: np.ndarray
    dxN_dx0: np.ndarray | None
    dxN_du: np.ndarray | None


def rollout(
    lcs: LCS,
    x0,
    u,
    smoothing: SmoothingPolicy | None = None,
    *,
    gradient: GradientMode = "total",
    jacobians: bool = True,
    on_unconverged: UnconvergedPolicy = "drop",
) -> Rollout:
    """Roll out ``x_{t+1} = lcs.step(x_t, u_t)`` for a batch.

    Args:
        lcs: the system.
        x0: (dx,) or (B, dx) initial states.
        u: (N, du) inputs shared by the batch, or (B, N, du).
        smoothing, gradient: as in :meth:`LCS.step`.
        jacobians: accumulate dxN_dx0 and dxN_du.
        on_unconverged: ``"drop"`` (default: a rollout with an unconverged step gets NaN
            Jacobians and ``used`` False), ``"flag"`` or ``"raise"``
            (:mod:`drake_abs.contact.unconverged`).
    """
    check_unconverged_policy(on_unconverged)
    nx, nu, nc = lcs.dims
    x0 = as_finite_array(x0, "x0", ndim=(1, 2))
    X = np.atleast_2d(x0)
    nb = X.shape[0]
    u = as_finite_array(u, "u", ndim=(2, 3))
    U = np.broadcast_to(u, (nb,) + u.shape) if u.ndim == 2 else u
    if U.shape[0] != nb or U.shape[2] != nu:
        raise ValueError(
            f"u must have shape (N, du) or (B, N, du) with B = {nb}, du = {nu}; got {u.shape}"
        )
    n = U.shape[1]
    xs = np.empty((nb, n + 1, nx))
    lams = np.empty((nb, n, nc))
    mus = np.empty((nb, n, nc))
    conv = np.empty((nb, n), dtype=bool)
    xs[:, 0] = X
    Fx = np.empty((nb, n, nx, nx)) if jacobians else None
    Ju = np.empty((nb, n, nx, nu)) if jacobians else None
    for t in range(n):
        r = lcs.step(xs[:, t], U[:, t], smoothing, gradient=gradient, jacobians=jacobians)
        xs[:, t + 1], lams[:, t], mus[:, t], conv[:, t] = r.x_next, r.lam, r.mu, r.converged
        if jacobians:
            Fx[:, t], Ju[:, t] = r.dx_dx, r.dx_du
    Jx = None
    used = apply_unconverged_policy(conv, on_unconverged)
    if jacobians:  # one backward sweep: P = dx_N / dx_{t+1}, so dx_N / du_t = P dx_{t+1} / du_t
        Jx = np.broadcast_to(np.eye(nx), (nb, nx, nx)).copy()
        for t in range(n - 1, -1, -1):
            Ju[:, t] = Jx @ Ju[:, t]
            Jx = Jx @ Fx[:, t]
        Jx[~used] = np.nan  # never used silently
        Ju[~used] = np.nan
    return Rollout(xs, lams, mus, conv, used, Jx, Ju)
