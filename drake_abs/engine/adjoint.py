"""The reverse (adjoint) pass over a stored trajectory (docs/math.md section 7; Zhang et al. 2023,
eq. 4.1,
Zuliani et al. 2025, eq. 8 in reverse mode).

For K objectives at once (K = 1 for a return, K = nx for the Jacobian of the final state), with
``g_x(t)`` (M, K, nx) the adjoint of x_t and the step Jacobians F_x, F_u, F_theta of step t:

    g_x(H)     = given (dr_T/dx_H, or the identity for the final state itself)
    g_u(t)     = dr/du_t + g_x(t+1) F_u(t)
    g_x(t)     = dr/dx_t + g_x(t+1) F_x(t) + g_u(t) dpi/dx_t
    dJ/dtheta  = sum_t g_u(t) dpi/dtheta_t                          (policy parameters)
    dJ/dphi    = sum_t g_x(t+1) F_phi(t)                            (model parameters phi)

One sweep, O(H) products of small matrices per rollout; nothing is re-simulated.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from drake_abs.engine.protocols import PolicyVjp


@dataclass(frozen=True)
class Adjoints:
    """What the reverse pass returns, for M rollouts and K objectives.

    Attributes:
        x0: (M, K, nx) dJ/dx_0.
        policy: (M, K, P) dJ/dtheta of the policy parameters (None without a policy).
        model: (M, K, T) dJ/dphi of the stepper's model parameters (None unless asked for).
        inputs: (M, H, K, nu) dJ/du_t of every applied input (None unless asked for).
    """

    x0: np.ndarray
    policy: np.ndarray | None = None
    model: np.ndarray | None = None
    inputs: np.ndarray | None = None


def reverse_pass(
    dx_dx: np.ndarray,
    dx_du: np.ndarray,
    g_final: np.ndarray,
    *,
    stage_x: np.ndarray | None = None,
    stage_u: np.ndarray | None = None,
    policy_vjps: Sequence[PolicyVjp] | None = None,
    n_policy_params: int = 0,
    dx_dtheta: np.ndarray | None = None,
    keep_inputs: bool = False,
) -> Adjoints:
    """Propagate the adjoints of K objectives from the final state back to the start.

    Args:
        dx_dx: (M, H, nx, nx) stored step Jacobians dx_{t+1}/dx_t.
        dx_du: (M, H, nx, nu) stored dx_{t+1}/du_t.
        g_final: (M, K, nx) dJ/dx_H.
        stage_x, stage_u: (M, H, K, nx), (M, H, K, nu) the objectives' stage gradients
            (None: the objectives depend on the final state only).
        policy_vjps: H functions, the policy's vector-Jacobian product at each step
            (``vjp(g_u (M, nu)) -> (g_x (M, nx), g_theta (M, P))``); None for open-loop inputs.
        n_policy_params: P.
        dx_dtheta: (M, H, nx, T) stored model-parameter Jacobians (None: not asked for).
        keep_inputs: also return dJ/du_t for every t.
    """
    M, H, nx, nu = dx_du.shape
    g_x = np.asarray(g_final, dtype=float)
    K = g_x.shape[1]
    g_theta = np.zeros((M, K, n_policy_params)) if policy_vjps is not None else None
    g_model = np.zeros((M, K, dx_dtheta.shape[-1])) if dx_dtheta is not None else None
    g_inputs = np.empty((M, H, K, nu)) if keep_inputs else None
    for t in range(H - 1, -1, -1):
        g_u = g_x @ dx_du[:, t]
        if stage_u is not None:
            g_u = stage_u[:, t] + g_u
        if keep_inputs:
            g_inputs[:, t] = g_u
        if g_model is not None:
            g_model += g_x @ dx_dtheta[:, t]
        g_next = g_x @ dx_dx[:, t]
        if stage_x is not None:
            g_next = stage_x[:, t] + g_next
        if policy_vjps is not None:
            for k in range(K):
                gx_pi, gth_pi = policy_vjps[t](g_u[:, k])
                g_theta[:, k] += gth_pi
                g_next[:, k] += gx_pi
        g_x = g_next
    return Adjoints(x0=g_x, policy=g_theta, model=g_model, inputs=g_inputs)
