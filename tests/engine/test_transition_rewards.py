"""Rewards of transitions (x_t, u_t, x_{t+1}) and episodes that end (gymnasium's locomotion
rewards and termination) in the one engine: a transition reward that ignores x_{t+1} equals the
stage reward; one that uses x_{t+1} (forward velocity from positions) is differentiated correctly
(central differences with fixed noise); an episode ends with the step that reached a terminal
state, the later rewards count nothing, the ended rollout stays put and its later steps'
convergence does not drop it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs import ContactAware, LcsStepper, point_mass_lcs, rollout
from drake_abs.policy.policies import LinearPolicy
from drake_abs.policy.rewards import QuadraticReward

NX, NU, DT = 4, 2, 0.02


def _ball():
    lcs = point_mass_lcs(2, time_step=DT)
    return LcsStepper(lcs, ContactAware(1e-2, 0.05)), np.array([0.0, 0.3, 1.0, -1.0])


class AsTransition:
    """A stage reward presented as a reward of the transition (x_next unused)."""

    def __init__(self, inner):
        self.inner = inner

    def transition(self, x, u, x_next):
        r, rx, ru = self.inner.stage(x, u)
        return r, rx, ru, np.zeros_like(x_next)

    def terminal(self, x):
        return self.inner.terminal(x)


class Forward:
    """gymnasium-style: forward velocity (p_x after - p_x before) / dt, minus a control cost,
    plus a healthy reward 1 while the ball is below ``ceiling`` after the step; with
    ``ceiling`` the episode ends when it is above (``terminated``)."""

    def __init__(self, ceiling=None, w_ctrl=0.1):
        self.ceiling, self.w_ctrl = ceiling, w_ctrl

    def _healthy(self, x_next):
        if self.ceiling is None:
            return np.ones(x_next.shape[0])
        return (x_next[:, 1] <= self.ceiling).astype(float)

    def transition(self, x, u, x_next):
        r = (x_next[:, 0] - x[:, 0]) / DT - self.w_ctrl * (u**2).sum(axis=1)
        r = r + self._healthy(x_next)
        dx, dxn = np.zeros_like(x), np.zeros_like(x_next)
        dx[:, 0], dxn[:, 0] = -1.0 / DT, 1.0 / DT
        return r, dx, -2 * self.w_ctrl * u, dxn

    def terminal(self, x):
        return np.zeros(x.shape[0]), np.zeros_like(x)

    def terminated(self, x_next):
        return self._healthy(x_next) == 0.0


def _noise(M, H, seed=0):
    return np.random.default_rng(seed).standard_normal((M, H, NU))


def test_a_transition_reward_without_x_next_equals_the_stage_reward(rng):
    stepper, x0 = _ball()
    stage = QuadraticReward(np.diag([0.0, 1.0, 0.0, 0.01]), 0.01 * np.eye(NU),
                            np.array([1.0, 0.2, 0.0, 0.0]), Q_final=np.eye(NX))  # fmt: skip
    theta = 0.1 * rng.standard_normal(LinearPolicy(NX, NU).n_params)
    noise = _noise(5, 30)
    a = rollout(stepper, LinearPolicy(NX, NU), theta, x0, noise, stage, sigma=0.3)
    b = rollout(stepper, LinearPolicy(NX, NU), theta, x0, noise, AsTransition(stage), sigma=0.3)
    np.testing.assert_allclose(b.returns, a.returns, rtol=1e-13)
    np.testing.assert_allclose(b.grad, a.grad, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(b.grad_x0, a.grad_x0, rtol=1e-12, atol=1e-14)
    assert b.alive.all()


def test_a_reward_of_x_next_is_differentiated_exactly(rng):
    stepper, x0 = _ball()
    policy, reward = LinearPolicy(NX, NU), Forward()
    theta = 0.1 * rng.standard_normal(policy.n_params)
    noise = _noise(3, 25)
    r = rollout(stepper, policy, theta, x0, noise, reward, sigma=0.3)
    # the forward term telescopes: sum_t (p_{t+1} - p_t) / dt = (p_H - p_0) / dt
    expected = ((r.x[:, -1, 0] - r.x[:, 0, 0]) / DT - 0.1 * (r.u**2).sum(axis=(1, 2))
                + r.u.shape[1])  # fmt: skip
    np.testing.assert_allclose(r.returns, expected, rtol=1e-12)
    for m in range(3):

        def ret(th, m=m):
            return rollout(stepper, policy, th, x0, noise[m : m + 1], reward, sigma=0.3,
                           gradient=False).returns[0]  # fmt: skip

        fd = central_difference(ret, theta)
        np.testing.assert_allclose(r.grad[m], fd, rtol=1e-5, atol=1e-6)
        fd_x0 = central_difference(
            lambda y, m=m: rollout(stepper, policy, theta, y, noise[m : m + 1], reward,
                                   sigma=0.3, gradient=False).returns[0], x0)  # fmt: skip
        np.testing.assert_allclose(r.grad_x0[m], fd_x0, rtol=1e-5, atol=1e-6)


def test_an_episode_ends_with_the_step_that_reached_a_terminal_state(rng):
    stepper, x0 = _ball()
    policy = LinearPolicy(NX, NU)
    theta = np.zeros(policy.n_params)
    theta[-1] = 20.0  # pushes up: u_z = 20 N (+ noise) against gravity; it rises past 0.45 m
    reward = Forward(ceiling=0.45)
    noise = _noise(4, 40)
    r = rollout(stepper, policy, theta, x0, noise, reward, sigma=0.3)
    ended = ~r.alive.all(axis=1)
    assert ended.any() and r.alive[:, 0].all()
    free = rollout(stepper, policy, theta, x0, noise, Forward(), sigma=0.3, gradient=False)
    for m in range(4):
        T = int(r.alive[m].sum())  # steps that counted
        if T < 40:  # ended at step T - 1: x_T is above the ceiling, the earlier ones are not
            assert r.x[m, T, 1] > 0.45 and np.all(r.x[m, 1:T, 1] <= 0.45)
            np.testing.assert_array_equal(
                r.x[m, T + 1 :], np.broadcast_to(r.x[m, T], r.x[m, T + 1 :].shape)
            )
        # the return is the free run's per-step rewards summed over the steps that counted
        x, u = free.x[m], free.u[m]
        steps = (x[1:, 0] - x[:-1, 0]) / DT - 0.1 * (u**2).sum(axis=1) + (x[1:, 1] <= 0.45)
        assert r.returns[m] == pytest.approx(steps[:T].sum(), rel=1e-12)
    # the gradient of the ended episodes: central differences (the end step does not move)
    for m in np.flatnonzero(ended)[:2]:

        def ret(th, m=m):
            return rollout(stepper, policy, th, x0, noise[m : m + 1], reward, sigma=0.3,
                           gradient=False).returns[0]  # fmt: skip

        np.testing.assert_allclose(r.grad[m], central_difference(ret, theta, eps=1e-7),
                                   rtol=1e-5, atol=1e-5)  # fmt: skip


class _FailsWhenHigh:
    """Marks unconverged every step that starts above 0.6 m (after the episodes ended)."""

    def __init__(self, inner):
        self.inner = inner
        self.parameter_names = inner.parameter_names

    def step(self, x, u, *, jacobians=True, parameters=False):
        s = self.inner.step(x, u, jacobians=jacobians, parameters=parameters)
        return replace(s, converged=s.converged & ~(np.asarray(x)[:, 1] > 0.6))


def test_steps_after_the_end_do_not_drop_the_rollout():
    stepper, x0 = _ball()
    policy = LinearPolicy(NX, NU)
    theta = np.zeros(policy.n_params)
    theta[-1] = 20.0
    noise = _noise(3, 40)
    flaky = _FailsWhenHigh(stepper)
    # without an end, the high steps are unconverged and the rollouts are dropped
    with pytest.warns(UserWarning, match="dropped"):
        free = rollout(flaky, policy, theta, x0, noise, Forward(), sigma=0.3)
    assert not free.used.any()
    # ending the episode at 0.45 m: the ended rollouts stay below 0.6 m and count
    ended = rollout(flaky, policy, theta, x0, noise, Forward(ceiling=0.45), sigma=0.3)
    assert ended.used.all() and np.isfinite(ended.grad).all()
    assert (~ended.alive).any()
