"""ZeroOrderHold: an input held over several steps of another stepper, with chained Jacobians.

Checked against the closed form for a linear model (A^n, sum A^k B), against the inner stepper
called by hand, and against central differences through a contact scene (the Hopper's foot on
the ground, several substeps)."""

from __future__ import annotations

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs.engine import LinearStepper, ZeroOrderHold, rollout


def test_linear_model_matches_the_closed_form():
    rng = np.random.default_rng(0)
    A, B = 0.3 * rng.standard_normal((4, 4)) + np.eye(4), rng.standard_normal((4, 2))
    x, u = rng.standard_normal((3, 4)), rng.standard_normal((3, 2))
    s = ZeroOrderHold(LinearStepper(A, B), 3).step(x, u)
    A3 = A @ A @ A
    want_u = (A @ A + A + np.eye(4)) @ B
    np.testing.assert_allclose(s.x_next, x @ A3.T + u @ want_u.T, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(s.dx_dx, np.broadcast_to(A3, (3, 4, 4)), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(s.dx_du, np.broadcast_to(want_u, (3, 4, 2)), rtol=1e-13)
    assert s.converged.all()


def test_one_substep_is_the_inner_step():
    lin = LinearStepper(np.eye(2), np.ones((2, 1)))
    x, u = np.zeros((1, 2)), np.ones((1, 1))
    assert ZeroOrderHold(lin, 1).step(x, u).x_next.tolist() == lin.step(x, u).x_next.tolist()


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_substeps_must_be_a_positive_integer(bad):
    with pytest.raises(ValueError, match="substeps must be an integer >= 1"):
        ZeroOrderHold(LinearStepper(np.eye(1), np.ones((1, 1))), bad)


@pytest.fixture(scope="module")
def hopper():
    from drake_abs.multibody import build_scene_model

    model = build_scene_model("gym_hopper")
    return model, model.stepper()


def test_contact_scene_substeps_are_the_inner_steps_and_their_jacobians(hopper):
    model, inner = hopper
    hold = ZeroOrderHold(inner, 3)
    x = model.x0.copy()
    x[1] -= 0.04  # the foot on the ground
    u = np.array([20.0, -30.0, 10.0])
    s = hold.step(x[None], u[None])
    by_hand = x[None]
    impulse = 0.0
    for _ in range(3):
        step = inner.step(by_hand, u[None])
        by_hand, impulse = step.x_next, impulse + step.impulse
    np.testing.assert_array_equal(s.x_next, by_hand)
    np.testing.assert_allclose(s.impulse, impulse, rtol=1e-14, atol=0)
    assert s.converged.all() and impulse.sum() > 0
    assert s.dimpulse_dx is None and s.dmu_dx is None  # not chained
    fd_x = central_difference(lambda z: hold.step(z[None], u[None], jacobians=False).x_next[0], x)
    fd_u = central_difference(lambda w: hold.step(x[None], w[None], jacobians=False).x_next[0], u)
    np.testing.assert_allclose(s.dx_dx[0], fd_x, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(s.dx_du[0], fd_u, rtol=1e-5, atol=1e-7)


def test_an_unconverged_substep_flags_the_period():
    class Flaky(LinearStepper):
        calls = 0

        def step(self, x, u, **kw):
            s = super().step(x, u, **kw)
            Flaky.calls += 1
            bad = np.zeros(s.x_next.shape[0], bool)
            bad[0] = Flaky.calls == 2  # the second substep of the first row
            return type(s)(**{**s.__dict__, "converged": s.converged & ~bad})

    s = ZeroOrderHold(Flaky(np.eye(1), np.ones((1, 1))), 3).step(np.zeros((2, 1)), np.ones((2, 1)))
    assert s.converged.tolist() == [False, True]


def test_policy_gradient_through_held_inputs_matches_central_differences():
    rng = np.random.default_rng(3)
    A = np.array([[1.0, 0.1], [-0.2, 0.95]])
    B = np.array([[0.0], [0.1]])
    hold = ZeroOrderHold(LinearStepper(A, B), 4)

    class Reward:
        def stage(self, x, u):
            return -np.sum(x * x, 1) - np.sum(u * u, 1), -2 * x, -2 * u

        def terminal(self, x):
            return -np.sum(x * x, 1), -2 * x

    from drake_abs.policy.policies import LinearPolicy

    policy = LinearPolicy(2, 1)
    theta = 0.1 * rng.standard_normal(policy.n_params)
    x0, noise = rng.standard_normal((2, 2)), rng.standard_normal((2, 5, 1))
    run = rollout(hold, policy, theta, x0, noise, Reward(), sigma=0.1)
    fd = central_difference(
        lambda th: (
            rollout(hold, policy, th, x0, noise, Reward(), sigma=0.1, gradient=False).returns
        ),
        theta,
    )
    np.testing.assert_allclose(run.grad, fd, rtol=1e-6, atol=1e-8)
