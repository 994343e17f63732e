"""The hopping ball (drake_abs.tasks.hopping_ball): the spring policy is the spring, the ball
hops (lands, leaves the ground, lands again), and a reward and start given replace the tracking
task's."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.contact.smoothing import Exact, Fixed
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.tasks.hopping_ball import SPRING, TIME_STEP, X0, Y_EQ, hopping_ball, spring_theta


def test_the_spring_policy_is_the_spring():
    obj = hopping_ball(Exact())
    x = np.array([[0.3, 0.25, 1.0, -2.0], [0.0, 0.05, 0.0, 0.0]])
    u = obj.policy.act(spring_theta(), x)
    np.testing.assert_allclose(u, np.column_stack([[0.0, 0.0], -SPRING * (x[:, 1] - Y_EQ)]),
                               rtol=1e-15, atol=1e-15)  # fmt: skip
    assert obj.stepper.gradient == "frozen" and obj.horizon == 200 and obj.sigma == 1.0
    np.testing.assert_array_equal(obj.x0, X0)
    assert obj.stepper.lcs.time_step == TIME_STEP


def test_the_ball_hops():
    obj = hopping_ball(Exact(), horizon=200)
    r = obj.rollout(spring_theta(), np.zeros((1, 200, 2)), gradient=False)
    touching = np.any(r.impulse[0] > 1e-9, axis=1)
    landings = np.flatnonzero(touching[1:] & ~touching[:-1]) + 1
    assert not touching[0] and landings.size >= 3  # dropped, it lands, leaves and lands again
    assert np.all(np.diff(landings) > 30)  # hops, not a bounce in place (about 0.6 s apart)
    assert np.all(r.x[0, :, 1] > -1e-6)  # never through the ground


def test_reward_and_start_can_be_replaced():
    reward = QuadraticReward(Q=np.eye(4), R=np.zeros((2, 2)), x_goal=np.zeros(4))
    obj = hopping_ball(Fixed(1e-2), "total", 10, 0.5, reward=reward, x0=(0.0, 0.3, 0.0, 0.0))
    assert obj.reward is reward and obj.stepper.gradient == "total" and obj.sigma == 0.5
    np.testing.assert_array_equal(obj.x0, [0.0, 0.3, 0.0, 0.0])
    with pytest.raises(ValueError):
        hopping_ball(Exact(), "sideways")
