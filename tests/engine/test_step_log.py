"""StepLog keeps what a stepper's steps carry beyond the trajectory: the wrapped stepper gives
the same rollout, and the kept fields are the inner steps' own, in time order."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.contact.lcs import LcsStepper
from drake_abs.engine import LinearStepper, open_loop
from drake_abs.engine.step_log import StepLog
from drake_abs.tasks.point_mass import point_mass_lcs


def test_the_log_leaves_the_rollout_unchanged_and_keeps_each_step():
    stepper = LcsStepper(point_mass_lcs(1))
    x0 = np.array([[0.3, -1.0], [0.1, 0.5]])
    u = np.linspace(-1.0, 1.0, 8)[:, None]
    plain = open_loop(stepper, x0, u)
    log = StepLog(stepper, ("iterations", "impulse"))
    logged = open_loop(log, x0, u)
    np.testing.assert_array_equal(logged.x, plain.x)
    np.testing.assert_array_equal(logged.dxH_du, plain.dxH_du)
    impulse = log.stacked("impulse")
    assert impulse.shape == plain.impulse.shape == (2, 8, plain.impulse.shape[-1])
    np.testing.assert_array_equal(impulse, plain.impulse)
    iterations = log.stacked("iterations")
    assert iterations.shape == (2, 8) and (iterations > 0).any()  # the ball lands: LCPs solved


def test_a_field_the_steps_do_not_carry_or_did_not_keep_is_refused_by_name():
    log = StepLog(LinearStepper(np.eye(2), np.ones((2, 1))))
    with pytest.raises(ValueError, match="no steps"):
        log.stacked("limit_impulse")
    open_loop(log, np.zeros(2), np.ones((3, 1)), jacobians=False)
    with pytest.raises(ValueError, match="limit_impulse"):
        log.stacked("limit_impulse")  # a linear model has no joint limits
    with pytest.raises(ValueError, match="kept fields"):
        log.stacked("impulse")
    with pytest.raises(ValueError, match="names"):
        StepLog(LinearStepper(np.eye(2), np.ones((2, 1))), ("x_nxt",))
    with pytest.raises(TypeError, match="stepper"):
        StepLog(object())
