"""Batched closed-loop rollouts ``x_{t+1} = f(x_t, pi(x_t; theta) + sigma xi_t)`` and their
pathwise (first-order) gradients by a reverse (adjoint) pass over the stored step Jacobians
(docs/math.md section 7; paper 000 eq. 4.1).

M rollouts of H steps run at once through any batched stepper (an :class:`LcsStepper` here, or
a rigid-body ``ComplementarityStepper``): one call per time step for the whole batch, no
per-step Drake system. The reverse pass, per rollout, with ``g_x`` the adjoint of x_t:

    g_x(H) = dr_T/dx_H
    g_u(t) = dr/du_t + g_x(t+1) dx_{t+1}/du_t
    g_x(t) = dr/dx_t + g_x(t+1) dx_{t+1}/dx_t + g_u(t) dpi/dx_t
    dJ/dtheta = sum_t g_u(t) dpi/dtheta_t

Memory (stated and bounded): the forward pass stores per step the states, inputs and the step
Jacobians, ``8 M H (nx^2 + nx nu + 2 nx + 2 nu)`` bytes (:func:`rollout_memory_bytes`); for
M = 1024, H = 1000 and the 2-D ball (nx = 4, nu = 2) that is 0.29 GB. Policy Jacobians are not
stored: the reverse pass recomputes the policy's vector-Jacobian products from x_t.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.contact.lcs import LCS, GradientMode
from drake_abs.contact.smoothing import SmoothingPolicy
from drake_abs.contact.unconverged import (
    UnconvergedPolicy,
    UnconvergedStepError,
    UnconvergedStepWarning,
    apply_unconverged_policy,
    check_unconverged_policy,
)
from drake_abs.policy.policies import Policy
from drake_abs.policy.rewards import Reward

__all__ = [
    "LcsStepper",
    "PolicyRollout",
    "Stepper",
    "UnconvergedPolicy",
    "UnconvergedStepError",
    "UnconvergedStepWarning",
    "rollout_memory_bytes",
    "rollout_policy",
]


class Stepper(Protocol):
    """A batched step: ``step(x (M, nx), u (M, nu), jacobians=...)`` returns an object with
    ``x_next`` (M, nx), ``converged`` (M,) and, with jacobians, ``dx_dx`` (M, nx, nx) and
    ``dx_du`` (M, nx, nu)."""

    def step(self, x: np.ndarray, u: np.ndarray, *, jacobians: bool = True): ...


@dataclass(frozen=True)
class LcsStepper:
    """An LCS with its smoothing policy and gradient mode, as a :class:`Stepper`."""

    lcs: LCS
    smoothing: SmoothingPolicy | None = None
    gradient: GradientMode = "total"

    def step(self, x: np.ndarray, u: np.ndarray, *, jacobians: bool = True):
        return self.lcs.step(x, u, self.smoothing, gradient=self.gradient, jacobians=jacobians)


@dataclass(frozen=True)
class PolicyRollout:
    """M closed-loop rollouts of H steps.

    Attributes:
        x: (M, H + 1, nx) states; u: (M, H, nu) inputs applied (policy plus noise).
        returns: (M,) sum of stage rewards plus the terminal reward, per rollout (NaN for a
            dropped rollout).
        converged: (M, H) the step solver's flags (a rollout with a False is not exact).
        used: (M,) the rollouts estimators may use: all of them under ``on_unconverged="flag"``,
            those whose every step converged under ``"drop"``.
        grad: (M, P) dJ_m / dtheta per rollout (None unless gradients were asked for; NaN for
            a dropped rollout).
        grad_x0: (M, nx) dJ_m / dx_0 per rollout (as ``grad``).
    """

    x: np.ndarray
    u: np.ndarray
    returns: np.ndarray
    converged: np.ndarray
    used: np.ndarray
    grad: np.ndarray | None = None
    grad_x0: np.ndarray | None = None

    @property
    def dropped(self) -> int:
        """Rollouts left out because a step did not converge."""
        return int((~self.used).sum())


def rollout_memory_bytes(M: int, H: int, nx: int, nu: int) -> int:
    """Bytes the forward pass stores for the reverse pass (float64)."""
    return 8 * M * H * (nx * nx + nx * nu + 2 * nx + 2 * nu) + 8 * M * nx


def rollout_policy(
    stepper: Stepper,
    policy: Policy,
    theta,
    x0,
    noise,
    reward: Reward,
    *,
    sigma: float = 1.0,
    gradient: bool = True,
    on_unconverged: UnconvergedPolicy = "drop",
) -> PolicyRollout:
    """Roll out M noisy closed loops and (optionally) differentiate each return.

    Args:
        stepper: the batched dynamics (see :class:`Stepper`).
        policy: a policy of :mod:`drake_abs.policy.policies` (act, vjp).
        theta: (P,) policy parameters.
        x0: (nx,) shared or (M, nx) initial states.
        noise: (M, H, nu) standard-normal exploration samples xi (the caller seeds them); the
            applied input is ``pi(x_t) + sigma xi_t``.
        reward: a reward of :mod:`drake_abs.policy.rewards` (stage, terminal).
        sigma: exploration scale (units of u); 0 for the deterministic policy.
        gradient: run the reverse pass.
        on_unconverged: what to do with a rollout that took an unconverged step: ``"drop"``
            (default; marked unused, gradient NaN), ``"flag"`` or ``"raise"``
            (:mod:`drake_abs.contact.unconverged` says why ``"drop"`` is the default).
    """
    check_unconverged_policy(on_unconverged)
    theta = as_finite_array(theta, "theta", ndim=(1,))
    noise = as_finite_array(noise, "noise", ndim=(3,))
    M, H, nu = noise.shape
    x0 = as_finite_array(x0, "x0", ndim=(1, 2))
    X0 = np.broadcast_to(x0, (M, x0.shape[-1])) if x0.ndim == 1 else x0
    nx = X0.shape[1]
    if X0.shape[0] != M:
        raise ValueError(f"x0 must have shape (nx,) or (M, nx) with M = {M}; got {x0.shape}")
    if nu != policy.nu or nx != policy.nx:
        raise ValueError(
            f"noise (M, H, nu) and x0 must match the policy's nu = {policy.nu}, nx = {policy.nx}"
        )
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"sigma must be a finite number >= 0; got {sigma!r}")
    xs = np.empty((M, H + 1, nx))
    us = np.empty((M, H, nu))
    conv = np.empty((M, H), dtype=bool)
    xs[:, 0] = X0
    returns = np.zeros(M)
    if gradient:
        Fx = np.empty((M, H, nx, nx))
        Fu = np.empty((M, H, nx, nu))
        rx = np.empty((M, H, nx))
        ru = np.empty((M, H, nu))
    for t in range(H):
        u = policy.act(theta, xs[:, t]) + sigma * noise[:, t]
        us[:, t] = u
        r, dr_dx, dr_du = reward.stage(xs[:, t], u)
        returns += r
        step = stepper.step(xs[:, t], u, jacobians=gradient)
        xs[:, t + 1] = step.x_next
        conv[:, t] = step.converged
        if gradient:
            Fx[:, t], Fu[:, t], rx[:, t], ru[:, t] = step.dx_dx, step.dx_du, dr_dx, dr_du
    rT, drT = reward.terminal(xs[:, H])
    returns += rT
    used = apply_unconverged_policy(conv, on_unconverged)
    _check_finite(returns[used], "return")
    returns[~used] = np.nan  # a dropped rollout's states are not the model's either
    if not gradient:
        return PolicyRollout(xs, us, returns, conv, used)
    g_x = drT
    g_theta = np.zeros((M, theta.size))
    for t in range(H - 1, -1, -1):
        g_u = ru[:, t] + np.einsum("mi,mij->mj", g_x, Fu[:, t])
        gx_pi, gth_pi = policy.vjp(theta, xs[:, t], g_u)
        g_theta += gth_pi
        g_x = rx[:, t] + np.einsum("mi,mij->mj", g_x, Fx[:, t]) + gx_pi
    _check_finite(g_theta[used], "gradient")
    g_theta[~used] = np.nan  # never averaged in silently
    g_x[~used] = np.nan
    return PolicyRollout(xs, us, returns, conv, used, g_theta, g_x)


def _check_finite(values: np.ndarray, what: str) -> None:
    """A usable rollout (every step converged, or kept under "flag") must have a finite return
    and gradient: otherwise the state left the finite numbers, which is an error, not a result."""
    if not np.all(np.isfinite(values)):
        raise FloatingPointError(
            f"rollout_policy: a rollout's {what} is not finite although its steps are usable "
            "(the state or the policy left the finite numbers)"
        )
