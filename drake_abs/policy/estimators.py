"""Policy-gradient estimators of ``J(theta) = E[sum_t r(x_t, u_t)]`` with
``u_t = pi(x_t; theta) + sigma xi_t`` (docs/math.md section 7; Zhang et al. 2023, sections 2 and 4).

- :func:`first_order`: FOPG, the pathwise (reparameterised) gradient, eq. 4.1: the mean of the
  per-rollout adjoint gradients.
- :func:`zeroth_order`: ZOPG, the likelihood ratio with a leave-one-out baseline,
  ``(1/M) sum_m (R_m - b_m) sum_t (xi_t / sigma) dpi/dtheta`` (unbiased: b_m does not use R_m).
- :func:`randomized_smoothing`: the bundled first-order gradient of the objective smoothed in
  parameter space, ``(1/N) sum_i grad J(theta + w_i)``, ``w_i ~ N(0, std^2 I)``.
- :func:`ars`: Augmented Random Search (Mania et al. 2018, V1-t): antithetic directions, the
  top-b by max(J+, J-), step scaled by the std of the returns used.
- :func:`alpha_order`: the alpha-order interpolation (Suh et al. 2022a),
  ``alpha g_FO + (1 - alpha) g_ZO`` from the same rollouts.

Every estimator takes a :class:`PolicyObjective`, theta and a numpy Generator (all randomness
comes from it: the same seed gives the same numbers) and returns a :class:`GradientEstimate`.

Every rollout runs in the one closed-loop engine (:func:`drake_abs.engine.rollout`).
Unconverged solver steps: the objective's ``on_unconverged`` policy (default ``"drop"``) decides;
under ``"drop"`` every average runs over the rollouts whose steps all converged, and the estimate
says how many were dropped. An estimate with no usable rollout raises
:class:`~drake_abs.contact.unconverged.UnconvergedStepError`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs.contact.unconverged import (
    UnconvergedPolicy,
    UnconvergedStepError,
    check_unconverged_policy,
)
from drake_abs.engine import Policy, Reward, Stepper, Trajectory, rollout
from drake_abs.engine.closed_loop import STEPPER_FORM
from drake_abs.engine.protocols import check_protocol


@dataclass(frozen=True)
class PolicyObjective:
    """The stochastic objective: dynamics, policy, reward, initial state(s), horizon, noise.

    Args:
        stepper: batched dynamics (a :class:`~drake_abs.engine.Stepper`).
        policy: a :class:`~drake_abs.engine.Policy` (e.g. of :mod:`drake_abs.policy.policies`).
        reward: a :class:`~drake_abs.engine.Reward` (maximised).
        x0: (nx,) initial state.
        horizon: H steps.
        sigma: exploration noise scale (units of u).
        on_unconverged: ``"drop"`` (default), ``"flag"`` or ``"raise"``: what rollouts with an
            unconverged solver step count for (:func:`~drake_abs.engine.rollout`).
    """

    stepper: Stepper
    policy: Policy
    reward: Reward
    x0: np.ndarray
    horizon: int
    sigma: float = 0.1
    on_unconverged: UnconvergedPolicy = "drop"

    def __post_init__(self):
        check_unconverged_policy(self.on_unconverged)
        check_protocol(self.stepper, Stepper, "stepper", STEPPER_FORM)
        check_protocol(self.policy, Policy, "policy", "nx, nu, n_params, act, jacobians, vjp")
        check_protocol(self.reward, Reward, "reward", "stage, terminal")
        if int(self.horizon) < 1:
            raise ValueError(f"horizon must be >= 1; got {self.horizon!r}")
        if not (np.isfinite(self.sigma) and self.sigma >= 0):
            raise ValueError(f"sigma must be >= 0; got {self.sigma!r}")

    def noise(self, rng: np.random.Generator, M: int) -> np.ndarray:
        return rng.standard_normal((M, int(self.horizon), self.policy.nu))

    def rollout(self, theta, noise: np.ndarray, gradient: bool = True) -> Trajectory:
        return rollout(
            self.stepper, self.policy, theta, self.x0, noise, self.reward,
            sigma=self.sigma, gradient=gradient, on_unconverged=self.on_unconverged,
        )  # fmt: skip


@dataclass(frozen=True)
class GradientEstimate:
    """One estimate: ``grad`` (P,) of the mean return, ``value`` (mean return of the rollouts
    it used), ``rollouts`` and ``steps`` (simulated), ``unconverged`` (steps whose solver did not
    converge), ``dropped`` (rollouts left out for them, under ``on_unconverged="drop"``)."""

    grad: np.ndarray
    value: float
    rollouts: int
    steps: int
    unconverged: int
    dropped: int = 0


def _summary(grad, returns, rollouts: list[Trajectory]) -> GradientEstimate:
    steps = sum(r.converged.size for r in rollouts)
    bad = sum(int((~r.converged).sum()) for r in rollouts)
    n = sum(r.converged.shape[0] for r in rollouts)
    dropped = sum(r.dropped for r in rollouts)
    return GradientEstimate(np.asarray(grad), float(np.mean(returns)), n, steps, bad, dropped)


def _require(count: int, needed: int, what: str) -> None:
    if count < needed:
        raise UnconvergedStepError(
            f"{what}: only {count} rollout(s) without unconverged steps, {needed} needed"
        )


def first_order(obj: PolicyObjective, theta, rng: np.random.Generator, M: int) -> GradientEstimate:
    """FOPG (eq. 4.1) from M rollouts (the mean over the rollouts used)."""
    r = obj.rollout(theta, obj.noise(rng, M))
    _require(int(r.used.sum()), 1, "first_order")
    return _summary(r.grad[r.used].mean(axis=0), r.returns[r.used], [r])


def _score(obj: PolicyObjective, theta, r: Trajectory, noise: np.ndarray) -> np.ndarray:
    """sum_t grad_theta log pi(u_t | x_t) per rollout (M, P): (xi_t / sigma) dpi/dtheta."""
    if obj.sigma <= 0:
        raise ValueError("the likelihood-ratio estimator needs exploration noise: sigma > 0")
    score = np.zeros((noise.shape[0], np.size(theta)))
    for t in range(noise.shape[1]):
        score += obj.policy.vjp(theta, r.x[:, t], noise[:, t] / obj.sigma)[1]
    return score


def _loo_baseline(R: np.ndarray) -> np.ndarray:
    M = R.size
    return (R.sum() - R) / (M - 1) if M > 1 else np.zeros(M)


def zeroth_order(obj: PolicyObjective, theta, rng: np.random.Generator, M: int) -> GradientEstimate:
    """ZOPG: likelihood ratio with a leave-one-out baseline, from M rollouts (M >= 2)."""
    if M < 2:
        raise ValueError(f"M must be >= 2 for the leave-one-out baseline; got {M}")
    noise = obj.noise(rng, M)
    r = obj.rollout(theta, noise, gradient=False)
    _require(int(r.used.sum()), 2, "zeroth_order")
    score = _score(obj, theta, r, noise)[r.used]
    R = r.returns[r.used]
    adv = R - _loo_baseline(R)
    return _summary((adv[:, None] * score).mean(axis=0), R, [r])


def alpha_order(
    obj: PolicyObjective, theta, rng: np.random.Generator, M: int, alpha: float
) -> GradientEstimate:
    """``alpha g_FO + (1 - alpha) g_ZO`` from the same M rollouts (alpha in [0, 1])."""
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"alpha must be in [0, 1]; got {alpha!r}")
    noise = obj.noise(rng, M)
    r = obj.rollout(theta, noise)
    _require(int(r.used.sum()), 2, "alpha_order")
    score = _score(obj, theta, r, noise)[r.used]
    R = r.returns[r.used]
    g_zo = ((R - _loo_baseline(R))[:, None] * score).mean(axis=0)
    return _summary(alpha * r.grad[r.used].mean(axis=0) + (1 - alpha) * g_zo, R, [r])


def randomized_smoothing(
    obj: PolicyObjective, theta, rng: np.random.Generator, N: int, std: float
) -> GradientEstimate:
    """Bundled gradient: the mean first-order gradient at N parameters theta + w_i,
    ``w_i ~ N(0, std^2 I)``, one rollout each (its own action noise)."""
    if not (np.isfinite(std) and std > 0):
        raise ValueError(f"std must be a finite number > 0; got {std!r}")
    theta = np.asarray(theta, float)
    w = std * rng.standard_normal((N, theta.size))
    noise = obj.noise(rng, N)
    grads, returns, rolls = [], [], []
    for i in range(N):  # one parameter per rollout: N batched rollouts of one
        r = obj.rollout(theta + w[i], noise[i : i + 1])
        rolls.append(r)
        if r.used[0]:
            grads.append(r.grad[0])
            returns.append(r.returns[0])
    _require(len(grads), 1, "randomized_smoothing")
    return _summary(np.mean(grads, axis=0), np.array(returns), rolls)


def ars(
    obj: PolicyObjective,
    theta,
    rng: np.random.Generator,
    directions: int,
    step: float,
    top: int | None = None,
    M: int = 1,
) -> GradientEstimate:
    """ARS V1-t (Mania et al. 2018): ``(1 / (b sigma_R)) sum_top (J(theta + s d) -
    J(theta - s d)) d`` over b = ``top`` of ``directions`` Gaussian directions d, with s =
    ``step``; each J from M rollouts with common noise for the + and - evaluation. Returned as
    an ascent direction in the units ARS steps with (not divided by s)."""
    theta = np.asarray(theta, float)
    top = directions if top is None else int(top)
    if not 1 <= top <= directions:
        raise ValueError(f"top must be in [1, directions = {directions}]; got {top}")
    d = rng.standard_normal((directions, theta.size))
    plus, minus, rolls = np.empty(directions), np.empty(directions), []
    valid = np.ones(directions, dtype=bool)  # both sides free of unconverged rollouts
    for i in range(directions):
        noise = obj.noise(rng, M)
        rp = obj.rollout(theta + step * d[i], noise, gradient=False)
        rm = obj.rollout(theta - step * d[i], noise, gradient=False)
        plus[i], minus[i] = rp.returns.mean(), rm.returns.mean()
        valid[i] = rp.used.all() and rm.used.all()
        rolls += [rp, rm]
    _require(int(valid.sum()), top, "ars (directions)")
    plus, minus, d = plus[valid], minus[valid], d[valid]
    best = np.argsort(-np.maximum(plus, minus))[:top]
    used = np.concatenate([plus[best], minus[best]])
    scale = used.std() if used.std() > 0 else 1.0
    grad = ((plus[best] - minus[best])[:, None] * d[best]).sum(axis=0) / (top * scale)
    return _summary(grad, np.concatenate([plus, minus]), rolls)
