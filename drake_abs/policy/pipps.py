"""PIPPS total propagation (Parmas, Rasmussen, Peters and Doya 2018, "PIPPS: Flexible
Model-Based Policy Search Robust to the Curse of Chaos", section 4, Algorithm 1 "total
propagation"): a policy gradient that mixes, at every stochastic node of the trajectory, a
pathwise (reparameterisation, RP) and a likelihood-ratio (LR) estimate of the same derivative
with inverse-variance weights, and propagates the *mixed* derivative backwards to the earlier
nodes.

The setting here. Our rollouts are ``u_t = pi(x_t; theta) + sigma xi_t`` (xi_t standard normal)
and ``x_{t+1} = f(x_t, u_t)`` deterministic (drake_abs.engine); the stochastic nodes are the
actions u_t ~ N(zeta_t, sigma^2 I) with distribution parameter ``zeta_t = pi(x_t; theta)``
(units of u). (PIPPS is stated for a stochastic model ``x_{t+1} ~ N(mu(x_t, u_t), Sigma(...))``;
with our deterministic transition the only place an LR estimate exists is the action, so the
mixing happens there, and the direct path x_t -> x_{t+1} through ``df/dx`` stays pathwise.)

For M rollouts (particles) m with return-to-go ``G_t^m = sum_{s >= t} r_s^m + r_T^m`` the
backward pass runs t = H-1, ..., 0 with ``lam_H = dr_T/dx(x_H)`` (M, nx):

- RP estimate of ``dE[G_t | x_t] / dzeta_t`` (M, nu): ``g_RP = dr_t/du + lam_{t+1} df/du``;
- LR estimate of the same: ``g_LR = (G_t^m - b_t^m) xi_t^m / sigma`` with the leave-one-out
  baseline ``b_t^m = mean_{j != m} G_t^j`` (the score of N(zeta, sigma^2 I) is xi / sigma);
- their sample variances across the M particles, ``v_RP``, ``v_LR`` (traces), and the
  inverse-variance weight on the RP estimate ``k_t = v_LR / (v_RP + v_LR)``
  (the paper's ``k_LR = sigma_RP^2 / (sigma_RP^2 + sigma_LR^2)`` is ``1 - k_t``);
- the mixed derivative ``gamma_t = k_t g_RP + (1 - k_t) g_LR``, its contribution to the policy
  gradient ``gamma_t dpi/dtheta(x_t)``, and the propagation
  ``lam_t = dr_t/dx + lam_{t+1} df/dx + gamma_t dpi/dx(x_t)`` (Algorithm 1's backward pass).

The estimate is ``(1/M) sum_m sum_t gamma_t^m dpi/dtheta(x_t^m)`` (P,). Both per-node estimates
are unbiased for the same derivative (given the state), so any fixed weight gives an unbiased
gradient; the weights estimated from the same particles add a small O(1/M) bias, which Parmas
et al. accept as well.

Special cases: ``rp_weight=1`` (all weight on the pathwise part) is FOPG, the engine's adjoint
gradient (Zhang et al. 2023, eq. 4.1), to rounding; ``rp_weight=0`` is REINFORCE with
returns-to-go and per-step leave-one-out baselines (an unbiased relative of
:func:`~drake_abs.policy.estimators.zeroth_order`, which uses the whole return).

Which variance. ``variance_of="theta"`` (default) weighs by the variance of each node's
contributions to the policy gradient, ``g dpi/dtheta(x_t)`` (M, P); ``"action"`` by the
variance of ``g_RP``, ``g_LR`` themselves (M, nu). As far as I recall Parmas et al. measure the
variance of the gradient with respect to the policy parameters; this was written from memory
of the paper, not checked against its text.

Differences from the paper, besides the stochastic node being the action: the baseline is
leave-one-out (the estimate at a fixed weight is exactly unbiased), and the particles are not
resampled (the paper's "particle" method is not part of total propagation).

Where it runs: in this process, one forward pass of its own (``stepper.step(x, u,
jacobians=True)``, the policy's ``act`` and ``vjp``, the reward's ``stage`` and ``terminal``),
because it needs every rollout's per-step Jacobians, which the engine keeps to itself. The
noise is the objective's (:meth:`PolicyObjective.noise`), so with the same seed it sees the
rollouts :func:`~drake_abs.policy.estimators.first_order` sees. Memory: the forward pass keeps
``8 M H (nx^2 + nx nu + 2 nx + 2 nu + 1)`` bytes, as the engine's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from drake_abs.contact.unconverged import UnconvergedStepError, apply_on_unconverged
from drake_abs.engine import record
from drake_abs.policy.estimators import GradientEstimate, PolicyObjective

__all__ = ["PippsEstimate", "pipps", "pipps_detailed"]

VarianceOf = Literal["theta", "action"]


@dataclass(frozen=True)
class PippsEstimate:
    """A PIPPS gradient with what it was mixed from.

    Attributes:
        estimate: the :class:`~drake_abs.policy.estimators.GradientEstimate` (grad (P,) of the
            mean return, value, counts).
        rp_weight: (H,) k_t, the weight on the pathwise estimate at each action node.
        var_rp, var_lr: (H,) the traces of the two estimates' sample variances across the
            particles (units of grad^2 for ``variance_of="theta"``, of (return / u)^2 for
            ``"action"``; NaN where a fixed ``rp_weight`` made them unnecessary).
    """

    estimate: GradientEstimate
    rp_weight: np.ndarray
    var_rp: np.ndarray
    var_lr: np.ndarray


@dataclass(frozen=True)
class _Forward:
    x: np.ndarray  # (M, H + 1, nx)
    r: np.ndarray  # (M, H) stage rewards
    rx: np.ndarray  # (M, H, nx)
    ru: np.ndarray  # (M, H, nu)
    fx: np.ndarray  # (M, H, nx, nx)
    fu: np.ndarray  # (M, H, nx, nu)
    r_T: np.ndarray  # (M,)
    drT: np.ndarray  # (M, nx)
    converged: np.ndarray  # (M, H) (True after an episode ended)
    env_steps: int  # steps that counted


def pipps(
    obj: PolicyObjective,
    theta,
    rng: np.random.Generator,
    M: int,
    *,
    rp_weight: float | None = None,
    variance_of: VarianceOf = "theta",
) -> GradientEstimate:
    """PIPPS total propagation from M rollouts (Parmas et al. 2018, Algorithm 1).

    Args:
        obj: the objective (stepper, policy, reward, x0, horizon H, sigma > 0).
        theta: (P,) policy parameters.
        rng: numpy Generator; the noise is ``obj.noise(rng, M)`` (one key drawn, as every
            estimator of :mod:`drake_abs.policy.estimators` draws it).
        M: rollouts (particles), >= 2 (the baselines and variances need two).
        rp_weight: None (default) for the inverse-variance weights; a number in [0, 1] fixes the
            weight on the pathwise estimate at every node (1: FOPG; 0: REINFORCE with
            returns-to-go).
        variance_of: ``"theta"`` (default) or ``"action"``: see the module docstring.

    Returns:
        The :class:`~drake_abs.policy.estimators.GradientEstimate` of the mean return.
    """
    return pipps_detailed(obj, theta, rng, M, rp_weight=rp_weight, variance_of=variance_of).estimate


def pipps_detailed(
    obj: PolicyObjective,
    theta,
    rng: np.random.Generator,
    M: int,
    *,
    rp_weight: float | None = None,
    variance_of: VarianceOf = "theta",
) -> PippsEstimate:
    """:func:`pipps` with the per-step weights and variances (:class:`PippsEstimate`)."""
    if not isinstance(obj, PolicyObjective):
        raise ValueError(f"obj must be a PolicyObjective; got {type(obj).__name__}")
    if isinstance(M, bool) or not isinstance(M, int | np.integer) or M < 2:
        raise ValueError(f"M must be a whole number >= 2 (baselines and variances); got {M!r}")
    if rp_weight is not None and not (np.isfinite(rp_weight) and 0.0 <= rp_weight <= 1.0):
        raise ValueError(f"rp_weight must be None or a number in [0, 1]; got {rp_weight!r}")
    if variance_of not in ("theta", "action"):
        raise ValueError(f"variance_of must be 'theta' or 'action'; got {variance_of!r}")
    needs_lr = rp_weight is None or rp_weight < 1.0
    if needs_lr and obj.sigma <= 0:
        raise ValueError(
            "PIPPS's likelihood-ratio part needs exploration noise: sigma > 0 (or rp_weight=1)"
        )
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (obj.policy.n_params,):
        raise ValueError(
            f"theta must have shape (P,) = ({obj.policy.n_params},); got {theta.shape}"
        )
    M = int(M)
    noise = obj.noise(rng, M)
    fwd = _forward(obj, theta, noise)
    used = apply_on_unconverged(fwd.converged, obj.on_unconverged)
    n_used = int(used.sum())
    if n_used < 2:
        raise UnconvergedStepError(
            f"pipps: only {n_used} rollout(s) without unconverged steps, 2 needed"
        )
    grad, k, v_rp, v_lr, returns = _backward(
        obj, theta, fwd, noise, used, rp_weight, variance_of, needs_lr
    )
    H = noise.shape[1]
    estimate = GradientEstimate(
        grad=grad, value=float(returns.mean()), rollouts=M, steps=M * H,
        unconverged=int((~fwd.converged).sum()), dropped=int(M - n_used),
        env_steps=fwd.env_steps,
    )  # fmt: skip
    return PippsEstimate(estimate, k, v_rp, v_lr)


def _forward(obj: PolicyObjective, theta: np.ndarray, noise: np.ndarray) -> _Forward:
    """The rollouts, with every step's Jacobians and reward derivatives: the engine's own
    forward pass (:func:`drake_abs.engine.record`; a reward of transitions contributes its
    dr/dx_{t+1} at t + 1, an ended episode's later steps count nothing)."""
    tape = record(obj.stepper, obj.policy, theta, obj.x0, noise, obj.reward, sigma=obj.sigma)
    H = noise.shape[1]
    end = tape.alive[:, H]
    r_T, drT = obj.reward.terminal(tape.x[:, H])
    r_T = np.where(end, np.asarray(r_T, float), 0.0)
    drT = np.where(end[:, None], np.asarray(drT, float), 0.0) + tape.stage_x[:, H]
    conv = tape.converged | ~tape.alive[:, :H]  # steps after the end do not count
    return _Forward(tape.x, tape.rewards, tape.stage_x[:, :H], tape.stage_u, tape.dx_dx,
                    tape.dx_du, r_T, drT, conv, int(tape.alive[:, :H].sum()))  # fmt: skip


def _loo(values: np.ndarray) -> np.ndarray:
    """Leave-one-out means of values (n,) (n >= 2)."""
    return (values.sum() - values) / (values.size - 1)


def _trace_var(values: np.ndarray) -> float:
    """Trace of the sample covariance (ddof 1) of the rows of values (n, d)."""
    return float(np.var(values, axis=0, ddof=1).sum())


def _backward(obj, theta, fwd: _Forward, noise, used, rp_weight, variance_of, needs_lr):
    """Algorithm 1's backward pass over the used particles; returns (grad (P,), k (H,),
    v_rp (H,), v_lr (H,), returns (n,))."""
    x, r, rx, ru = fwd.x[used], fwd.r[used], fwd.rx[used], fwd.ru[used]
    fx, fu, xi = fwd.fx[used], fwd.fu[used], noise[used]
    n, H = r.shape
    G = fwd.r_T[used].copy()  # return-to-go from t + 1 (at t = H: the terminal reward)
    lam = fwd.drT[used].copy()  # d G_{t+1} / d x_{t+1}, the mixed (total) derivative
    _check_finite(np.concatenate([x.reshape(n, -1), r, G[:, None]], axis=1), "rollout")
    grad = np.zeros(theta.size)
    k_all, v_rp_all, v_lr_all = np.empty(H), np.full(H, np.nan), np.full(H, np.nan)
    for t in range(H - 1, -1, -1):
        G = G + r[:, t]
        g_rp = ru[:, t] + np.einsum("mi,mij->mj", lam, fu[:, t])
        if not needs_lr:
            gx, gth = obj.policy.vjp(theta, x[:, t], g_rp)
            k = 1.0
        else:
            g_lr = (G - _loo(G))[:, None] * xi[:, t] / obj.sigma
            both_x = np.concatenate([x[:, t], x[:, t]])
            gx2, gth2 = obj.policy.vjp(theta, both_x, np.concatenate([g_rp, g_lr]))
            if rp_weight is None:
                a, b = (gth2[:n], gth2[n:]) if variance_of == "theta" else (g_rp, g_lr)
                v_rp, v_lr = _trace_var(a), _trace_var(b)
                _check_finite(np.array([v_rp, v_lr]), f"variance at step {t}")
                k = v_lr / (v_rp + v_lr) if v_rp + v_lr > 0 else 1.0
                v_rp_all[t], v_lr_all[t] = v_rp, v_lr
            else:
                k = float(rp_weight)
            gx = k * gx2[:n] + (1.0 - k) * gx2[n:]
            gth = k * gth2[:n] + (1.0 - k) * gth2[n:]
        k_all[t] = k
        grad += gth.sum(axis=0)
        lam = rx[:, t] + np.einsum("mi,mij->mj", lam, fx[:, t]) + gx
        _check_finite(lam, f"propagated derivative at step {t}")
    return grad / n, k_all, v_rp_all, v_lr_all, G


def _check_finite(values: np.ndarray, what: str) -> None:
    if not np.all(np.isfinite(values)):
        raise FloatingPointError(
            f"pipps: the {what} is not finite although every step converged (the state, the "
            "policy or the derivatives left the finite numbers)"
        )
