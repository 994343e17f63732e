"""The estimators' unit of work (drake_abs.policy.rollouts): the seed tree gives every rollout the
same noise however the rollouts are split; jobs refuse bad ranges, keys and parameters by name;
a runner given as the default is used and removed again; a runner returning mismatched results
is an error, never a result."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs import Fixed, LcsStepper, point_mass_lcs
from drake_abs.policy.estimators import PolicyObjective, first_order
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.policy.rollouts import (
    LocalRunner,
    RolloutJob,
    default_runner,
    noise_key,
    rollout_noise,
    rollout_stats,
    use_runner,
)


def _objective():
    lcs = point_mass_lcs(2, time_step=0.02)
    reward = QuadraticReward(np.eye(4), 0.01 * np.eye(2), np.array([1.0, 0.2, 0.0, 0.0]))
    return PolicyObjective(LcsStepper(lcs, Fixed(1e-3)), LinearPolicy(4, 2), reward,
                           np.array([0.0, 0.3, 1.0, -1.0]), 12, 0.3)  # fmt: skip


def test_a_rollouts_noise_does_not_depend_on_the_split():
    whole = rollout_noise(7, 0, 10, 5, 2)
    parts = np.concatenate([rollout_noise(7, a, b, 5, 2) for a, b in ((0, 3), (3, 4), (4, 10))])
    np.testing.assert_array_equal(parts, whole)
    assert not np.array_equal(rollout_noise(8, 0, 10, 5, 2), whole)  # another stream
    assert whole.shape == (10, 5, 2)


def test_pieces_of_a_job_give_the_whole_jobs_rollouts():
    obj = _objective()
    theta = 0.1 * np.ones(obj.policy.n_params)
    whole = rollout_stats(obj, RolloutJob(theta, 5, 0, 6), gradient=True, score=True)
    parts = [rollout_stats(obj, j, gradient=True, score=True)
             for j in RolloutJob(theta, 5, 0, 6).split(4)]  # fmt: skip
    # different batch compositions: equal to rounding, not bit for bit
    for name in ("returns", "grad", "score"):
        np.testing.assert_allclose(np.concatenate([getattr(p, name) for p in parts]),
                                   getattr(whole, name), rtol=1e-12, atol=1e-14)  # fmt: skip


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((np.zeros(3), 1, 2, 2), "start < stop"),
        ((np.zeros(3), 1, -1, 2), "start < stop"),
        ((np.zeros(3), -1, 0, 2), "key"),
        ((np.zeros(3), 1.5, 0, 2), "key"),
        ((np.array([0.0, np.nan, 1.0]), 1, 0, 2), "theta"),
        ((np.zeros(3), 1, 0.0, 2), "start"),
    ],
)
def test_bad_jobs_are_refused_by_name(args, match):
    with pytest.raises(ValueError, match=match):
        RolloutJob(*args)


def test_noise_keys_need_a_generator_and_are_seeded():
    with pytest.raises(ValueError, match="rng"):
        noise_key(0)
    assert noise_key(np.random.default_rng(3)) == noise_key(np.random.default_rng(3))


class _Counting(LocalRunner):
    def __init__(self):
        self.calls = 0

    def run(self, objective, jobs, *, gradient, score):
        self.calls += 1
        return super().run(objective, jobs, gradient=gradient, score=score)


class _Short(LocalRunner):
    def run(self, objective, jobs, *, gradient, score):
        return super().run(objective, jobs, gradient=gradient, score=score)[:-1]


def test_the_default_runner_is_used_and_removed_again():
    obj = _objective()
    counting = _Counting()
    assert isinstance(default_runner(), LocalRunner)
    with use_runner(counting):
        first_order(obj, np.zeros(10), np.random.default_rng(0), 4)
    assert counting.calls == 1 and default_runner() is not counting
    with pytest.raises(ValueError, match="runner"):
        use_runner(object())
    with pytest.raises(RuntimeError, match="do not match"):
        first_order(obj, np.zeros(10), np.random.default_rng(0), 4, runner=_Short())
