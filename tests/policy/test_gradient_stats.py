"""Variance and bias measurement of gradient estimators (drake_abs.policy.gradient_stats).

Checks: the trace variance and its standard error against a linear-Gaussian problem whose FOPG
variance is known in closed form; the reference gradient against the analytic gradient there;
an unbiased estimator's bias comes out unresolved, a deliberately biased one (BS with a large mu
near contact) clearly resolved; seeding; common random numbers across policies in a sweep; bad
input named in the errors.
"""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs import Exact, Fixed
from drake_abs.contact.lcs import LCS, LcsStepper
from drake_abs.policy.estimators import GradientEstimate, PolicyObjective, first_order
from drake_abs.policy.gradient_stats import (
    fopg,
    measure_bias,
    measure_variance,
    reference_gradient,
    trace_variance,
    variance_bias_sweep,
)
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.tasks.hopping_ball import hopping_ball, spring_theta

C0, GOAL, Q, SIGMA = 0.5, 2.0, 3.0, 0.7  # x0, target, terminal weight, action noise


def linear_gaussian(theta_smoothing=None) -> PolicyObjective:
    """x1 = x0 + u, u = K x0 + k + sigma xi, R = -Q (x1 - GOAL)^2 (one step, no contact: the
    LCS's only contact is 1 m away and does not act on x). Per rollout
    dR/d(K, k) = -2 Q (x1 - GOAL) (x0, 1), so the FOPG trace variance from M rollouts is
    4 Q^2 sigma^2 (1 + x0^2) / M and E grad = -2 Q (x0 + K x0 + k - GOAL) (x0, 1)."""
    lcs = LCS(A=[[1.0]], B=[[1.0]], C=[[0.0]], c=[0.0], D=[[0.0]], E=[[0.0]], F=[[1.0]], d=[1.0])
    reward = QuadraticReward(
        Q=np.zeros((1, 1)), R=np.zeros((1, 1)), x_goal=np.array([GOAL]), Q_final=Q * np.eye(1)
    )
    stepper = LcsStepper(lcs, theta_smoothing or Exact())
    return PolicyObjective(stepper, LinearPolicy(1, 1), reward, np.array([C0]), 1, SIGMA)


THETA = np.array([0.3, -0.2])  # (K, k)


def analytic_gradient(theta=THETA) -> np.ndarray:
    mean_x1 = C0 + theta[0] * C0 + theta[1]
    return -2 * Q * (mean_x1 - GOAL) * np.array([C0, 1.0])


def test_trace_variance_matches_numpy():
    g = np.random.default_rng(0).standard_normal((50, 3)) * [1.0, 2.0, 3.0]
    v, se = trace_variance(g)
    assert v == pytest.approx(np.var(g, axis=0, ddof=1).sum(), rel=1e-12)
    assert 0 < se < v


def test_variance_matches_the_closed_form_of_a_linear_gaussian_problem():
    obj = linear_gaussian()
    M, K = 8, 400
    stats = measure_variance(lambda th, rng: first_order(obj, th, rng, M), THETA, batches=K, seed=3)
    per_rollout = np.array([4 * Q**2 * SIGMA**2 * C0**2, 4 * Q**2 * SIGMA**2])  # diag cov
    v_true = per_rollout.sum() / M
    assert abs(stats.trace_variance - v_true) < 4 * stats.trace_variance_se
    assert stats.trace_variance == pytest.approx(v_true, rel=0.2)
    # the standard error against the Gaussian value sqrt(2 tr(Sigma^2) / (K - 1))
    se_true = np.sqrt(2 * np.sum((per_rollout / M) ** 2) / (K - 1))
    assert stats.trace_variance_se == pytest.approx(se_true, rel=0.3)
    # the mean is unbiased within its own error
    assert np.linalg.norm(stats.mean_grad - analytic_gradient()) < 4 * stats.mean_grad_se
    assert stats.variance_seconds == pytest.approx(
        stats.trace_variance * stats.seconds_per_estimate
    )
    assert stats.rollouts_per_estimate == M and stats.steps == M * K
    assert 0 < stats.largest_batch_share < 0.05  # Gaussian: no batch dominates


def test_reference_is_unbiased_and_consistent_on_the_smooth_problem():
    ref = reference_gradient(linear_gaussian(), THETA, samples=4096, batches=16, seed=1)
    assert ref.method == "combined" and ref.consistent
    # the combined error is smaller than either estimator's alone
    assert ref.std_error < min(ref.first_order.mean_grad_se, ref.zeroth_order.mean_grad_se)
    assert np.linalg.norm(ref.grad - analytic_gradient()) < 4 * ref.std_error
    # FOPG on the same (smooth, exact) model: no bias to resolve
    obj = linear_gaussian()
    est = measure_variance(lambda th, rng: first_order(obj, th, rng, 32), THETA, batches=16, seed=2)
    b = measure_bias(est, ref)
    assert not b.resolved and b.bias is None
    assert b.distance < 2 * b.noise


def test_bias_near_contact_is_resolved_for_large_mu_and_much_smaller_for_exact_fopg():
    """BS with mu = 0.1 near contact is clearly biased. Hard-contact FOPG is unbiased in
    expectation (the step is Lipschitz) but heavy tailed, so at this sample size its measured
    distance need not be below the noise floor; it must be far below the BS bias though. With
    8 batches of 16 one seed in six drew a tail sample that put the exact distance at 0.17; with
    16 batches of 32 it stays at or below 0.043 for seeds 0-5 (BS: 0.43)."""
    theta, H = spring_theta(), 100
    ref = reference_gradient(
        hopping_ball(Exact(), horizon=H), theta, samples=512, batches=8, seed=0
    )
    out = {}
    for name, smoothing in {"exact": Exact(), "bs": Fixed(1e-1)}.items():
        obj = hopping_ball(smoothing, horizon=H)
        est = measure_variance(lambda th, rng, o=obj: first_order(o, th, rng, 32), theta,
                               batches=16, seed=4)  # fmt: skip
        out[name] = measure_bias(est, ref)
    assert out["exact"].distance < out["bs"].distance / 3
    assert out["bs"].resolved and out["bs"].bias > 10 * out["bs"].noise
    assert out["bs"].relative_bias > 0.3


def test_same_seed_same_numbers_and_seed_objects_are_not_consumed():
    obj = hopping_ball(Fixed(1e-4), horizon=30)
    est = fopg(4)

    def run(seed):
        return measure_variance(lambda th, rng: est(obj, th, rng), spring_theta(), batches=3,
                                seed=seed)  # fmt: skip

    a, b, c = run(7), run(7), run(8)
    np.testing.assert_array_equal(a.mean_grad, b.mean_grad)
    assert a.trace_variance == b.trace_variance
    assert not np.array_equal(a.mean_grad, c.mean_grad)
    seq = np.random.SeedSequence(11)
    np.testing.assert_array_equal(run(seq).mean_grad, run(seq).mean_grad)


def test_sweep_measures_constant_policies_once_and_uses_common_noise():
    rows = variance_bias_sweep(
        lambda pol, mode, H: hopping_ball(pol, mode, H),
        spring_theta(),
        {"exact": Exact(), "bs0": Fixed(0.0), "bs": Fixed(1e-2)},
        (20, 40),
        batches=3,
        seed=0,
        estimator=fopg(4),
        reference_samples=32,
        reference_batches=4,
    )
    assert len(rows) == 6 and all(r["mode"] == "frozen" and r["modes_coincide"] for r in rows)
    by = {(r["policy"], r["horizon"]): r for r in rows}
    # Fixed(0) is Exact: with common random numbers the two rows are identical
    for H in (20, 40):
        assert by[("exact", H)]["trace_variance"] == by[("bs0", H)]["trace_variance"]
        assert by[("bs", H)]["trace_variance"] != by[("exact", H)]["trace_variance"]
    for r in rows:
        assert np.isfinite(r["trace_variance"]) and r["bias"]["distance"] >= 0


def test_bad_input_is_named():
    obj = linear_gaussian()
    est = fopg(2)

    def f(th, rng):
        return est(obj, th, rng)

    with pytest.raises(ValueError, match="batches"):
        measure_variance(f, THETA, batches=1, seed=0)
    with pytest.raises(ValueError, match="seed"):
        measure_variance(f, THETA, batches=2, seed=-1)
    with pytest.raises(ValueError, match="method"):
        reference_gradient(obj, THETA, samples=64, seed=0, method="exact")
    with pytest.raises(ValueError, match="samples"):
        reference_gradient(obj, THETA, samples=10, batches=16, seed=0)
    with pytest.raises(ValueError, match="hard-contact"):
        reference_gradient(linear_gaussian(Fixed(1e-3)), THETA, samples=64, seed=0)
    with pytest.raises(ValueError, match="samples"):
        fopg(0)
    with pytest.raises(ValueError, match="grads"):
        trace_variance(np.ones((1, 3)))

    def bad(th, rng):
        return GradientEstimate(np.array([np.nan, 0.0]), 0.0, 1, 1, 0)

    with pytest.raises(FloatingPointError, match="estimate 0"):
        measure_variance(bad, THETA, batches=2, seed=0)
    a = measure_variance(f, THETA, batches=2, seed=0)
    ref = reference_gradient(obj, THETA, samples=8, batches=2, seed=0, method="first_order")
    short = type(ref)(ref.grad[:1], ref.std_error, ref.method, None, None, None, None)
    with pytest.raises(ValueError, match="same shape"):
        measure_bias(a, short)
    make = lambda pol, mode, H: obj  # noqa: E731
    with pytest.raises(ValueError, match="policies"):
        variance_bias_sweep(make, THETA, {}, (1,), batches=2, seed=0)
    with pytest.raises(ValueError, match="modes"):
        variance_bias_sweep(make, THETA, {"e": Exact()}, (1,), batches=2, seed=0, modes=("x",))
    with pytest.raises(ValueError, match="horizons"):
        variance_bias_sweep(make, THETA, {"e": Exact()}, (0,), batches=2, seed=0)


def test_exactness_and_constancy_are_asked_of_the_policy_not_its_class():
    """A wrapped policy (the box's per-contact rows) answers for the policy it wraps: the exact
    box objective is accepted as a reference, a smoothed one is refused."""
    from drake_abs.contact.smoothing import ContactAware
    from drake_abs.tasks.box_lcs import TranslatingBox

    box = TranslatingBox(mass=1.0, half_height=0.1, friction=0.5, time_step=0.01)
    assert box.smoothing().is_exact and box.smoothing().is_constant
    assert box.smoothing(Fixed(1e-3)).is_constant and not box.smoothing(Fixed(1e-3)).is_exact
    assert not box.smoothing(ContactAware(1e-3, 0.02)).is_constant
    policy = LinearPolicy(4, 1)
    reward = QuadraticReward(Q=np.eye(4), R=0.01 * np.eye(1), x_goal=np.zeros(4))
    x0 = box.resting_state()
    theta = np.zeros(policy.n_params)
    exact = PolicyObjective(box.stepper(), policy, reward, x0, 5, 1.0)
    ref = reference_gradient(exact, theta, samples=8, batches=2, seed=0)
    assert np.all(np.isfinite(ref.grad))
    smoothed = PolicyObjective(box.stepper(Fixed(1e-3)), policy, reward, x0, 5, 1.0)
    with pytest.raises(ValueError, match="hard-contact"):
        reference_gradient(smoothed, theta, samples=8, batches=2, seed=0)
