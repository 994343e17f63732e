"""The baselines on a task with a reward of transitions and episodes that end (gymnasium's
Hopper on our plant): PIPPS with all weight on the pathwise part is FOPG exactly (both read the
engine's one forward pass); ARS V2-t and the MBPO-style loop count only the steps that counted
and learn from those transitions only."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.contact.smoothing import ContactAware
from drake_abs.policy.ars_v2 import NormalizedLinearPolicy, ars_v2_train
from drake_abs.policy.estimators import first_order
from drake_abs.policy.mbpo import MbpoConfig, mbpo_train
from drake_abs.policy.pipps import pipps, pipps_detailed
from drake_abs.policy.policies import LinearPolicy
from drake_abs.tasks.locomotion import locomotion_task


@pytest.fixture(scope="module")
def hopper():
    return locomotion_task("hopper", smoothing=ContactAware(1e-2, 0.05))


def _falling_objective(hopper, horizon=40):
    """A policy that drives the hopper over: some episodes end within the horizon."""
    obj = hopper.objective(LinearPolicy(hopper.n_obs, hopper.nu), horizon, 0.3)
    theta = np.zeros(obj.policy.n_params)
    theta[-3:] = 1.0  # full torque on every joint
    return obj, theta


def test_pipps_all_pathwise_is_fopg_on_a_task_that_ends(hopper):
    obj, theta = _falling_objective(hopper)
    fo = first_order(obj, theta, np.random.default_rng(3), 6)
    pp = pipps(obj, theta, np.random.default_rng(3), 6, rp_weight=1.0)
    assert 0 < fo.env_steps < 6 * 40  # episodes ended: the case this test is about
    assert pp.env_steps == fo.env_steps
    np.testing.assert_allclose(pp.grad, fo.grad, rtol=1e-10, atol=1e-12 * np.abs(fo.grad).max())
    assert pp.value == pytest.approx(fo.value, rel=1e-12)
    mixed = pipps_detailed(obj, theta, np.random.default_rng(3), 6)
    assert np.isfinite(mixed.estimate.grad).all()


def test_ars_counts_only_the_steps_that_counted(hopper):
    obj, theta = _falling_objective(hopper, horizon=30)
    policy = NormalizedLinearPolicy(hopper.nx, hopper.nu)
    run = ars_v2_train(
        obj.__class__(obj.stepper, policy, obj.reward, obj.x0, 30, 0.0), np.zeros(policy.n_params),
        iterations=2, directions=2, top=1, step_size=0.02, noise=0.5,
        rng=np.random.default_rng(0),
    )  # fmt: skip
    steps = [r["env_steps"] for r in run.rows if "env_steps" in r]
    assert all(0 < s <= 2 * 2 * 30 for s in steps)
    assert min(steps) < 2 * 2 * 30  # episodes ended: fewer steps than rollouts x horizon
    assert np.isfinite(run.theta).all()


def test_mbpo_learns_from_the_transitions_before_the_end(hopper):
    obj, theta = _falling_objective(hopper, horizon=30)
    config = MbpoConfig(iterations=1, real_rollouts=4, ensemble_size=2, hidden=(8,),
                        model_epochs=2, branches=8, policy_updates=1, rollout_length=3)  # fmt: skip
    run = mbpo_train(obj, theta, config, np.random.default_rng(0))
    first = run.rows[0]
    assert 0 < first["real_steps"] < 4 * 30  # episodes ended early
    assert first["transitions"] == first["real_steps"]
