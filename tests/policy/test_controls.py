"""Scripted inputs (drake_abs.policy.controls): the seeded held random schedule is what its
docstring says (range, blocks, seed, a longer schedule continues a shorter one), and a control law
of (t, x) runs in the engine as a time-varying policy: equal to the open loop of the inputs it
produced, fed the step index and the batch of states, refused where gradients are asked for."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.contact.lcs import LcsStepper
from drake_abs.engine import open_loop, rollout
from drake_abs.policy.controls import TimeVaryingController, held_random_inputs
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.tasks.point_mass import point_mass_lcs


def test_held_random_inputs_are_seeded_blocks_in_range():
    u = held_random_inputs(23, 3, scale=0.7, hold=5, seed=4)
    assert u.shape == (23, 3) and np.abs(u).max() <= 0.7 and np.abs(u).max() > 0.3
    blocks = u[::5]
    np.testing.assert_array_equal(u, np.repeat(blocks, 5, axis=0)[:23])
    assert not np.any(blocks[1:] == blocks[:-1])  # a new draw every 5 steps
    np.testing.assert_array_equal(u, held_random_inputs(23, 3, scale=0.7, hold=5, seed=4))
    assert not np.array_equal(u, held_random_inputs(23, 3, scale=0.7, hold=5, seed=5))
    longer = held_random_inputs(1000, 3, scale=0.7, hold=5, seed=4)
    np.testing.assert_array_equal(longer[:23], u)  # a longer schedule continues a shorter one


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(steps=-1, nu=2), "steps"),
        (dict(steps=5, nu=0), "nu"),
        (dict(steps=5, nu=2, hold=0), "hold"),
        (dict(steps=5, nu=2, scale=float("nan")), "scale"),
        (dict(steps=5, nu=2, scale=-1.0), "scale"),
    ],
)
def test_held_random_inputs_refuse_bad_arguments_by_name(kwargs, match):
    with pytest.raises(ValueError, match=match):
        held_random_inputs(**kwargs)


def test_a_control_law_of_t_and_x_runs_in_the_engine_as_its_open_loop():
    stepper = LcsStepper(point_mass_lcs(1))
    seen = []

    def servo(t, x):  # feedback on the state plus a schedule of the step index
        seen.append((t, x.shape))
        return -2.0 * x[:, 1:2] + np.sin(0.3 * t)

    policy = TimeVaryingController(servo, 2, 1)
    x0 = np.array([[0.5, 0.0], [0.2, 1.0]])
    closed = rollout(stepper, policy, np.zeros(0), x0, np.zeros((2, 12, 1)), sigma=0.0,
                     gradient=False)  # fmt: skip
    assert seen == [(t, (2, 2)) for t in range(12)]
    np.testing.assert_array_equal(
        closed.u[:, :, 0], -2.0 * closed.x[:, :-1, 1] + np.sin(0.3 * np.arange(12))
    )
    replay = open_loop(stepper, x0, closed.u, jacobians=False)
    np.testing.assert_array_equal(closed.x, replay.x)
    assert closed.x[0, -1, 0] != closed.x[1, -1, 0]  # the rows are the batch's own


def test_one_input_for_the_batch_is_broadcast_and_a_wrong_shape_is_named():
    schedule = held_random_inputs(6, 1)
    policy = TimeVaryingController(lambda t, x: schedule[t], 2, 1)
    np.testing.assert_array_equal(
        policy.act(None, np.zeros((3, 2)), 4), np.tile(schedule[4], (3, 1))
    )
    with pytest.raises(ValueError, match="control"):
        TimeVaryingController(lambda t, x: np.zeros(2), 2, 1).act(None, np.zeros((3, 2)), 0)
    with pytest.raises(TypeError, match="control"):
        TimeVaryingController("not callable", 2, 1)
    with pytest.raises(ValueError, match="nx"):
        TimeVaryingController(lambda t, x: schedule[t], 0, 1)


def test_a_time_varying_controller_is_refused_where_gradients_are_asked_for():
    stepper = LcsStepper(point_mass_lcs(1))
    policy = TimeVaryingController(lambda t, x: np.zeros(1), 2, 1)
    reward = QuadraticReward(Q=np.eye(2), R=np.eye(1), x_goal=np.zeros(2))
    with pytest.raises(ValueError, match="time-varying"):
        rollout(stepper, policy, np.zeros(0), np.zeros(2), np.zeros((1, 5, 1)), reward)
