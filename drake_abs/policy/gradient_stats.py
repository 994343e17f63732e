"""Variance and bias of policy-gradient estimators (docs/math.md section 7; Zhang et al. 2023,
Theorem 4.2,
section 8.2 Figure 3 and section 8.4 Figure 5).

For an estimator ``g_hat(theta)`` of ``grad J(theta)`` (one call = one estimate from a batch of
rollouts) this module measures

- the **variance** ``v = E || g_hat - E g_hat ||^2`` (the trace of its covariance, units of
  grad^2), from K repeated independent batches (:func:`measure_variance`);
- the **bias** ``b = || E g_hat - grad J_exact ||`` against a high-sample reference gradient of
  the *exact* objective, i.e. hard contact (:func:`reference_gradient`, :func:`measure_bias`);
- both over smoothing designs, gradient modes and horizons (:func:`variance_bias_sweep`).

Compute cost. Every estimate is timed (wall clock, ``time.perf_counter``). The **variance per
second of compute** is ``variance_seconds = v * t`` with t the mean seconds per estimate: the
variance of the average of the ``1 / t`` independent estimates one second of compute buys
(``v / (1 / t)``). Lower is better; it is what compares a cheap noisy estimator with an expensive
quiet one at equal compute.

The reference gradient. ``J_exact(theta) = E_xi[R(theta, xi)]`` is smooth in theta because the
action noise smooths it, but its pathwise (first-order) estimate through hard contact can have a
huge variance, and it is unbiased only when every return ``R(., xi)`` is continuous in theta
(true for the inelastic LCS, whose step is Lipschitz; not guaranteed for every contact model).
The likelihood-ratio (zeroth-order) estimate is unbiased without any smoothness of the dynamics,
but noisy in its own way. :func:`reference_gradient` therefore computes both from many samples,
in independent batches so that each has a measured standard error, and checks that they agree
within those errors. If they agree, the reference is their inverse-variance weighted mean; if not
(a sign that the first-order estimate is biased), the zeroth-order one alone. Its standard
error travels with it, and :func:`measure_bias` reports a bias smaller than the combined noise
as *unresolved* (``bias = None``) rather than as a number.

Everything random comes from an integer ``seed`` through ``numpy.random.SeedSequence``: the same
seed gives the same numbers. Results are frozen dataclasses with ``to_dict()`` for JSON.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from drake_abs.contact.lcs import GradientMode, check_gradient_mode
from drake_abs.contact.smoothing import Exact, Smoothing
from drake_abs.policy.estimators import GradientEstimate, PolicyObjective, first_order, zeroth_order

#: ``estimator(theta, rng) -> GradientEstimate``: one estimate, all randomness from ``rng``.
Estimator = Callable[[np.ndarray, np.random.Generator], GradientEstimate]
#: ``make_estimator(objective, theta, rng) -> GradientEstimate`` (e.g. FOPG with M rollouts).
ObjectiveEstimator = Callable[[PolicyObjective, np.ndarray, np.random.Generator], GradientEstimate]

#: A first- and zeroth-order reference disagree when ``||g_FO - g_ZO||^2`` exceeds this many
#: times its expectation under "both unbiased" (``se_FO^2 + se_ZO^2``).
AGREEMENT_THRESHOLD = 4.0
#: A bias is resolved when the measured distance exceeds this many times the noise floor.
RESOLUTION_FACTOR = 2.0


def _check_int(value, name: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


def _seed_sequence(seed) -> np.random.SeedSequence:
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer; got {seed!r}")
    return np.random.SeedSequence(int(seed))


def _child(seq: np.random.SeedSequence, *keys: int) -> np.random.SeedSequence:
    """A child of ``seq`` named by ``keys`` (unlike ``spawn``, it does not change ``seq``, so the
    same seed object always gives the same children)."""
    return np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, *keys))


@dataclass(frozen=True)
class VarianceStats:
    """K independent estimates of one estimator at one theta.

    Attributes:
        mean_grad: (P,) mean of the K estimates (an estimate of ``E g_hat``).
        trace_variance: ``v = E||g_hat - E g_hat||^2`` of ONE estimate, unbiased
            (``sum_k ||g_k - mean||^2 / (K - 1)``), units of grad^2.
        trace_variance_se: its standard error (the spread of the per-batch squared deviations
            over sqrt(K); about ``v sqrt(2 / (K - 1))`` for Gaussian estimates in one dimension).
        mean_grad_se: ``sqrt(v / K)``, the root expected squared error of ``mean_grad``.
        batches: K.
        seconds_per_estimate: mean wall-clock seconds of one estimate.
        variance_seconds: ``v * seconds_per_estimate``: the variance per second of compute
            (the variance of an average over one second's worth of estimates; lower is better).
        mean_value: mean over the batches of the estimates' mean return.
        rollouts_per_estimate: rollouts one estimate simulates.
        unconverged_steps: solver steps that did not converge, summed over all K batches.
        dropped_rollouts: rollouts the estimates left out for those steps (``"drop"`` policy).
        steps: simulated steps, summed over all K batches.
        largest_batch_share: the largest single batch's share of ``sum_k ||g_k - mean||^2``.
            A heavy-tail diagnostic: about ``log(K) / K`` or less for Gaussian-like estimates,
            near 1 when one batch caught a rare huge gradient. Hard-contact FOPG is heavy
            tailed (on the hopping ball, 1 % of rollouts carry 70 % of the variance at H = 100):
            then K batches that miss the tail *underestimate* ``v`` and the standard errors, and
            a small-sample mean looks biased (the "empirical bias" of Suh et al. 2022).
    """

    mean_grad: np.ndarray
    trace_variance: float
    trace_variance_se: float
    mean_grad_se: float
    batches: int
    seconds_per_estimate: float
    variance_seconds: float
    mean_value: float
    rollouts_per_estimate: int
    unconverged_steps: int
    steps: int
    largest_batch_share: float
    dropped_rollouts: int = 0

    def to_dict(self) -> dict:
        return {
            "mean_grad": self.mean_grad.tolist(),
            "trace_variance": self.trace_variance,
            "trace_variance_se": self.trace_variance_se,
            "mean_grad_se": self.mean_grad_se,
            "batches": self.batches,
            "seconds_per_estimate": self.seconds_per_estimate,
            "variance_seconds": self.variance_seconds,
            "mean_value": self.mean_value,
            "rollouts_per_estimate": self.rollouts_per_estimate,
            "unconverged_steps": self.unconverged_steps,
            "steps": self.steps,
            "largest_batch_share": self.largest_batch_share,
            "dropped_rollouts": self.dropped_rollouts,
        }


def trace_variance(grads: np.ndarray) -> tuple[float, float]:
    """Unbiased ``E||g - E g||^2`` from K independent samples ``grads`` (K, P), and its standard
    error: ``(sum_k ||g_k - mean||^2 / (K - 1), std_k(d_k) / sqrt(K))`` with
    ``d_k = K / (K - 1) ||g_k - mean||^2`` (each d_k has expectation v)."""
    g = np.asarray(grads, dtype=float)
    if g.ndim != 2 or g.shape[0] < 2:
        raise ValueError(f"grads must have shape (K, P) with K >= 2; got {g.shape}")
    K = g.shape[0]
    d = K / (K - 1) * np.sum((g - g.mean(axis=0)) ** 2, axis=1)
    return float(d.mean()), float(d.std(ddof=1) / np.sqrt(K))


def measure_variance(estimator: Estimator, theta, *, batches: int, seed) -> VarianceStats:
    """Call ``estimator`` K = ``batches`` times at ``theta``, each with its own independent
    Generator (spawned from ``seed``), timing each call.

    Args:
        estimator: ``estimator(theta, rng) -> GradientEstimate``.
        theta: (P,) parameters.
        batches: K >= 2 independent estimates.
        seed: non-negative integer (or a ``SeedSequence``); the same seed gives the same numbers.

    Raises:
        FloatingPointError: an estimate was not finite (its batch index is named).
    """
    K = _check_int(batches, "batches", 2)
    theta = np.asarray(theta, dtype=float)
    root = _seed_sequence(seed)
    rngs = [np.random.default_rng(_child(root, k)) for k in range(K)]
    grads, values, seconds = [], [], []
    rollouts = unconverged = steps = dropped = 0
    for k, rng in enumerate(rngs):
        start = time.perf_counter()
        est = estimator(theta, rng)
        seconds.append(time.perf_counter() - start)
        g = np.asarray(est.grad, dtype=float)
        if not np.all(np.isfinite(g)):
            raise FloatingPointError(f"estimate {k} of {K} is not finite")
        grads.append(g)
        values.append(est.value)
        rollouts = est.rollouts
        unconverged += est.unconverged
        dropped += est.dropped
        steps += est.steps
    grads = np.array(grads)
    v, v_se = trace_variance(grads)
    dev = np.sum((grads - grads.mean(axis=0)) ** 2, axis=1)
    share = float(dev.max() / dev.sum()) if dev.sum() > 0 else 0.0
    t = float(np.mean(seconds))
    return VarianceStats(
        mean_grad=grads.mean(axis=0),
        trace_variance=v,
        trace_variance_se=v_se,
        mean_grad_se=float(np.sqrt(v / K)),
        batches=K,
        seconds_per_estimate=t,
        variance_seconds=v * t,
        mean_value=float(np.mean(values)),
        rollouts_per_estimate=int(rollouts),
        unconverged_steps=int(unconverged),
        steps=int(steps),
        largest_batch_share=share,
        dropped_rollouts=int(dropped),
    )


@dataclass(frozen=True)
class ReferenceGradient:
    """A high-sample estimate of the exact objective's gradient, with its standard error.

    Attributes:
        grad: (P,) the reference.
        std_error: root expected squared error ``sqrt(E||grad - grad J_exact||^2)`` (estimated).
        method: ``"combined"`` (inverse-variance mean of first- and zeroth-order),
            ``"first_order"`` or ``"zeroth_order"``.
        first_order, zeroth_order: the two measurements (None when not computed).
        agreement: ``||g_FO - g_ZO||^2 / (se_FO^2 + se_ZO^2)`` (about 1 when both are unbiased;
            None unless both were computed).
        consistent: ``agreement <= AGREEMENT_THRESHOLD`` (None unless both were computed).
    """

    grad: np.ndarray
    std_error: float
    method: str
    first_order: VarianceStats | None
    zeroth_order: VarianceStats | None
    agreement: float | None
    consistent: bool | None

    def to_dict(self) -> dict:
        return {
            "grad": self.grad.tolist(),
            "std_error": self.std_error,
            "method": self.method,
            "first_order": None if self.first_order is None else self.first_order.to_dict(),
            "zeroth_order": None if self.zeroth_order is None else self.zeroth_order.to_dict(),
            "agreement": self.agreement,
            "consistent": self.consistent,
        }


def reference_gradient(
    exact: PolicyObjective,
    theta,
    *,
    samples: int,
    batches: int = 16,
    seed,
    method: str = "combined",
) -> ReferenceGradient:
    """The gradient of the exact objective from ``samples`` rollouts per estimator, split into
    ``batches`` independent batches (the batch-to-batch spread gives the standard error).

    Args:
        exact: the objective under hard contact (``Exact()`` smoothing); the caller's duty.
        theta: (P,) parameters.
        samples: rollouts per estimator (each of FOPG and ZOPG with ``"combined"``).
        batches: independent batches they are split into (>= 2).
        seed: non-negative integer.
        method: ``"combined"`` (both; the inverse-variance weighted mean if they agree within
            ``AGREEMENT_THRESHOLD``, else the zeroth-order one, which needs no smoothness),
            ``"first_order"`` or ``"zeroth_order"``.
    """
    if method not in ("combined", "first_order", "zeroth_order"):
        raise ValueError(
            f"method must be 'combined', 'first_order' or 'zeroth_order'; got {method!r}"
        )
    smoothing = getattr(exact.stepper, "smoothing", None)
    if smoothing is not None and not smoothing.is_exact:
        raise ValueError(f"exact must be the hard-contact objective (Exact()); got {smoothing!r}")
    K = _check_int(batches, "batches", 2)
    n = _check_int(samples, "samples", 2 * K)
    m = n // K
    root = _seed_sequence(seed)
    fo_seed, zo_seed = _child(root, 0), _child(root, 1)
    fo = zo = None
    if method in ("combined", "first_order"):
        fo = measure_variance(
            lambda th, rng: first_order(exact, th, rng, m), theta, batches=K, seed=fo_seed
        )
    if method in ("combined", "zeroth_order"):
        zo = measure_variance(
            lambda th, rng: zeroth_order(exact, th, rng, m), theta, batches=K, seed=zo_seed
        )
    if fo is None or zo is None:
        only = fo if zo is None else zo
        return ReferenceGradient(only.mean_grad, only.mean_grad_se, method, fo, zo, None, None)
    s_fo, s_zo = fo.mean_grad_se**2, zo.mean_grad_se**2
    gap = float(np.sum((fo.mean_grad - zo.mean_grad) ** 2))
    agreement = gap / (s_fo + s_zo) if s_fo + s_zo > 0 else (0.0 if gap == 0 else np.inf)
    consistent = bool(agreement <= AGREEMENT_THRESHOLD)
    if not consistent:
        return ReferenceGradient(
            zo.mean_grad, zo.mean_grad_se, "zeroth_order", fo, zo, agreement, False
        )
    if s_fo + s_zo == 0:
        return ReferenceGradient(fo.mean_grad, 0.0, "combined", fo, zo, agreement, True)
    w = s_zo / (s_fo + s_zo)  # weight of the first-order estimate
    grad = w * fo.mean_grad + (1 - w) * zo.mean_grad
    se = float(np.sqrt(s_fo * s_zo / (s_fo + s_zo)))
    return ReferenceGradient(grad, se, "combined", fo, zo, agreement, consistent)


@dataclass(frozen=True)
class BiasStats:
    """``b = ||E g_hat - grad J_exact||`` measured as the distance between two noisy means.

    Attributes:
        distance: ``||mean_grad - reference||``.
        noise: ``sqrt(mean_grad_se^2 + reference_se^2)``: the distance expected from noise
            alone (``E distance^2 = b^2 + noise^2``).
        resolved: ``distance > RESOLUTION_FACTOR * noise``.
        bias: ``sqrt(distance^2 - noise^2)`` when resolved, else None (unresolved: the bias is
            below what these sample sizes can see, roughly below ``RESOLUTION_FACTOR * noise``).
        relative_bias: ``bias / ||reference||`` (None when unresolved).
        reference_norm: ``||reference||``.
    """

    distance: float
    noise: float
    resolved: bool
    bias: float | None
    relative_bias: float | None
    reference_norm: float

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def measure_bias(stats: VarianceStats, reference: ReferenceGradient) -> BiasStats:
    """The bias of the estimator measured by ``stats`` against ``reference`` (same theta)."""
    if stats.mean_grad.shape != reference.grad.shape:
        raise ValueError(
            f"stats.mean_grad {stats.mean_grad.shape} and reference.grad "
            f"{reference.grad.shape} must have the same shape"
        )
    distance = float(np.linalg.norm(stats.mean_grad - reference.grad))
    noise = float(np.hypot(stats.mean_grad_se, reference.std_error))
    resolved = bool(distance > RESOLUTION_FACTOR * noise)
    bias = float(np.sqrt(distance**2 - noise**2)) if resolved else None
    ref_norm = float(np.linalg.norm(reference.grad))
    rel = None if bias is None or ref_norm == 0 else bias / ref_norm
    return BiasStats(distance, noise, resolved, bias, rel, ref_norm)


def fopg(samples: int) -> ObjectiveEstimator:
    """FOPG (Zhang et al. 2023, eq. 4.1) with ``samples`` rollouts per estimate, as an
    :data:`ObjectiveEstimator`."""
    m = _check_int(samples, "samples", 1)
    return lambda obj, theta, rng: first_order(obj, theta, rng, m)


def variance_bias_sweep(
    make_objective: Callable[[Smoothing, GradientMode, int], PolicyObjective],
    theta,
    policies: Mapping[str, Smoothing],
    horizons: Sequence[int],
    *,
    batches: int,
    seed,
    estimator: ObjectiveEstimator | None = None,
    modes: Sequence[GradientMode] = ("frozen", "total"),
    reference_samples: int | None = None,
    reference_batches: int = 16,
    progress: Callable[[str], None] | None = None,
) -> list[dict]:
    """Variance (and, with ``reference_samples``, bias) of an estimator over smoothing designs,
    gradient modes and horizons, all at one theta.

    Args:
        make_objective: ``(policy, mode, horizon) -> PolicyObjective``.
        theta: (P,) parameters.
        policies: name -> smoothing (e.g. ``{"exact": Exact(), "bs_1e-2": Fixed(1e-2),
            "abs": ContactAware(1e-2, 0.05)}``); larger mu is more smoothing.
        horizons: horizons H to measure.
        batches: independent estimates per point (K >= 2).
        seed: non-negative integer. Every policy and mode at one horizon uses the same seed
            (common random numbers: their differences are not blurred by different noise).
        estimator: an :data:`ObjectiveEstimator`; FOPG with 64 rollouts by default.
        modes: gradient modes; for constant policies (Exact, Fixed) only the first is measured,
            as the two coincide (the row's ``modes_coincide`` says so).
        reference_samples: when given, the bias against :func:`reference_gradient` of
            ``make_objective(Exact(), "frozen", H)`` with that many samples, per horizon.
        reference_batches: batches of the reference.
        progress: optional callback receiving one line per finished point.

    Returns:
        One JSON-ready dict per (policy, mode, horizon): ``policy``, ``mode``, ``horizon``,
        ``modes_coincide``, the :class:`VarianceStats` fields (without ``mean_grad``), and with
        a reference ``bias`` (a :class:`BiasStats` dict).
    """
    if not policies:
        raise ValueError("policies must name at least one smoothing")
    hs = [_check_int(h, "horizons[i]", 1) for h in horizons]
    if not hs:
        raise ValueError("horizons must contain at least one horizon")
    for mode in modes:
        check_gradient_mode(mode, "modes")
    estimator = estimator or fopg(64)
    theta = np.asarray(theta, dtype=float)
    root = _seed_sequence(seed)
    rows = []
    for H in hs:
        ref = None
        if reference_samples is not None:
            exact = make_objective(Exact(), "frozen", H)
            ref = reference_gradient(
                exact,
                theta,
                samples=reference_samples,
                batches=reference_batches,
                seed=_child(root, H, 1),
            )
        for name, policy in policies.items():
            for i, mode in enumerate(modes):
                if policy.is_constant and i > 0:
                    continue
                obj = make_objective(policy, mode, H)
                stats = measure_variance(
                    lambda th, rng, obj=obj: estimator(obj, th, rng),
                    theta,
                    batches=batches,
                    seed=_child(root, H, 0),
                )
                row = {"policy": name, "mode": mode, "horizon": H}
                row["modes_coincide"] = policy.is_constant
                row.update({k: v for k, v in stats.to_dict().items() if k != "mean_grad"})
                if ref is not None:
                    row["bias"] = measure_bias(stats, ref).to_dict()
                    row["reference_std_error"] = ref.std_error
                    row["reference_method"] = ref.method
                rows.append(row)
                if progress is not None:
                    progress(f"H={H} {name} {mode}: v={stats.trace_variance:.3g}")
    return rows
