"""The locomotion comparison's baselines: PIPPS total propagation, ARS V2-t and the MBPO-style
model-based loop (drake_abs.policy.pipps, .ars_v2, .mbpo).

Checks: PIPPS is FOPG with all weight on the pathwise part and REINFORCE with returns-to-go with
none; on a linear-Gaussian problem it, FOPG and ZOPG all match the exact gradient (from the
propagated mean and covariance) within standard errors; its variance, measured, on a chaotic
map and on the ball with exact contact. ARS V2-t improves a quadratic return, its normaliser is
numpy's mean and std of the visited states, batched and per-direction rollouts agree, seeds
reproduce. The ensemble fits a linear system to rounding, learns a nonlinear one, has the
Jacobians of central differences; the MBPO loop improves the true return; seeds reproduce.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs import Exact, Fixed, point_mass_lcs
from drake_abs.contact.lcs import LcsStepper
from drake_abs.contact.step import contact_free_step
from drake_abs.engine import LinearStepper, rollout
from drake_abs.policy.ars_v2 import (
    PUBLISHED_SETTINGS,
    SURVIVAL_SHIFT,
    NormalizedLinearPolicy,
    ParameterBlocks,
    RunningMeanStd,
    ars_v2_train,
)
from drake_abs.policy.estimators import PolicyObjective, first_order, zeroth_order
from drake_abs.policy.gradient_stats import measure_variance
from drake_abs.policy.mbpo import MbpoConfig, MlpEnsemble, mbpo_train
from drake_abs.policy.pipps import pipps, pipps_detailed
from drake_abs.policy.policies import LinearPolicy, MLPPolicy
from drake_abs.policy.rewards import QuadraticReward

NX, NU = 4, 2


def double_integrator(policy=None, sigma=0.5, horizon=15):
    """A 2-D point mass without contact (x = (p, v), u = acceleration), a quadratic reward."""
    dt = 0.1
    A = np.eye(NX)
    A[0, 2] = A[1, 3] = dt
    B = np.zeros((NX, NU))
    B[2, 0] = B[3, 1] = dt
    reward = QuadraticReward(
        np.diag([1.0, 1.0, 0.1, 0.1]), 0.01 * np.eye(NU), np.zeros(NX), np.diag([5.0, 5.0, 1, 1])
    )
    return PolicyObjective(
        LinearStepper(A, B), policy or LinearPolicy(NX, NU), reward,
        np.array([1.0, -0.5, 0.0, 0.3]), horizon, sigma,
    )  # fmt: skip


def exact_return(obj: PolicyObjective, theta) -> float:
    """E[return] of a linear stepper under ``u = K x + k + sigma xi`` with a quadratic reward,
    from the propagated state mean m and covariance S (no sampling)."""
    A, B, rew = obj.stepper.A, obj.stepper.B, obj.reward
    K, k = obj.policy._split(np.asarray(theta, float))
    m, S, J = obj.x0.copy(), np.zeros((NX, NX)), 0.0
    for _ in range(obj.horizon):
        e, mu = m - rew.x_goal, K @ m + k
        Su = K @ S @ K.T + obj.sigma**2 * np.eye(NU)
        J -= e @ rew.Q @ e + np.trace(rew.Q @ S) + mu @ rew.R @ mu + np.trace(rew.R @ Su)
        Acl = A + B @ K
        m, S = Acl @ m + B @ k, Acl @ S @ Acl.T + obj.sigma**2 * B @ B.T
    e = m - rew.x_goal
    return J - e @ rew.Q_final @ e - np.trace(rew.Q_final @ S)


def ball_objective(smoothing, policy=None, horizon=40, sigma=0.3):
    """The 2-D ball thrown at the ground (as in test_policy_gradients.ball_task)."""
    reward = QuadraticReward(
        Q=np.diag([0.0, 1.0, 0.0, 0.01]), R=0.01 * np.eye(NU),
        x_goal=np.array([1.0, 0.2, 0.0, 0.0]), Q_final=np.diag([10.0, 1.0, 0.0, 0.0]),
    )  # fmt: skip
    stepper = LcsStepper(point_mass_lcs(2, time_step=0.02), smoothing, "frozen")
    return PolicyObjective(stepper, policy or LinearPolicy(NX, NU), reward,
                           np.array([0.0, 0.3, 1.0, -1.0]), horizon, sigma)  # fmt: skip


class KickedRotor:
    """The Chirikov standard map with a torque: ``p+ = p + K sin q + u``, ``q+ = q + p+``;
    chaotic (a positive Lyapunov exponent) for K of order 1."""

    parameter_names = ()

    def __init__(self, K: float):
        self.K = K

    def step(self, x, u, *, jacobians=True, parameters=False):
        q, p = x[:, 0], x[:, 1]
        p_next = p + self.K * np.sin(q) + u[:, 0]
        x_next = np.stack([q + p_next, p_next], axis=1)
        if not jacobians:
            return contact_free_step(x_next)
        c = self.K * np.cos(q)
        fx = np.empty((len(x), 2, 2))
        fx[:, 0, 0], fx[:, 0, 1], fx[:, 1, 0], fx[:, 1, 1] = 1 + c, 1.0, c, 1.0
        return contact_free_step(x_next, fx, np.ones((len(x), 2, 1)))


class CosineReward:
    """``r = cos q - 0.01 u^2`` per step, ``cos q`` at the end: bounded returns."""

    def stage(self, x, u):
        dx = np.stack([-np.sin(x[:, 0]), np.zeros(len(x))], axis=1)
        return np.cos(x[:, 0]) - 0.01 * u[:, 0] ** 2, dx, -0.02 * u

    def terminal(self, x):
        return np.cos(x[:, 0]), np.stack([-np.sin(x[:, 0]), np.zeros(len(x))], axis=1)


# ----- PIPPS ---------------------------------------------------------------------------------


@pytest.mark.parametrize("policy", [LinearPolicy(NX, NU), MLPPolicy(NX, NU, (8,))])
def test_pipps_with_all_weight_on_the_pathwise_part_is_fopg(policy):
    obj = ball_objective(Fixed(1e-3), policy)
    theta = 0.3 * np.random.default_rng(0).standard_normal(policy.n_params)
    est = pipps(obj, theta, np.random.default_rng(3), 16, rp_weight=1.0)
    fo = first_order(obj, theta, np.random.default_rng(3), 16)  # the same noise
    np.testing.assert_allclose(est.grad, fo.grad, rtol=1e-10, atol=1e-12 * np.abs(fo.grad).max())
    assert est.value == pytest.approx(fo.value, rel=1e-12)
    assert (est.rollouts, est.steps, est.unconverged) == (fo.rollouts, fo.steps, 0)


def test_pipps_with_no_pathwise_weight_is_reinforce_with_returns_to_go():
    obj = double_integrator()
    theta = 0.2 * np.random.default_rng(1).standard_normal(obj.policy.n_params)
    M = 8
    est = pipps(obj, theta, np.random.default_rng(4), M, rp_weight=0.0)
    xi = obj.noise(np.random.default_rng(4), M)
    traj = obj.rollout(theta, xi, gradient=False)
    r = np.stack([obj.reward.stage(traj.x[:, t], traj.u[:, t])[0] for t in range(obj.horizon)], 1)
    to_go = np.cumsum(r[:, ::-1], axis=1)[:, ::-1] + obj.reward.terminal(traj.x[:, -1])[0][:, None]
    g = np.zeros(obj.policy.n_params)
    for t in range(obj.horizon):
        adv = to_go[:, t] - (to_go[:, t].sum() - to_go[:, t]) / (M - 1)
        g += obj.policy.vjp(theta, traj.x[:, t], adv[:, None] * xi[:, t] / obj.sigma)[1].sum(0)
    np.testing.assert_allclose(est.grad, g / M, rtol=1e-10)


def test_pipps_fopg_and_zopg_agree_in_expectation_with_the_exact_gradient():
    """Linear dynamics, linear policy, quadratic reward: E[return] is exact from the propagated
    mean and covariance, and so is its gradient (central differences of a smooth function)."""
    obj = double_integrator()
    theta = 0.2 * np.random.default_rng(0).standard_normal(obj.policy.n_params)
    exact = central_difference(lambda th: np.array([exact_return(obj, th)]), theta)[0]
    estimators = {
        "fopg": lambda rng: first_order(obj, theta, rng, 64),
        "zopg": lambda rng: zeroth_order(obj, theta, rng, 64),
        "pipps": lambda rng: pipps(obj, theta, rng, 64),
        "pipps_action_variance": lambda rng: pipps(obj, theta, rng, 64, variance_of="action"),
        "pipps_half": lambda rng: pipps(obj, theta, rng, 64, rp_weight=0.5),
    }
    means, sems = {}, {}
    for name, est in estimators.items():
        g = np.array([est(np.random.default_rng(100 + s)).grad for s in range(30)])
        means[name], sems[name] = g.mean(axis=0), g.std(axis=0, ddof=1) / np.sqrt(len(g))
        assert np.all(np.abs(means[name] - exact) <= 4.5 * sems[name] + 1e-9), name
    for other in ("fopg", "zopg"):  # PIPPS against each, within their combined errors
        tol = 4.5 * np.hypot(sems["pipps"], sems[other])
        assert np.all(np.abs(means["pipps"] - means[other]) <= tol), other


def test_pipps_variance_is_below_the_worse_of_fopg_and_zopg_measured():
    """Measured (K = 30 independent estimates of M = 64 rollouts each, seeded). On the chaotic
    kicked rotor over 20 steps the pathwise gradient explodes (var ~8e5) while the likelihood
    ratio stays bounded (~1.4e3): PIPPS, mixing per step, is below both (~4.5e2). On the ball
    with exact contact (inelastic, not chaotic) the pathwise gradient is ~100 times quieter than
    the likelihood ratio, and PIPPS puts ~99.9% of the weight on it and matches it."""
    cases = {
        "rotor": (PolicyObjective(KickedRotor(1.5), LinearPolicy(2, 1), CosineReward(),
                                  np.array([1.0, 0.5]), 20, 0.2), np.array([-0.1, -0.1, 0.0])),
        "ball": (ball_objective(Exact()), np.full(LinearPolicy(NX, NU).n_params, 0.05)),
    }  # fmt: skip
    for name, (obj, theta) in cases.items():
        var = {}
        for est_name, est in (("fopg", first_order), ("zopg", zeroth_order), ("pipps", pipps)):
            stats = measure_variance(
                lambda th, rng, est=est, obj=obj: est(obj, th, rng, 64), theta, batches=30, seed=5
            )
            var[est_name] = stats.trace_variance
        assert var["pipps"] <= max(var["fopg"], var["zopg"]), (name, var)
        if name == "rotor":
            assert var["fopg"] > 100 * var["zopg"], var  # the curse of chaos is there
            assert var["pipps"] < min(var["fopg"], var["zopg"]), var
        else:
            assert var["zopg"] > 10 * var["fopg"], var
            assert var["pipps"] <= 1.05 * var["fopg"], var
            weights = pipps_detailed(obj, theta, np.random.default_rng(0), 64).rp_weight
            assert weights.min() > 0.95


def test_pipps_is_seeded_and_names_bad_arguments():
    obj = double_integrator()
    theta = np.zeros(obj.policy.n_params)
    a = pipps_detailed(obj, theta, np.random.default_rng(9), 8)
    b = pipps_detailed(obj, theta, np.random.default_rng(9), 8)
    np.testing.assert_array_equal(a.estimate.grad, b.estimate.grad)
    np.testing.assert_array_equal(a.rp_weight, b.rp_weight)
    assert a.rp_weight.shape == a.var_rp.shape == (obj.horizon,)
    assert np.all((a.rp_weight >= 0) & (a.rp_weight <= 1))
    with pytest.raises(ValueError, match="M must"):
        pipps(obj, theta, np.random.default_rng(0), 1)
    with pytest.raises(ValueError, match="rp_weight"):
        pipps(obj, theta, np.random.default_rng(0), 4, rp_weight=1.5)
    with pytest.raises(ValueError, match="variance_of"):
        pipps(obj, theta, np.random.default_rng(0), 4, variance_of="u")
    with pytest.raises(ValueError, match="theta must have shape"):
        pipps(obj, theta[:-1], np.random.default_rng(0), 4)
    quiet = dataclasses.replace(obj, sigma=0.0)
    with pytest.raises(ValueError, match="sigma > 0"):
        pipps(quiet, theta, np.random.default_rng(0), 4)
    pipps(quiet, theta, np.random.default_rng(0), 4, rp_weight=1.0)  # pathwise needs no noise


# ----- ARS V2-t ------------------------------------------------------------------------------


class RecordingStepper:
    """A stepper that keeps every state it is asked to step (the states the policy acted at)."""

    parameter_names = ()

    def __init__(self, inner):
        self.inner, self.seen = inner, []

    def step(self, x, u, *, jacobians=True, parameters=False):
        self.seen.append(np.array(x))
        return self.inner.step(x, u, jacobians=jacobians, parameters=parameters)


def ars_objective(stepper=None, sigma=0.1):
    base = double_integrator(NormalizedLinearPolicy(NX, NU), sigma=sigma, horizon=20)
    return base if stepper is None else dataclasses.replace(base, stepper=stepper(base.stepper))


def test_normalized_linear_policy_and_parameter_blocks_have_the_jacobians_of_differences():
    rng = np.random.default_rng(2)
    pol = NormalizedLinearPolicy(NX, NU, rng.standard_normal(NX),
                                 np.array([0.5, 2.0, 0.0, 1.5]), bias=True)  # fmt: skip
    theta = rng.standard_normal(pol.n_params)
    x = rng.standard_normal((4, NX))
    du_dx, du_dth = pol.jacobians(theta, x)
    assert np.all(du_dx[:, :, 2] == 0)  # a zero-variance coordinate has weight 0
    for pol_, th in (
        (pol, theta),
        (ParameterBlocks(pol, 2), rng.standard_normal(2 * pol.n_params)),
        (
            ParameterBlocks(pol, 3, owner=np.array([2, 0, 0, 1])),
            rng.standard_normal(3 * pol.n_params),
        ),
    ):
        du_dx, du_dth = pol_.jacobians(th, x)
        g = rng.standard_normal((4, NU))
        gx, gth = pol_.vjp(th, x, g)
        np.testing.assert_allclose(gx, np.einsum("mi,mij->mj", g, du_dx), atol=1e-12)
        np.testing.assert_allclose(gth, np.einsum("mi,mij->mj", g, du_dth), atol=1e-12)
        fd_th = central_difference(lambda t, p=pol_: p.act(t, x).ravel(), th)
        np.testing.assert_allclose(du_dth.reshape(-1, th.size), fd_th, atol=1e-8)
        for m in range(4):
            fd_x = central_difference(lambda y, m=m, p=pol_, t=th: p.act(t, _put(x, m, y))[m], x[m])
            np.testing.assert_allclose(du_dx[m], fd_x, atol=1e-8)


def _put(x, m, row):
    out = x.copy()
    out[m] = row
    return out


def test_ars_v2_t_improves_the_return_on_a_quadratic_problem():
    obj = ars_objective()
    run = ars_v2_train(obj, np.zeros(obj.policy.n_params), iterations=30, directions=8, top=4,
                       step_size=0.05, noise=0.05, rng=np.random.default_rng(0),
                       rollouts_per_direction=2)  # fmt: skip
    first, last = run.rows[0]["eval_return"], run.rows[-1]["eval_return"]
    assert last > first + 0.5 * abs(first), (first, last)
    assert len(run.rows) == 31 and all(r["env_steps"] == 2 * 8 * 2 * 20 for r in run.rows[:-1])
    assert run.rows[-2]["total_env_steps"] == 30 * 2 * 8 * 2 * 20
    assert np.all(np.isfinite(run.theta)) and isinstance(run.policy, NormalizedLinearPolicy)


def test_the_normaliser_is_numpys_mean_and_std_of_the_visited_states():
    obj = ars_objective(RecordingStepper)
    run = ars_v2_train(obj, np.zeros(obj.policy.n_params), iterations=5, directions=4, top=2,
                       step_size=0.05, noise=0.05, rng=np.random.default_rng(1),
                       rollouts_per_direction=3, evaluate=False)  # fmt: skip
    visited = np.concatenate(obj.stepper.seen)  # every training rollout's x_0 .. x_{H-1}
    assert visited.shape == (5 * 2 * 4 * 3 * 20, NX) and run.normalizer.count == len(visited)
    np.testing.assert_allclose(run.normalizer.mean, visited.mean(axis=0), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(run.normalizer.std, visited.std(axis=0), rtol=1e-10)
    np.testing.assert_array_equal(run.policy.mean, run.normalizer.mean)
    np.testing.assert_array_equal(run.policy.std, run.normalizer.std)
    stats = RunningMeanStd(3)  # batches of any size, one at a time
    rows = np.random.default_rng(0).standard_normal((50, 3)) * [1, 10, 1e-3] + [5, -2, 0]
    for part in np.split(rows, [1, 7, 30]):
        stats.push(part)
    np.testing.assert_allclose(stats.mean, rows.mean(0), rtol=1e-13)
    np.testing.assert_allclose(stats.std, rows.std(0), rtol=1e-12)


def test_ars_v2_is_seeded_and_batched_equals_one_rollout_per_policy():
    obj = ars_objective()
    kw = dict(iterations=4, directions=4, top=2, step_size=0.05, noise=0.05,
              rollouts_per_direction=2)  # fmt: skip
    a = ars_v2_train(obj, np.zeros(obj.policy.n_params), rng=np.random.default_rng(5), **kw)
    b = ars_v2_train(obj, np.zeros(obj.policy.n_params), rng=np.random.default_rng(5), **kw)
    c = ars_v2_train(obj, np.zeros(obj.policy.n_params), rng=np.random.default_rng(5),
                     batch_directions=False, **kw)  # fmt: skip
    np.testing.assert_array_equal(a.theta, b.theta)
    np.testing.assert_allclose(c.theta, a.theta, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(c.normalizer.std, a.normalizer.std, rtol=1e-12)


def test_published_settings_run_and_bad_arguments_are_named():
    assert set(PUBLISHED_SETTINGS) == {"Hopper-v1", "HalfCheetah-v1", "Walker2d-v1", "Ant-v1"}
    assert set(SURVIVAL_SHIFT) == set(PUBLISHED_SETTINGS)
    obj = ars_objective()
    theta = np.zeros(obj.policy.n_params)
    for settings in PUBLISHED_SETTINGS.values():
        run = ars_v2_train(obj, theta, iterations=1, rng=np.random.default_rng(0), **settings)
        assert run.rows[0]["env_steps"] == 2 * settings["directions"] * 20
    kw = dict(iterations=1, directions=4, top=2, step_size=0.1, noise=0.1,
              rng=np.random.default_rng(0))  # fmt: skip
    with pytest.raises(ValueError, match="NormalizedLinearPolicy"):
        ars_v2_train(double_integrator(), np.zeros(10), **kw)
    with pytest.raises(ValueError, match="top must be in"):
        ars_v2_train(obj, theta, **{**kw, "top": 5})
    with pytest.raises(ValueError, match="noise"):
        ars_v2_train(obj, theta, **{**kw, "noise": 0.0})
    with pytest.raises(ValueError, match="theta0"):
        ars_v2_train(obj, theta[:-1], **kw)
    with pytest.raises(ValueError, match="std must be >= 0"):
        NormalizedLinearPolicy(NX, NU, std=-np.ones(NX))


# ----- MBPO ----------------------------------------------------------------------------------


def test_the_ensemble_fits_a_linear_system_and_learns_a_nonlinear_one():
    rng = np.random.default_rng(0)
    A = np.eye(NX) + 0.1 * rng.standard_normal((NX, NX))
    B = 0.1 * rng.standard_normal((NX, NU))
    X, U = rng.standard_normal((600, NX)), rng.standard_normal((600, NU))
    Xn = X @ A.T + U @ B.T
    ens = MlpEnsemble(NX, NU, 5, (32, 32), np.random.default_rng(1))
    ens.fit(X[:500], U[:500], Xn[:500], np.random.default_rng(2), epochs=10)
    assert ens.error(X[500:], U[500:], Xn[500:]) < 1e-5  # held out, normalised units
    pred = ens.predict(X[500:], U[500:], np.arange(100) % 5)
    assert np.abs(pred - Xn[500:]).max() < 1e-3 * np.abs(Xn[500:] - X[500:]).max()

    def pendulum(x, u):
        return x + 0.1 * np.stack([x[:, 1], -np.sin(3 * x[:, 0]) + u[:, 0]], axis=1)

    X2, U2 = rng.uniform(-1.5, 1.5, (2000, 2)), rng.standard_normal((2000, 1))
    Xn2 = pendulum(X2, U2)
    errors = []
    for epochs in (0, 50):  # 0: the linear least-squares part alone
        ens2 = MlpEnsemble(2, 1, 3, (32, 32), np.random.default_rng(1))
        ens2.fit(X2[:1500], U2[:1500], Xn2[:1500], np.random.default_rng(2), epochs=epochs,
                 lr=3e-3, batch=128)  # fmt: skip
        errors.append(ens2.error(X2[1500:], U2[1500:], Xn2[1500:]))
    assert errors[1] < 0.05 * errors[0], errors


def test_the_model_has_the_jacobians_of_central_differences_also_through_a_rollout():
    rng = np.random.default_rng(3)
    X, U = rng.uniform(-1, 1, (400, NX)), rng.standard_normal((400, NU))
    Xn = X + 0.1 * np.tanh(X @ rng.standard_normal((NX, NX)) + U @ rng.standard_normal((NU, NX)))
    ens = MlpEnsemble(NX, NU, 3, (16, 16), np.random.default_rng(4))
    ens.fit(X, U, Xn, np.random.default_rng(5), epochs=20, lr=3e-3, batch=64)
    members = np.array([0, 2, 1, 2])
    x, u = X[:4], U[:4]
    _, dx_dx, dx_du = ens.predict(x, u, members, jacobians=True)
    for b in range(4):
        one = members[b : b + 1]
        fd_x = central_difference(lambda y, b=b, o=one: ens.predict(y[None], u[b : b + 1], o)[0],
                                  x[b])  # fmt: skip
        fd_u = central_difference(lambda v, b=b, o=one: ens.predict(x[b : b + 1], v[None], o)[0],
                                  u[b])  # fmt: skip
        np.testing.assert_allclose(dx_dx[b], fd_x, atol=1e-8)
        np.testing.assert_allclose(dx_du[b], fd_u, atol=1e-8)
    # the engine's adjoint gradient through the model (each rollout in its member)
    obj = double_integrator()
    theta = 0.1 * rng.standard_normal(obj.policy.n_params)
    noise = rng.standard_normal((4, 6, NU))
    x0 = X[:4]
    r = rollout(ens.stepper(members), obj.policy, theta, x0, noise, obj.reward, sigma=0.3)
    for m in range(4):
        fd = central_difference(
            lambda th, m=m: rollout(ens.stepper(members[m : m + 1]), obj.policy, th,
                                    x0[m : m + 1], noise[m : m + 1], obj.reward, sigma=0.3,
                                    gradient=False).returns,
            theta,
        )[0]  # fmt: skip
        np.testing.assert_allclose(r.grad[m], fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_mbpo_improves_the_true_return_and_is_seeded():
    obj = double_integrator(sigma=0.1, horizon=20)
    config = MbpoConfig(
        iterations=5, real_rollouts=4, hidden=(16,), model_epochs=10, rollout_length=5,
        branches=64, policy_updates=20, policy_lr=0.05,
    )  # fmt: skip
    theta0 = np.zeros(obj.policy.n_params)
    run = mbpo_train(obj, theta0, config, np.random.default_rng(0))
    first, last = run.rows[0]["real_return"], run.rows[-1]["eval_return"]
    assert last > first + 0.4 * abs(first), (first, last)
    assert [r["total_real_steps"] for r in run.rows[:-1]] == [80 * (j + 1) for j in range(5)]
    assert run.rows[1]["model_error"] < 1e-6  # a linear system: the model is exact
    again = mbpo_train(obj, theta0, config, np.random.default_rng(0))
    np.testing.assert_array_equal(run.theta, again.theta)
    strip = [{k: v for k, v in r.items() if k != "seconds"} for r in run.rows]
    assert strip == [{k: v for k, v in r.items() if k != "seconds"} for r in again.rows]


def test_branches_return_the_truncated_return_to_go_with_the_terminal_reward_at_the_horizon():
    """An exact model (a linear system): a branch from a state visited at step t runs
    min(k, H - t) steps, and its return and gradient are the true system's over those steps,
    with the terminal reward exactly when it reaches the horizon."""
    from drake_abs.policy.mbpo import _model_gradient

    obj = double_integrator(sigma=0.3, horizon=10)
    rng = np.random.default_rng(0)
    X, U = rng.standard_normal((300, NX)), rng.standard_normal((300, NU))
    ens = MlpEnsemble(NX, NU, 2, (8,), np.random.default_rng(1))
    ens.fit(X, U, obj.stepper.step(X, U, jacobians=False).x_next, rng, epochs=5, ridge=0.0)
    theta = 0.1 * rng.standard_normal(obj.policy.n_params)
    config = MbpoConfig(rollout_length=3, branches=4)
    start = np.array([0.5, -0.2, 0.1, 0.3])
    for t, steps, terminal in ((8, 2, True), (2, 3, False)):  # H - t = 2 < k; H - t = 8 > k
        data = {"x": start[None], "t": np.array([t])}
        grad, ret = _model_gradient(obj, ens, theta, data, config, np.random.default_rng(6))
        draw = np.random.default_rng(6)  # the same draws: start rows, members, then the noise
        draw.integers(0, 1, size=4), draw.integers(0, 2, size=4)
        noise = obj.noise(draw, 4)[:, :steps]
        reward = obj.reward if terminal else dataclasses.replace(
            obj.reward, Q_final=np.zeros((NX, NX))
        )  # fmt: skip
        true = rollout(obj.stepper, obj.policy, theta, start, noise, reward, sigma=obj.sigma)
        assert ret == pytest.approx(true.returns.mean(), rel=1e-8)
        np.testing.assert_allclose(grad, true.grad.mean(axis=0), rtol=1e-7, atol=1e-10)


def test_mbpo_names_bad_arguments():
    with pytest.raises(ValueError, match="rollout_length"):
        MbpoConfig(rollout_length=0)
    with pytest.raises(ValueError, match="hidden"):
        MbpoConfig(hidden=(0,))
    with pytest.raises(ValueError, match="policy_lr"):
        MbpoConfig(policy_lr=-1.0)
    obj = double_integrator()
    with pytest.raises(ValueError, match="theta0"):
        mbpo_train(obj, np.zeros(3), MbpoConfig(), np.random.default_rng(0))
    with pytest.raises(ValueError, match="config"):
        mbpo_train(obj, np.zeros(10), {"iterations": 1}, np.random.default_rng(0))
    ens = MlpEnsemble(NX, NU, 2, (4,), np.random.default_rng(0))
    with pytest.raises(ValueError, match="members"):
        ens.predict(np.zeros((2, NX)), np.zeros((2, NU)), np.array([0, 2]))
    with pytest.raises(ValueError, match="x and u must have shapes"):
        ens.predict(np.zeros((2, NX)), np.zeros((3, NU)), np.array([0, 1]))
