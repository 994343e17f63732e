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

Where the rollouts run: each estimator states its rollouts as jobs
(:class:`~drake_abs.policy.rollouts.RolloutJob`) with noise from a seed tree, and a ``runner``
runs them: this process by default, or Ray actors (:class:`drake_abs.parallel.RayRunner`). The
estimate is the same, to rounding, whatever runs the jobs and however they are split.

Every rollout runs in the one closed-loop engine (:func:`drake_abs.engine.rollout`).
Unconverged solver steps: the objective's ``on_unconverged`` policy (default ``"drop"``) decides;
under ``"drop"`` every average runs over the rollouts whose steps all converged, and the estimate
says how many were dropped. An estimate with no usable rollout raises
:class:`~drake_abs.contact.unconverged.UnconvergedStepError`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_count, as_finite_array, as_real_number
from drake_abs.contact.unconverged import (
    OnUnconverged,
    UnconvergedStepError,
    check_on_unconverged,
)
from drake_abs.engine import Policy, Reward, Stepper, Trajectory, rollout
from drake_abs.engine.closed_loop import STEPPER_FORM
from drake_abs.engine.protocols import check_protocol, check_reward
from drake_abs.engine.steppers import refuse_inside_ground
from drake_abs.policy.rollouts import (
    RolloutJob,
    RolloutStats,
    Runner,
    default_runner,
    noise_key,
    reraise_warnings,
    rollout_noise,
)


@dataclass(frozen=True)
class PolicyObjective:
    """The stochastic objective: dynamics, policy, reward, initial state(s), horizon, noise.

    Args:
        stepper: batched dynamics (a :class:`~drake_abs.engine.Stepper`).
        policy: a :class:`~drake_abs.engine.Policy` (e.g. of :mod:`drake_abs.policy.policies`).
        reward: a :class:`~drake_abs.engine.Reward` (maximised).
        x0: (nx,) initial state.
        horizon: H steps, a whole number >= 1 (an integral float such as 5.0 is taken as 5;
            1.7, text, booleans, NaN and inf are refused).
        sigma: exploration noise scale (units of u), a finite real number >= 0.
        on_unconverged: ``"drop"`` (default), ``"flag"`` or ``"raise"``: what rollouts with an
            unconverged solver step count for (:func:`~drake_abs.engine.rollout`).
    """

    stepper: Stepper
    policy: Policy
    reward: Reward
    x0: np.ndarray
    horizon: int
    sigma: float = 0.1
    on_unconverged: OnUnconverged = "drop"

    def __post_init__(self):
        check_on_unconverged(self.on_unconverged)
        check_protocol(self.stepper, Stepper, "stepper", STEPPER_FORM)
        check_protocol(self.policy, Policy, "policy", "nx, nu, n_params, act, jacobians, vjp")
        check_reward(self.reward)
        x0 = as_finite_array(self.x0, "x0")
        if x0.shape != (self.policy.nx,):
            raise ValueError(
                f"x0 must have shape (nx,) = ({self.policy.nx},), the policy's state size; got "
                f"{x0.shape}"
            )
        for size in ("nx", "nu"):
            mine, theirs = getattr(self.policy, size), getattr(self.reward, size, None)
            if theirs is not None and theirs != mine:
                raise ValueError(
                    f"reward and policy disagree on {size}: the reward's is {theirs}, the "
                    f"policy's {mine}"
                )
        refuse_inside_ground(self.stepper, x0, "x0")
        # a whole number of steps >= 1 (1.7, "5", True and NaN are refused, not truncated)
        object.__setattr__(self, "horizon", as_count(self.horizon, "horizon", minimum=1))
        object.__setattr__(self, "sigma", as_real_number(self.sigma, "sigma", minimum=0.0))

    def noise(self, rng: np.random.Generator, M: int) -> np.ndarray:
        """(M, H, nu) standard-normal exploration noise: rollouts 0..M-1 of a fresh stream of
        the seed tree (:func:`~drake_abs.policy.rollouts.rollout_noise`), the noise an estimator
        given the same ``rng`` uses."""
        return rollout_noise(noise_key(rng), 0, int(M), int(self.horizon), self.policy.nu)

    def rollout(self, theta, noise: np.ndarray, gradient: bool = True) -> Trajectory:
        return rollout(
            self.stepper, self.policy, theta, self.x0, noise, self.reward,
            sigma=self.sigma, gradient=gradient, on_unconverged=self.on_unconverged,
        )  # fmt: skip


@dataclass(frozen=True)
class GradientEstimate:
    """One estimate: ``grad`` (P,) of the mean return, ``value`` (mean return of the rollouts
    it used), ``rollouts`` and ``steps`` (simulated), ``unconverged`` (steps whose solver did not
    converge), ``dropped`` (rollouts left out for them, under ``on_unconverged="drop"``),
    ``env_steps`` (the steps that counted: ``steps`` unless episodes ended early; the sample
    count of a learning curve)."""

    grad: np.ndarray
    value: float
    rollouts: int
    steps: int
    unconverged: int
    dropped: int = 0
    env_steps: int = 0


def _summary(grad, returns, stats: list[RolloutStats]) -> GradientEstimate:
    return GradientEstimate(
        np.asarray(grad), float(np.mean(returns)), sum(s.rollouts for s in stats),
        sum(s.steps for s in stats), sum(int(s.unconverged.sum()) for s in stats),
        sum(s.dropped for s in stats), sum(int(s.env_steps.sum()) for s in stats),
    )  # fmt: skip


def _require(count: int, needed: int, what: str) -> None:
    if count < needed:
        raise UnconvergedStepError(
            f"{what}: only {count} rollout(s) without unconverged steps, {needed} needed"
        )


def _run(obj: PolicyObjective, runner: Runner | None, jobs: list[RolloutJob], *, gradient: bool,
         score: bool = False) -> list[RolloutStats]:  # fmt: skip
    """The jobs' per-rollout results from ``runner`` (default: :func:`default_runner`)."""
    runner = default_runner() if runner is None else runner
    if not isinstance(runner, Runner):
        raise ValueError(
            f"runner must have run(objective, jobs, *, gradient, score) (a LocalRunner or a "
            f"drake_abs.parallel.RayRunner); got {type(runner).__name__}"
        )
    stats = runner.run(obj, jobs, gradient=gradient, score=score)
    if len(stats) != len(jobs) or any(
        s.rollouts != j.size for s, j in zip(stats, jobs, strict=True)
    ):
        raise RuntimeError(f"{runner!r} returned results that do not match the jobs it was given")
    reraise_warnings(stats)
    return stats


def first_order(
    obj: PolicyObjective, theta, rng: np.random.Generator, M: int, *, runner: Runner | None = None
) -> GradientEstimate:
    """FOPG (eq. 4.1) from M rollouts (the mean over the rollouts used)."""
    (s,) = _run(obj, runner, [RolloutJob(theta, noise_key(rng), 0, _count(M, "M"))], gradient=True)
    _require(int(s.used.sum()), 1, "first_order")
    return _summary(s.grad[s.used].mean(axis=0), s.returns[s.used], [s])


def _count(value, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} must be a whole number >= {minimum}; got {value!r}")
    return int(value)


def _loo_baseline(R: np.ndarray) -> np.ndarray:
    M = R.size
    return (R.sum() - R) / (M - 1) if M > 1 else np.zeros(M)


def zeroth_order(
    obj: PolicyObjective, theta, rng: np.random.Generator, M: int, *, runner: Runner | None = None
) -> GradientEstimate:
    """ZOPG: likelihood ratio with a leave-one-out baseline, from M rollouts (M >= 2)."""
    M = _count(M, "M", 2)  # the leave-one-out baseline needs another sample
    if obj.sigma <= 0:
        raise ValueError("the likelihood-ratio estimator needs exploration noise: sigma > 0")
    job = RolloutJob(theta, noise_key(rng), 0, M)
    (s,) = _run(obj, runner, [job], gradient=False, score=True)
    _require(int(s.used.sum()), 2, "zeroth_order")
    R = s.returns[s.used]
    adv = R - _loo_baseline(R)
    return _summary((adv[:, None] * s.score[s.used]).mean(axis=0), R, [s])


def alpha_order(
    obj: PolicyObjective, theta, rng: np.random.Generator, M: int, alpha: float, *,
    runner: Runner | None = None,
) -> GradientEstimate:  # fmt: skip
    """``alpha g_FO + (1 - alpha) g_ZO`` from the same M rollouts (alpha in [0, 1])."""
    alpha = as_real_number(alpha, "alpha")
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"alpha must be in [0, 1]; got {alpha!r}")
    if obj.sigma <= 0:
        raise ValueError("the likelihood-ratio estimator needs exploration noise: sigma > 0")
    job = RolloutJob(theta, noise_key(rng), 0, _count(M, "M"))
    (s,) = _run(obj, runner, [job], gradient=True, score=True)
    _require(int(s.used.sum()), 2, "alpha_order")
    R = s.returns[s.used]
    g_zo = ((R - _loo_baseline(R))[:, None] * s.score[s.used]).mean(axis=0)
    return _summary(alpha * s.grad[s.used].mean(axis=0) + (1 - alpha) * g_zo, R, [s])


def randomized_smoothing(
    obj: PolicyObjective, theta, rng: np.random.Generator, N: int, std: float, *,
    runner: Runner | None = None,
) -> GradientEstimate:  # fmt: skip
    """Bundled gradient: the mean first-order gradient at N parameters theta + w_i,
    ``w_i ~ N(0, std^2 I)``, one rollout each (rollout i of one noise stream)."""
    if as_real_number(std, "std") <= 0:
        raise ValueError(f"std must be a finite number > 0; got {std!r}")
    theta = as_finite_array(theta, "theta", ndim=(1,))
    w = std * rng.standard_normal((_count(N, "N"), theta.size))
    key = noise_key(rng)
    jobs = [RolloutJob(theta + w[i], key, i, i + 1) for i in range(N)]
    stats = _run(obj, runner, jobs, gradient=True)
    used = [s for s in stats if s.used[0]]
    _require(len(used), 1, "randomized_smoothing")
    grads = np.array([s.grad[0] for s in used])
    return _summary(grads.mean(axis=0), np.array([s.returns[0] for s in used]), stats)


def ars(
    obj: PolicyObjective,
    theta,
    rng: np.random.Generator,
    directions: int,
    step: float,
    top: int | None = None,
    M: int = 1,
    *,
    runner: Runner | None = None,
) -> GradientEstimate:
    """ARS V1-t (Mania et al. 2018): ``(1 / (b sigma_R)) sum_top (J(theta + s d) -
    J(theta - s d)) d`` over b = ``top`` of ``directions`` Gaussian directions d, with s =
    ``step``; each J from M rollouts with common noise for the + and - evaluation. Returned as
    an ascent direction in the units ARS steps with (not divided by s)."""
    theta = as_finite_array(theta, "theta", ndim=(1,))
    directions = _count(directions, "directions")
    if as_real_number(step, "step") <= 0:
        raise ValueError(f"step must be a finite number > 0; got {step!r}")
    top = directions if top is None else int(top)
    if not 1 <= top <= directions:
        raise ValueError(f"top must be in [1, directions = {directions}]; got {top}")
    d = rng.standard_normal((directions, theta.size))
    keys = [noise_key(rng) for _ in range(directions)]  # common noise for + and -
    jobs = [
        RolloutJob(theta + sign * step * d[i], keys[i], 0, _count(M, "M"))
        for i in range(directions)
        for sign in (1.0, -1.0)
    ]
    stats = _run(obj, runner, jobs, gradient=False)
    plus = np.array([s.returns.mean() for s in stats[0::2]])
    minus = np.array([s.returns.mean() for s in stats[1::2]])
    valid = np.array(
        [p.used.all() and m.used.all() for p, m in zip(stats[0::2], stats[1::2], strict=True)]
    )
    _require(int(valid.sum()), top, "ars (directions)")
    plus, minus, d = plus[valid], minus[valid], d[valid]
    best = np.argsort(-np.maximum(plus, minus))[:top]
    used = np.concatenate([plus[best], minus[best]])
    scale = used.std() if used.std() > 0 else 1.0
    grad = ((plus[best] - minus[best])[:, None] * d[best]).sum(axis=0) / (top * scale)
    return _summary(grad, np.concatenate([plus, minus]), stats)
