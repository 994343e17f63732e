"""The critic of short-horizon policy learning (drake_abs.policy.value_function): TD(lambda)
targets against their definitions, the fit converging to a known value (a constant reward:
V = r / (1 - gamma)), and its derivatives against central differences."""

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs.policy.training import Adam
from drake_abs.policy.value_function import StateValue, ValueFunction, td_lambda_targets
from drake_abs.tasks.locomotion import LocomotionObservation


def _case(rng, M=4, H=6):
    rewards = rng.standard_normal((M, H))
    values = rng.standard_normal((M, H + 1))
    lengths = np.array([6, 3, 1, 6])[:M]
    bootstrap = np.array([True, True, False, False])[:M]
    return rewards, values, lengths, bootstrap


def test_lambda_one_is_the_discounted_sum_plus_the_tail():
    rewards, values, lengths, bootstrap = _case(np.random.default_rng(0))
    g = 0.9
    G = td_lambda_targets(rewards, values, lengths, bootstrap, g, 1.0)
    for m, L in enumerate(lengths):
        tail = values[m, L] if bootstrap[m] else 0.0
        for t in range(L):
            want = sum(g ** (k - t) * rewards[m, k] for k in range(t, L)) + g ** (L - t) * tail
            assert G[m, t] == pytest.approx(want, rel=1e-12)
        assert np.all(G[m, L:] == 0)


def test_lambda_zero_is_one_step_td():
    rewards, values, lengths, bootstrap = _case(np.random.default_rng(1))
    g = 0.8
    G = td_lambda_targets(rewards, values, lengths, bootstrap, g, 0.0)
    for m, L in enumerate(lengths):
        for t in range(L):
            nxt = values[m, t + 1] if (t + 1 < L or bootstrap[m]) else 0.0
            assert G[m, t] == pytest.approx(rewards[m, t] + g * nxt, rel=1e-12)


def test_lambda_is_the_weighted_mix_of_n_step_returns():
    """G^lambda = (1 - lambda) sum_n lambda^(n-1) G^(n) + lambda^(L-t-1) G^(L-t) (the n-step
    returns G^(n), the last one running to the window's end)."""
    rewards, values, lengths, bootstrap = _case(np.random.default_rng(2))
    g, lam = 0.95, 0.7
    G = td_lambda_targets(rewards, values, lengths, bootstrap, g, lam)
    for m, L in enumerate(lengths):
        v = values[m].copy()
        v[L] = v[L] if bootstrap[m] else 0.0
        for t in range(L):
            n_step = [
                sum(g ** (k - t) * rewards[m, k] for k in range(t, t + n)) + g**n * v[t + n]
                for n in range(1, L - t + 1)
            ]
            want = (1 - lam) * sum(lam ** (n - 1) * n_step[n - 1] for n in range(1, L - t))
            want += lam ** (L - t - 1) * n_step[-1]
            assert G[m, t] == pytest.approx(want, rel=1e-10)


def test_a_constant_reward_is_learned_as_r_over_one_minus_gamma():
    """Fitting on the window's own TD(lambda) targets, again and again (as SHAC does), reaches
    the fixed point of a constant reward that never ends: V = 1 / (1 - 0.9) = 10 everywhere."""
    rng = np.random.default_rng(3)
    critic = ValueFunction(3, (16,))
    phi = critic.init(rng)
    opt = Adam(lr=1e-2)
    gamma, lam, M, H = 0.9, 0.95, 16, 8
    for _ in range(150):
        z = rng.standard_normal((M, H + 1, 3))
        values = critic(phi, z.reshape(-1, 3)).reshape(M, H + 1)
        G = td_lambda_targets(np.ones((M, H)), values, np.full(M, H), np.ones(M, bool), gamma, lam)
        phi, loss = critic.fit(phi, z[:, :H].reshape(-1, 3), G.reshape(-1), opt, rng,
                               epochs=4, minibatches=4)  # fmt: skip
    v = critic(phi, rng.standard_normal((200, 3)))
    np.testing.assert_allclose(v, 10.0, rtol=0.02)
    assert loss < 0.05


def test_derivatives_against_central_differences():
    rng = np.random.default_rng(4)
    critic = ValueFunction(3, (5, 4))
    phi = critic.init(rng)
    z = rng.standard_normal((6, 3))
    G = rng.standard_normal(6)
    loss, g_phi = critic.loss_and_gradient(phi, z, G)
    fd = central_difference(lambda p: np.array([critic.loss_and_gradient(p, z, G)[0]]), phi)[0]
    np.testing.assert_allclose(g_phi, fd, rtol=1e-6, atol=1e-9)
    _, g_z = critic.value_and_input_gradient(phi, z)
    for m in range(6):
        fd_z = central_difference(lambda zz, m=m: critic(phi, zz[None])[:1], z[m])[0]
        np.testing.assert_allclose(g_z[m], fd_z, rtol=1e-6, atol=1e-9)


def test_state_value_through_a_clipped_observation():
    """V(x) through the Hopper-like observation (position skipped, velocities clipped at 10) and
    the normaliser: dV/dx against central differences, zero where a velocity is clipped."""
    rng = np.random.default_rng(5)
    obs = LocomotionObservation(3, 3, 10.0)
    critic = ValueFunction(obs.n_obs, (6,))
    sv = StateValue(critic, critic.init(rng), obs, rng.standard_normal(5), 0.5 + rng.random(5))
    x = rng.standard_normal((4, 6))
    x[2, 4] = 12.0  # clipped
    v, dv = sv.value_and_gradient(x)
    np.testing.assert_allclose(v, sv(x), rtol=1e-14)
    for m in range(4):
        fd = central_difference(lambda xx, m=m: sv(xx[None]), x[m])[0]
        np.testing.assert_allclose(dv[m], fd, rtol=1e-6, atol=1e-9)
    assert dv[2, 4] == 0.0 and dv[0, 0] == 0.0


def test_bad_input_is_refused():
    rewards, values, lengths, bootstrap = _case(np.random.default_rng(6))
    with pytest.raises(ValueError, match="values"):
        td_lambda_targets(rewards, values[:, :-1], lengths, bootstrap, 0.9, 0.9)
    with pytest.raises(ValueError, match="lengths"):
        td_lambda_targets(rewards, values, lengths + 5, bootstrap, 0.9, 0.9)
    with pytest.raises(ValueError, match="bootstrap"):
        td_lambda_targets(rewards, values, lengths, bootstrap.astype(int), 0.9, 0.9)
    with pytest.raises(ValueError, match="lam"):
        td_lambda_targets(rewards, values, lengths, bootstrap, 0.9, 1.5)
    with pytest.raises(ValueError, match="hidden"):
        ValueFunction(3, ())


def test_the_summed_product_is_the_sum_of_the_per_row_ones():
    from drake_abs.policy.policies import MLPPolicy

    rng = np.random.default_rng(7)
    net = MLPPolicy(4, 2, (5, 3), output_scale=1.5)
    theta, x, g = net.init(rng), rng.standard_normal((9, 4)), rng.standard_normal((9, 2))
    gx, gth = net.vjp(theta, x, g)
    gx_s, gth_s = net.vjp_sum(theta, x, g)
    np.testing.assert_allclose(gx_s, gx, rtol=1e-14)
    np.testing.assert_allclose(gth_s, gth.sum(axis=0), rtol=1e-12, atol=1e-14)
