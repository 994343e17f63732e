"""Policies, the batched closed-loop rollout and its adjoint gradient, and the estimators.

Checks: policy vector-Jacobian products against their Jacobians and central differences; the
adjoint gradient of each rollout's return against central differences (fixed noise) and against
an independent forward-mode chain rule (paper 000 eq. 4.1); on a problem without contact, the
first- and zeroth-order estimators agree in expectation (both unbiased); seeding; bad input.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs import ContactAware, Fixed, point_mass_lcs
from drake_abs.contact.lcs import LcsStepper
from drake_abs.engine import rollout, rollout_memory_bytes
from drake_abs.policy.estimators import (
    PolicyObjective,
    alpha_order,
    ars,
    first_order,
    randomized_smoothing,
    zeroth_order,
)
from drake_abs.policy.policies import LinearPolicy, MLPPolicy
from drake_abs.policy.rewards import QuadraticReward
from drake_abs.policy.training import SGD, Adam, train

NX, NU = 4, 2  # the 2-D point mass: x = (p_x, p_z, v_x, v_z), u = force


def ball_task(smoothing, gradient="frozen", horizon=40, height=0.3):
    """A 2-D ball thrown at the ground: it bounces (inelastically) during the horizon."""
    lcs = point_mass_lcs(2, time_step=0.02)
    reward = QuadraticReward(
        Q=np.diag([0.0, 1.0, 0.0, 0.01]),
        R=0.01 * np.eye(NU),
        x_goal=np.array([1.0, 0.2, 0.0, 0.0]),
        Q_final=np.diag([10.0, 1.0, 0.0, 0.0]),
    )
    x0 = np.array([0.0, height, 1.0, -1.0])
    return LcsStepper(lcs, smoothing, gradient), reward, x0, horizon


@pytest.mark.parametrize("policy", [LinearPolicy(NX, NU), MLPPolicy(NX, NU, (8, 8))])
def test_policy_vjp_matches_jacobians_and_finite_differences(policy, rng):
    theta = 0.5 * rng.standard_normal(policy.n_params)
    x = rng.standard_normal((3, NX))
    du_dx, du_dth = policy.jacobians(theta, x)
    g = rng.standard_normal((3, NU))
    gx, gth = policy.vjp(theta, x, g)
    np.testing.assert_allclose(gx, np.einsum("mi,mij->mj", g, du_dx), atol=1e-12)
    np.testing.assert_allclose(gth, np.einsum("mi,mij->mj", g, du_dth), atol=1e-12)
    for m in range(3):
        fd_x = central_difference(lambda y, m=m: policy.act(theta, y[None])[0], x[m])
        fd_th = central_difference(lambda th, m=m: policy.act(th, x[m : m + 1])[0], theta)
        np.testing.assert_allclose(du_dx[m], fd_x, atol=1e-8)
        np.testing.assert_allclose(du_dth[m], fd_th, atol=1e-8)


def forward_mode_gradient(stepper, policy, theta, x0, noise, reward, sigma):
    """dJ/dtheta per rollout by forward accumulation of dx_t/dtheta (eq. 4.1)."""
    M, H, _ = noise.shape
    x = np.broadcast_to(x0, (M, NX)).copy()
    dx = np.zeros((M, NX, theta.size))
    g = np.zeros((M, theta.size))
    for t in range(H):
        du_dx, du_dth = policy.jacobians(theta, x)
        u = policy.act(theta, x) + sigma * noise[:, t]
        du = du_dx @ dx + du_dth
        _, dr_dx, dr_du = reward.stage(x, u)
        g += np.einsum("mi,mip->mp", dr_dx, dx) + np.einsum("mi,mip->mp", dr_du, du)
        s = stepper.step(x, u)
        dx = s.dx_dx @ dx + s.dx_du @ du
        x = s.x_next
    _, drT = reward.terminal(x)
    return g + np.einsum("mi,mip->mp", drT, dx)


@pytest.mark.parametrize(
    ("smoothing", "gradient"),
    [(Fixed(1e-2), "frozen"), (ContactAware(mu_max=1e-2, length=0.1), "total")],
)
@pytest.mark.parametrize("policy", [LinearPolicy(NX, NU), MLPPolicy(NX, NU, (8,))])
def test_adjoint_gradient_matches_forward_mode_and_finite_differences(
    smoothing, gradient, policy, rng
):
    stepper, reward, x0, H = ball_task(smoothing, gradient)
    theta = 0.1 * rng.standard_normal(policy.n_params)
    noise = rng.standard_normal((3, H, NU))
    r = rollout(stepper, policy, theta, x0, noise, reward, sigma=0.5)
    assert r.converged.all()
    assert r.x[:, :, 1].min() < 0.05  # the ball reaches the ground: contact is in the gradient
    fwd = forward_mode_gradient(stepper, policy, theta, x0, noise, reward, 0.5)
    np.testing.assert_allclose(r.grad, fwd, rtol=1e-9, atol=1e-9 * np.abs(fwd).max())
    for m in range(3):

        def J(th, m=m):
            one = rollout(
                stepper, policy, th, x0, noise[m : m + 1], reward, sigma=0.5, gradient=False
            )
            return one.returns[0]

        fd = central_difference(J, theta, eps=1e-6)
        np.testing.assert_allclose(r.grad[m], fd, rtol=1e-5, atol=1e-5 * np.abs(fd).max())
        fd_x0 = central_difference(
            lambda y, m=m: rollout(
                stepper, policy, theta, y, noise[m : m + 1], reward, sigma=0.5, gradient=False
            ).returns[0],
            x0,
            eps=1e-6,
        )
        np.testing.assert_allclose(r.grad_x0[m], fd_x0, rtol=1e-5, atol=1e-5 * np.abs(fd_x0).max())


def free_flight_objective(sigma=0.3):
    """No contact within the horizon (the ball starts 10 m up): J is smooth, FO is unbiased."""
    stepper, reward, _, _ = ball_task(Fixed(0.0))
    return PolicyObjective(
        stepper, LinearPolicy(NX, NU), reward, np.array([0.0, 10.0, 1.0, 0.0]), 10, sigma
    )


def test_first_and_zeroth_order_agree_in_expectation():
    obj = free_flight_objective()
    theta = np.full(obj.policy.n_params, 0.05)
    fo = first_order(obj, theta, np.random.default_rng(1), 4000)
    # the ZO estimate's spread, from independent batches
    zos = [zeroth_order(obj, theta, np.random.default_rng(10 + k), 4000).grad for k in range(8)]
    zo_mean = np.mean(zos, axis=0)
    zo_sem = np.std(zos, axis=0, ddof=1) / np.sqrt(len(zos))
    assert np.all(np.abs(zo_mean - fo.grad) <= 4 * zo_sem + 1e-3 * np.abs(fo.grad).max())
    # alpha-order interpolates: alpha = 1 is first order on the same draws
    a1 = alpha_order(obj, theta, np.random.default_rng(1), 4000, 1.0)
    np.testing.assert_allclose(a1.grad, fo.grad, rtol=1e-12)


def test_randomized_smoothing_and_ars_point_uphill_on_a_smooth_objective():
    obj = free_flight_objective(sigma=0.0)
    theta = np.zeros(obj.policy.n_params)
    exact = first_order(obj, theta, np.random.default_rng(0), 1).grad  # deterministic
    rs = randomized_smoothing(obj, theta, np.random.default_rng(2), 64, 1e-3).grad
    np.testing.assert_allclose(rs, exact, rtol=1e-2, atol=1e-3 * np.abs(exact).max())
    a = ars(obj, theta, np.random.default_rng(3), directions=64, step=1e-3).grad
    assert a @ exact > 0.5 * np.linalg.norm(a) * np.linalg.norm(exact)


def test_same_seed_same_numbers_and_memory_formula():
    stepper, reward, x0, _ = ball_task(Fixed(1e-3))
    obj = PolicyObjective(stepper, LinearPolicy(NX, NU), reward, x0, 20, 0.2)
    theta = np.full(obj.policy.n_params, 0.1)
    a = first_order(obj, theta, np.random.default_rng(7), 16)
    b = first_order(obj, theta, np.random.default_rng(7), 16)
    np.testing.assert_array_equal(a.grad, b.grad)
    assert a.rollouts == 16 and a.steps == 16 * 20 and a.unconverged == 0
    # M = 1024, H = 1000 for this 2-D ball: stated in the module docstring
    assert rollout_memory_bytes(1024, 1000, NX, NU) / 1e9 == pytest.approx(0.29, abs=0.01)


def test_bad_input_names_the_argument():
    stepper, reward, x0, H = ball_task(Fixed(1e-3))
    pol = LinearPolicy(NX, NU)
    theta = np.zeros(pol.n_params)
    with pytest.raises(ValueError, match="theta"):
        rollout(stepper, pol, theta[:-1], x0, np.zeros((2, H, NU)), reward)
    with pytest.raises(ValueError, match="noise"):
        rollout(stepper, pol, theta, x0, np.zeros((2, H)), reward)
    with pytest.raises(ValueError, match="x0"):
        rollout(stepper, pol, theta, np.zeros((3, NX)), np.zeros((2, H, NU)), reward)
    with pytest.raises(ValueError, match="sigma"):
        rollout(stepper, pol, theta, x0, np.zeros((2, H, NU)), reward, sigma=-1.0)
    with pytest.raises(ValueError, match="sigma > 0"):
        zeroth_order(PolicyObjective(stepper, pol, reward, x0, H, 0.0), theta,
                     np.random.default_rng(0), 4)  # fmt: skip
    with pytest.raises(ValueError, match="Q must be symmetric"):
        QuadraticReward(np.ones((NX, NX + 1)), np.eye(NU), np.zeros(NX))


def test_training_improves_the_return_and_logs_every_iteration(tmp_path):
    """Hold the ball at 10 m (against gravity) while it drifts to x = 0.2 m: no contact."""
    base = free_flight_objective(sigma=0.1)
    reward = QuadraticReward(
        Q=np.diag([0.0, 10.0, 0.0, 0.1]), R=1e-3 * np.eye(NU),
        x_goal=np.array([0.2, 10.0, 0.0, 0.0]), Q_final=np.diag([100.0, 10.0, 1.0, 1.0]),
    )  # fmt: skip
    obj = PolicyObjective(base.stepper, base.policy, reward, base.x0, 20, 0.1)
    theta0 = np.zeros(obj.policy.n_params)

    def evaluate(theta):  # the return of the noise-free policy
        noise = np.zeros((1, obj.horizon, NU))
        return float(obj.rollout(theta, noise, gradient=False).returns[0])

    runs = [
        train(lambda th, rng: first_order(obj, th, rng, 16), theta0, Adam(lr=0.05), 30,
              seed=3, evaluate=evaluate, log_dir=tmp_path / str(k), name="fo", progress=False)
        for k in range(2)
    ]  # fmt: skip
    rows = runs[0].rows
    assert rows[-1]["eval_return"] > rows[0]["eval_return"] + 0.5 * abs(rows[0]["eval_return"])
    assert len(rows) == 31 and all(r["rollouts"] == 16 for r in rows[:-1])
    np.testing.assert_array_equal(runs[0].theta, runs[1].theta)  # the same seed
    logged = json.loads((tmp_path / "0" / "fo.json").read_text())
    assert logged["seed"] == 3 and logged["config"]["optimizer"]["kind"] == "Adam"
    assert (tmp_path / "0" / "fo.csv").read_text().count("\n") == 32  # header + 31 rows
    sgd = train(lambda th, rng: first_order(obj, th, rng, 16), theta0, SGD(lr=1e-3), 5,
                seed=3, progress=False)  # fmt: skip
    assert np.all(np.isfinite(sgd.theta)) and not np.array_equal(sgd.theta, theta0)


class _Corrupting:
    """Wraps a stepper: rollouts in ``bad`` report unconverged steps from step ``t_bad`` on and
    return wrong (scaled) Jacobians there, as a solve stopped early does."""

    def __init__(self, inner, bad, t_bad=3):
        self.inner, self.bad, self.t_bad, self.t = inner, np.asarray(bad), t_bad, 0
        self.parameter_names = ()

    def step(self, x, u, *, jacobians=True, parameters=False):
        from dataclasses import replace

        r = self.inner.step(x, u, jacobians=jacobians, parameters=parameters)
        if self.t >= self.t_bad:
            conv = r.converged.copy()
            conv[self.bad] = False
            r = replace(r, converged=conv)
            if jacobians:
                dx = r.dx_dx.copy()
                dx[self.bad] *= 1.4
                r = replace(r, dx_dx=dx)
        self.t += 1
        return r


def _objective(stepper, on_unconverged):
    _, reward, x0, horizon = ball_task(Fixed(1e-3), "total", horizon=12)
    return PolicyObjective(stepper, LinearPolicy(NX, NU), reward, x0, horizon, 0.3, on_unconverged)


def test_unconverged_rollouts_are_dropped_by_default_flagged_or_raised(rng):
    from drake_abs.contact.unconverged import UnconvergedStepError, UnconvergedStepWarning

    inner = ball_task(Fixed(1e-3), "total", horizon=12)[0]
    theta = 0.1 * rng.standard_normal(LinearPolicy(NX, NU).n_params)
    M, bad = 8, [1, 5]
    clean = first_order(_objective(inner, "drop"), theta, np.random.default_rng(3), M)
    assert clean.dropped == 0 and clean.unconverged == 0
    # the per-rollout gradients of the clean run, to average over the kept ones by hand
    obj = _objective(inner, "drop")
    per = obj.rollout(theta, obj.noise(np.random.default_rng(3), M))
    keep = np.setdiff1d(np.arange(M), bad)

    assert PolicyObjective.__dataclass_fields__["on_unconverged"].default == "drop"
    with pytest.warns(UnconvergedStepWarning, match="2 of 8 rollouts"):
        dropped = first_order(_objective(_Corrupting(inner, bad), "drop"), theta,
                              np.random.default_rng(3), M)  # fmt: skip
    assert dropped.dropped == 2 and dropped.unconverged == 2 * 9 and dropped.rollouts == M
    np.testing.assert_allclose(dropped.grad, per.grad[keep].mean(axis=0), rtol=1e-12)
    assert dropped.value == pytest.approx(per.returns[keep].mean(), rel=1e-12)

    with pytest.warns(UnconvergedStepWarning, match="kept"):
        flagged = first_order(_objective(_Corrupting(inner, bad), "flag"), theta,
                              np.random.default_rng(3), M)  # fmt: skip
    assert flagged.dropped == 0 and flagged.unconverged == 18
    assert not np.allclose(flagged.grad, clean.grad)  # the wrong Jacobians were used, visibly

    with pytest.raises(UnconvergedStepError, match="2 of 8"):
        first_order(_objective(_Corrupting(inner, bad), "raise"), theta,
                    np.random.default_rng(3), M)  # fmt: skip
    with pytest.raises(ValueError, match="on_unconverged"):
        _objective(inner, "ignore")


def test_dropped_rollouts_carry_nan_gradients_and_every_estimator_honours_the_mask(rng):
    from drake_abs.contact.unconverged import UnconvergedStepError, UnconvergedStepWarning

    inner = ball_task(Fixed(1e-3), "total", horizon=12)[0]
    theta = 0.1 * rng.standard_normal(LinearPolicy(NX, NU).n_params)
    obj = _objective(_Corrupting(inner, [0]), "drop")
    with pytest.warns(UnconvergedStepWarning):
        r = obj.rollout(theta, obj.noise(np.random.default_rng(0), 4))
    assert r.dropped == 1 and not r.used[0] and r.used[1:].all()
    assert np.isnan(r.grad[0]).all() and np.isfinite(r.grad[1:]).all()
    assert np.isnan(r.returns[0]) and np.isfinite(r.returns[1:]).all()
    with pytest.warns(UnconvergedStepWarning):
        for est in (
            zeroth_order(_objective(_Corrupting(inner, [0]), "drop"), theta, rng, 4),
            alpha_order(_objective(_Corrupting(inner, [0]), "drop"), theta, rng, 4, 0.5),
        ):
            assert est.dropped == 1 and np.isfinite(est.grad).all()
    every = _Corrupting(inner, np.arange(4))
    with pytest.warns(UnconvergedStepWarning), pytest.raises(UnconvergedStepError, match="only 0"):
        first_order(_objective(every, "drop"), theta, rng, 4)


def test_a_non_finite_return_of_a_usable_rollout_raises():
    """Converged steps but a non-finite return (here a reward that overflows): an error, never a
    result handed back bare."""
    stepper, reward, x0, horizon = ball_task(Fixed(1e-3), "total", horizon=6)

    class Overflowing:
        def stage(self, x, u):
            r, dx, du = reward.stage(x, u)
            return r * np.inf, dx, du

        def terminal(self, x):
            return reward.terminal(x)

    theta = np.zeros(LinearPolicy(NX, NU).n_params)
    noise = np.zeros((2, horizon, NU))
    with pytest.raises(FloatingPointError, match="return is not finite"):
        rollout(stepper, LinearPolicy(NX, NU), theta, x0, noise, Overflowing())
    r = rollout(stepper, LinearPolicy(NX, NU), theta, x0, np.zeros((2, 0, NU)), reward)
    assert r.x.shape == (2, 1, NX) and np.all(r.grad == 0)  # H = 0: the initial state's value
    np.testing.assert_allclose(r.returns, reward.terminal(r.x[:, 0])[0])


def test_the_objective_checks_its_policy_and_reward_protocols():
    stepper, reward, x0, horizon = ball_task(Fixed(1e-3))
    with pytest.raises(TypeError, match="policy must be a Policy"):
        PolicyObjective(stepper, object(), reward, x0, horizon)
    with pytest.raises(TypeError, match="reward must be a Reward"):
        PolicyObjective(stepper, LinearPolicy(NX, NU), object(), x0, horizon)
    with pytest.raises(ValueError, match=r"x0 must have shape \(nx,\) = \(4,\)"):
        PolicyObjective(stepper, LinearPolicy(NX, NU), reward, np.zeros(5), horizon)
    with pytest.raises(ValueError, match="reward and policy disagree on nx"):
        PolicyObjective(stepper, LinearPolicy(5, NU), reward, np.zeros(5), horizon)
