"""The ball throw as a closed loop (drake_abs.tasks.ball_throw): the release step and the policy's
derivatives against central differences, the free flight and landing through the ball's LCS, and
no model parameters."""

from __future__ import annotations

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs.tasks.ball_throw import ThrowPolicy, ThrowStepper, throw_objective


def test_release_step_and_its_jacobian():
    stepper = throw_objective(speed=3.0).stepper
    assert isinstance(stepper, ThrowStepper)
    x = np.array([[0.2, 1.0, 0.0, 0.0, 1.0]])
    step = stepper.step(x, np.array([[0.7]]))
    np.testing.assert_allclose(step.x_next[0], [0.2, 1.0, 3 * np.cos(0.7), 3 * np.sin(0.7), 0.0],
                               rtol=1e-15)  # fmt: skip
    fd_u = central_difference(lambda u: stepper.step(x, u[None], jacobians=False).x_next[0], [0.7])
    fd_x = central_difference(lambda y: stepper.step(y[None], np.array([[0.7]]),
                                                     jacobians=False).x_next[0], x[0])  # fmt: skip
    np.testing.assert_allclose(step.dx_du[0], fd_u, atol=1e-8)
    np.testing.assert_allclose(step.dx_dx[0][:, :4], fd_x[:, :4], atol=1e-8)
    with pytest.raises(ValueError, match="parameters"):
        stepper.step(x, np.array([[0.7]]), parameters=True)


def test_after_release_the_input_is_ignored_and_the_ball_lands():
    obj = throw_objective(horizon=150)
    x = np.array([[0.0, 1.0, 3 * np.cos(1.0), 3 * np.sin(1.0), 0.0]])
    a = obj.stepper.step(x, np.array([[0.3]]))
    b = obj.stepper.step(x, np.array([[-2.0]]))
    np.testing.assert_array_equal(a.x_next, b.x_next)
    assert np.all(a.dx_du == 0.0)
    r = obj.rollout(np.array([1.0]), np.zeros((1, 150, 1)), gradient=False)
    assert r.x[0, -1, 1] == pytest.approx(0.05, abs=1e-6)  # resting on the ground (radius)
    assert abs(r.x[0, -1, 2]) < 1e-6 and r.impulse[0].max() > 0  # it landed and stopped
    assert r.returns[0] == pytest.approx(-((r.x[0, -1, 0] - 1.5) ** 2), rel=1e-12)


def test_policy_derivatives():
    pol, theta = ThrowPolicy(), np.array([0.8])
    x = np.array([[0.1, 1.0, 0.0, 0.0, 1.0], [0.3, 0.5, 1.0, 2.0, 0.0]])
    du_dx, du_dth = pol.jacobians(theta, x)
    for m in range(2):
        fd = central_difference(lambda y, m=m: pol.act(theta, y[None])[0], x[m])
        np.testing.assert_allclose(du_dx[m], fd, atol=1e-9)
        np.testing.assert_allclose(du_dth[m], central_difference(
            lambda th, m=m: pol.act(th, x[m : m + 1])[0], theta), atol=1e-9)  # fmt: skip
    g_x, g_th = pol.vjp(theta, x, np.array([[2.0], [3.0]]))
    np.testing.assert_allclose(g_x, np.einsum("mu,mux->mx", [[2.0], [3.0]], du_dx))
    np.testing.assert_allclose(g_th, np.einsum("mu,mup->mp", [[2.0], [3.0]], du_dth))
