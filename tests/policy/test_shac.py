"""SHAC through a differentiable stepper (drake_abs.policy.shac): the window gradient against
central differences (a point mass with terminations and truncations, and gymnasium's Hopper on
our plant), against the engine's own rollout gradient, independent of the chunking; checkpoints
resume bit for bit; a short run improves its return (SHAC and plain FOPG)."""

import numpy as np
import pytest
from numdiff import central_difference
from shac_cases import PointMassEnv

from drake_abs.contact.smoothing import ContactAware
from drake_abs.engine import rollout
from drake_abs.policy.observation_normalizer import NormalizedPolicy
from drake_abs.policy.policies import LinearPolicy, MLPPolicy
from drake_abs.policy.shac import ShacConfig, ShacTrainer, window_gradient
from drake_abs.policy.value_function import StateValue, ValueFunction

ENV = PointMassEnv()


def _point_mass_window(inner, rng, value=True, chunk=32):
    """A window of 6 environments over H = 8 steps: env 0 truncated after 3 steps, env 1 leaves
    the box (terminated), the others run through (bootstrapped from a random critic)."""
    mean, std = np.array([0.1, -0.2]), np.array([0.8, 1.5])
    policy = ENV.policy(NormalizedPolicy(inner, mean, std))
    x0 = rng.uniform(-1, 1, (6, 2))
    x0[1] = [1.8, 1.5]  # moving out: terminated within the window
    noise = rng.standard_normal((6, 8, 1))
    remaining = np.array([3, 20, 8, 9, 30, 100])
    critic = ValueFunction(2, (5,))
    V = StateValue(critic, critic.init(rng), ENV.observation, mean, std) if value else None

    def run(theta):
        return window_gradient(ENV.stepper, policy, theta, x0, noise, ENV.reward, sigma=0.3,
                               remaining=remaining, gamma=0.9, value=V, chunk=chunk)  # fmt: skip

    return run


@pytest.mark.parametrize("kind", ["linear", "mlp"])
def test_window_gradient_equals_central_differences(kind):
    rng = np.random.default_rng(3)
    inner = LinearPolicy(2, 1) if kind == "linear" else MLPPolicy(2, 1, (4,))
    theta = 0.3 * rng.standard_normal(inner.n_params)
    run = _point_mass_window(inner, rng)
    win = run(theta)
    assert list(win.lengths[:2]) == [3, win.lengths[1]] and win.lengths[1] < 8
    assert win.truncated[0] and win.terminated[1] and not win.terminated[2:].any()
    assert list(win.bootstrap) == [True, False, True, True, True, True]
    fd = central_difference(lambda th: np.array([run(th).objective]), theta)[0]
    np.testing.assert_allclose(win.grad, fd, rtol=1e-6, atol=1e-8)


def test_window_objective_is_the_discounted_sum_plus_the_tail():
    rng = np.random.default_rng(4)
    inner = LinearPolicy(2, 1)
    theta = 0.3 * rng.standard_normal(inner.n_params)
    win = _point_mass_window(inner, rng)(theta)
    L = win.lengths
    by_hand = [
        sum(0.9**t * win.rewards[m, t] for t in range(L[m])) + 0.9 ** L[m] * win.tail[m]
        for m in range(6)
    ]
    np.testing.assert_allclose(win.objectives, by_hand, rtol=1e-12)
    assert win.tail[1] == 0.0 and np.all(win.tail[[0, 2, 3, 4, 5]] != 0.0)
    assert win.objective == pytest.approx(np.mean(by_hand), rel=1e-12)
    np.testing.assert_array_equal(win.scores, 0.0)  # no score reward given


def test_a_score_reward_is_summed_over_the_same_steps():
    rng = np.random.default_rng(4)
    inner = LinearPolicy(2, 1)
    theta = 0.3 * rng.standard_normal(inner.n_params)
    run = _point_mass_window(inner, rng)
    win = run(theta)
    policy = ENV.policy(NormalizedPolicy(inner, np.array([0.1, -0.2]), np.array([0.8, 1.5])))
    x0, noise = win.x[:, 0], (win.u - policy.act(theta, win.x[:, 0])[:, None]) / 0.3
    again = window_gradient(
        ENV.stepper, policy, theta, x0, noise[:, :1], ENV.reward, sigma=0.3,
        remaining=np.full(6, 1), gamma=0.9, score_reward=ENV.reward,
    )  # fmt: skip
    np.testing.assert_allclose(again.scores, again.returns, rtol=1e-14)
    np.testing.assert_allclose(again.returns, win.rewards[:, 0], rtol=1e-12)


def test_chunking_changes_nothing():
    rng = np.random.default_rng(5)
    inner = MLPPolicy(2, 1, (4,))
    theta = 0.3 * rng.standard_normal(inner.n_params)
    a = _point_mass_window(inner, np.random.default_rng(6), chunk=32)(theta)
    b = _point_mass_window(inner, np.random.default_rng(6), chunk=3)(theta)
    np.testing.assert_allclose(a.grad, b.grad, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(a.lengths, b.lengths)
    np.testing.assert_allclose(a.objectives, b.objectives, rtol=1e-12)


def test_without_critic_discount_or_ends_it_is_the_engines_gradient():
    """gamma = 1, V = 0, no episode ending: the mean of engine.rollout's per-rollout gradients
    (an independent path through the same Jacobians)."""
    rng = np.random.default_rng(7)
    inner = LinearPolicy(2, 1)
    policy = ENV.policy(inner)
    theta = 0.2 * rng.standard_normal(inner.n_params)
    x0 = rng.uniform(-0.5, 0.5, (5, 2))
    noise = rng.standard_normal((5, 10, 1))
    win = window_gradient(ENV.stepper, policy, theta, x0, noise, ENV.reward, sigma=0.1,
                          remaining=np.full(5, 10), gamma=1.0)  # fmt: skip
    ref = rollout(ENV.stepper, policy, theta, x0, noise, ENV.reward, sigma=0.1)
    assert ref.alive.all()
    np.testing.assert_allclose(win.grad, ref.grad.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(win.returns, ref.returns, rtol=1e-12)


def test_hopper_window_gradient_equals_central_differences():
    """Three steps of gymnasium's Hopper on our plant (adaptive smoothing, the smooth survive
    term), with a critic tail: the reverse pass through the step Jacobians against central
    differences of the window objective."""
    from drake_abs.tasks.locomotion import SmoothHealthy, locomotion_task

    task = locomotion_task("hopper", smoothing=ContactAware(1e-2, 0.05),
                           reward_options={"smooth_survive": SmoothHealthy()})  # fmt: skip
    rng = np.random.default_rng(8)
    x0 = task.initial_states(rng, 2)
    x0[:, task.nq :] += 0.3 * rng.standard_normal((2, task.nx - task.nq))
    mean, std = np.zeros(task.n_obs), np.full(task.n_obs, 0.5)
    inner = LinearPolicy(task.n_obs, task.nu)
    policy = task.policy(NormalizedPolicy(inner, mean, std))
    critic = ValueFunction(task.n_obs, (4,))
    V = StateValue(critic, critic.init(rng), task.observation, mean, std)
    noise = rng.standard_normal((2, 3, task.nu))
    theta = 0.05 * rng.standard_normal(inner.n_params)

    def run(th):
        return window_gradient(task.stepper, policy, th, x0, noise, task.reward, sigma=0.2,
                               remaining=np.array([1000, 2]), gamma=0.99, value=V)  # fmt: skip

    win = run(theta)
    assert win.used.all() and list(win.lengths) == [3, 2]
    fd = central_difference(lambda th: np.array([run(th).objective]), theta, eps=1e-6)[0]
    np.testing.assert_allclose(win.grad, fd, rtol=1e-4, atol=1e-4 * np.abs(fd).max())


def _trainer(config, seed=0):
    return ShacTrainer(ENV, config, seed)


SMALL = ShacConfig(envs=8, window=6, episode_length=40, critic_hidden=(8,), critic_epochs=2,
                   critic_minibatches=2, actor_lr=0.05, critic_lr=1e-2)  # fmt: skip


def test_one_seed_gives_the_same_numbers():
    a, b = _trainer(SMALL, 3), _trainer(SMALL, 3)
    ra, rb = a.train(5), b.train(5)
    for x, y in zip(ra, rb, strict=True):
        assert {k: v for k, v in x.items() if k != "seconds"} == {
            k: v for k, v in y.items() if k != "seconds"
        }
    np.testing.assert_array_equal(a.state.theta, b.state.theta)
    c = _trainer(SMALL, 4)
    c.train(5)
    assert not np.array_equal(a.state.theta, c.state.theta)


@pytest.mark.parametrize("config", [SMALL, ShacConfig.fopg(envs=4, episode_length=15,
                                                           actor_lr=0.05, policy="mlp",
                                                           hidden=(4,))])  # fmt: skip
def test_resume_from_a_checkpoint_is_bit_identical(tmp_path, config):
    whole = _trainer(config, 11)
    whole.train(7)
    first = _trainer(config, 11)
    first.train(7, checkpoint=tmp_path / "run.ckpt", checkpoint_every=3, max_seconds=0.0)
    assert first.state.iteration == 1  # stopped by the time budget after one iteration
    resumed = ShacTrainer.load(tmp_path / "run.ckpt", ENV)
    resumed.train(4, checkpoint=tmp_path / "run.ckpt", checkpoint_every=3)
    again = ShacTrainer.load(tmp_path / "run.ckpt", ENV)  # saved at iteration 3 and 4
    assert again.state.iteration == 4
    again.train(7)
    s, w = again.state, whole.state
    for name in ("theta", "phi", "phi_target", "x", "episode_step", "episode_return",
                 "needs_reset"):  # fmt: skip
        np.testing.assert_array_equal(getattr(s, name), getattr(w, name), err_msg=name)
    assert s.env_steps == w.env_steps and s.episodes == w.episodes
    assert s.rng.bit_generator.state == w.rng.bit_generator.state
    strip = [{k: v for k, v in row.items() if k != "seconds"} for row in s.rows]
    assert strip == [{k: v for k, v in row.items() if k != "seconds"} for row in w.rows]


def test_what_is_not_a_checkpoint_is_refused(tmp_path):
    import pickle

    (tmp_path / "a.ckpt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="shac checkpoint"):
        ShacTrainer.load(tmp_path / "a.ckpt", ENV)
    (tmp_path / "b.ckpt").write_bytes(pickle.dumps({"format": "something else"}))
    with pytest.raises(ValueError, match="shac checkpoint"):
        ShacTrainer.load(tmp_path / "b.ckpt", ENV)


@pytest.mark.parametrize("config", [
    ShacConfig(envs=16, window=8, episode_length=50, critic_hidden=(16,), actor_lr=0.05,
               critic_lr=1e-2),
    ShacConfig.fopg(envs=16, episode_length=50, actor_lr=0.05),
])  # fmt: skip
def test_a_short_run_improves_the_return(config):
    t = _trainer(config, 1)
    rows = t.train(60)
    first = next(r["recent_return"] for r in rows if r["recent_return"] is not None)
    assert first < 10 and rows[-1]["recent_return"] > 40  # 50 steps of reward <= 1
    assert all(r["dropped"] == 0 for r in rows)
    steps = np.diff([0] + [r["env_steps"] for r in rows])
    assert rows[-1]["env_steps"] == t.state.env_steps and np.all(steps <= 16 * rows[0]["window"])
    arrays = t.policy_arrays()
    assert set(arrays) == {"W", "b", "obs_mean", "obs_std"} and arrays["W"].shape == (1, 2)


def test_policy_arrays_reproduce_the_policy():
    config = ShacConfig(envs=4, window=5, episode_length=20, policy="mlp", hidden=(6, 5),
                        critic_hidden=(4,), critic_epochs=1)  # fmt: skip
    t = _trainer(config, 2)
    t.train(3)
    a = t.policy_arrays()
    o = np.random.default_rng(0).standard_normal((7, 2))
    h = (o - a["obs_mean"]) / a["obs_std"]
    h = np.tanh(h @ a["W0"].T + a["b0"])
    h = np.tanh(h @ a["W1"].T + a["b1"])
    by_hand = h @ a["W2"].T + a["b2"]
    np.testing.assert_allclose(t.normalized_policy().act(t.state.theta, o), by_hand, rtol=1e-12)
    assert str(a["activation"]) == "tanh"


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="gamma"):
        ShacConfig(gamma=1.5)
    with pytest.raises(ValueError, match="sigma_decay_steps"):
        ShacConfig(sigma_end=0.0)
    with pytest.raises(ValueError, match="policy"):
        ShacConfig(policy="rnn")
    with pytest.raises(ValueError, match="on_unconverged"):
        ShacConfig(on_unconverged="ignore")
    with pytest.raises(ValueError, match="theta0"):
        ShacTrainer(ENV, SMALL, 0, theta0=np.zeros(2))
    with pytest.raises(TypeError, match="env"):
        ShacTrainer(object(), SMALL, 0)
    rng = np.random.default_rng(0)
    policy = ENV.policy(LinearPolicy(2, 1))
    with pytest.raises(ValueError, match="remaining"):
        window_gradient(ENV.stepper, policy, np.zeros(3), rng.standard_normal((2, 2)),
                        rng.standard_normal((2, 4, 1)), ENV.reward, sigma=0.1,
                        remaining=np.array([0, 3]), gamma=0.9)  # fmt: skip


def test_actor_step_size_decays_linearly_to_zero():
    from dataclasses import replace

    c = ShacConfig(actor_lr=4e-3, actor_lr_decay_steps=1000)
    assert c.actor_lr_at(0) == 4e-3 and c.actor_lr_at(250) == pytest.approx(3e-3)
    assert c.actor_lr_at(1000) == 0.0 and c.actor_lr_at(5000) == 0.0
    assert ShacConfig(actor_lr=4e-3).actor_lr_at(10**9) == 4e-3
    with pytest.raises(ValueError, match="actor_lr_decay_steps"):
        ShacConfig(actor_lr_decay_steps=-1)
    # past the decay the policy no longer moves; before it, the run differs from a constant one
    decayed = _trainer(replace(SMALL, actor_lr_decay_steps=60), 3)
    decayed.train(4)
    assert decayed.state.env_steps >= 60
    frozen = decayed.state.theta.copy()
    decayed.train(6)
    np.testing.assert_array_equal(decayed.state.theta, frozen)
    constant = _trainer(SMALL, 3)
    constant.train(4)
    assert not np.array_equal(constant.state.theta, frozen)


def test_sigma_schedule():
    c = ShacConfig(sigma=0.4, sigma_end=0.1, sigma_decay_steps=100)
    assert c.sigma_at(0) == 0.4 and c.sigma_at(50) == pytest.approx(0.25)
    assert c.sigma_at(1000) == pytest.approx(0.1)
    assert ShacConfig(sigma=0.2).sigma_at(10**6) == 0.2


def test_registered_methods_give_their_settings():
    assert ShacConfig.for_method("shac_abs") == ShacConfig()
    assert ShacConfig.for_method("shac_exact", envs=8).envs == 8
    fopg = ShacConfig.for_method("fopg_episode_abs")
    assert fopg.window is None and not fopg.critic and fopg.gamma == 1.0
    assert fopg.horizon == fopg.episode_length == 1000
    with pytest.raises(ValueError, match="this trainer runs"):
        ShacConfig.for_method("fopg_abs")
