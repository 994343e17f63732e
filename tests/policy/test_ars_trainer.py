"""ARS V2-t as the community runs it (drake_abs.policy.ars_trainer) and its update
(drake_abs.policy.ars_v2.ars_update).

Checks: the update against a hand computation on a tiny case (selection, sigma_R, step, unusable
directions, too few of them, equal returns); one iteration of the trainer against the same
iteration computed from separate single-episode rollouts (the directions and reset states drawn
from the seed, the + and - episodes from one state, the shift, the normaliser of the observations
acted on); episodes that end at termination stop counting steps and feed the normaliser only
the observations acted on, whatever the chunk; a run resumed from a checkpoint gives the numbers
of an uninterrupted one; seeds reproduce; a tiny run on the Hopper exports a policy file whose
actions equal the trained policy's on gymnasium's own observations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from shac_cases import PointMassEnv

from drake_abs.contact.unconverged import UnconvergedStepError
from drake_abs.engine import rollout
from drake_abs.engine.steppers import LinearStepper
from drake_abs.policy.ars_trainer import ArsConfig, ArsTrainer, run_episodes
from drake_abs.policy.ars_v2 import NormalizedLinearPolicy, ars_update
from drake_abs.tasks.adapters import ObservationPolicy
from drake_abs.tasks.locomotion import LocomotionObservation

# ----- the update ----------------------------------------------------------------------------


def test_ars_update_is_the_hand_computed_step():
    delta = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    returns = np.array([[3.0, 1.0], [0.0, 2.0], [5.0, 4.0]])  # max per direction: 3, 2, 5
    up = ars_update(np.array([0.5, -0.5]), delta, returns, np.ones(3, bool), 2, 0.1)
    # top 2: directions 2 (max 5) and 0 (max 3); the returns used 5, 4, 3, 1 have mean 3.25 and
    # population variance (1.75^2 + 0.75^2 + 0.25^2 + 2.25^2) / 4 = 2.1875;
    # sum (r+ - r-) delta = 1 * (1, 1) + 2 * (1, 0) = (3, 1)
    sigma = np.sqrt(2.1875)
    np.testing.assert_array_equal(up.best, [2, 0])
    assert up.sigma_R == pytest.approx(sigma, rel=1e-15)
    np.testing.assert_allclose(up.step, 0.1 / (2 * sigma) * np.array([3.0, 1.0]), rtol=1e-14)
    np.testing.assert_allclose(up.theta, [0.5, -0.5] + up.step, rtol=0, atol=0)

    # direction 2 unusable: 0 (max 3) and 1 (max 2); returns 3, 1, 0, 2: variance 1.25;
    # sum = 2 * (1, 0) + (-2) * (0, 1) = (2, -2)
    up = ars_update(np.zeros(2), delta, returns, np.array([True, True, False]), 2, 0.1)
    np.testing.assert_array_equal(up.best, [0, 1])
    np.testing.assert_allclose(up.step, 0.1 / (2 * np.sqrt(1.25)) * np.array([2.0, -2.0]))
    with pytest.raises(UnconvergedStepError, match="only 1 direction"):
        ars_update(np.zeros(2), delta, returns, np.array([False, True, False]), 2, 0.1)
    # equal returns: sigma_R is taken as 1 (and the step is 0)
    up = ars_update(np.zeros(2), delta, np.ones((3, 2)), np.ones(3, bool), 3, 0.1)
    assert up.sigma_R == 1.0 and np.all(up.step == 0)


# ----- one iteration against separate rollouts ------------------------------------------------


def _by_hand(env, config: ArsConfig, seed: int, theta, mean, std):
    """One iteration from separate single-episode engine rollouts (no chunks, no parameter
    blocks): the new theta and the observations acted on."""
    rng = np.random.default_rng(seed)
    N, nu_ = config.directions, config.noise
    delta = rng.standard_normal((N, theta.size))
    if config.paired_starts:
        starts = env.initial_states(rng, N)
        x0 = [starts[k] for k in range(N) for _ in (0, 1)]
    else:
        x0 = list(env.initial_states(rng, 2 * N))
    inner = NormalizedLinearPolicy(env.n_obs, env.nu, mean, std)
    policy = env.policy(inner)
    R, seen = np.zeros((N, 2)), []
    H = config.episode_length
    for k in range(N):
        for j, sign in enumerate((1.0, -1.0)):
            tr = rollout(env.stepper, policy, theta + sign * nu_ * delta[k], x0[2 * k + j],
                         np.zeros((1, H, env.nu)), env.reward, sigma=0.0,
                         gradient=False)  # fmt: skip
            L = int(tr.alive.sum())
            R[k, j] = tr.returns[0] - config.shift * L
            seen.append(env.observation(tr.x[0, :L]))
    best = np.argsort(-R.max(axis=1), kind="stable")[: config.top]
    sigma = R[best].std()
    step = sum((R[k, 0] - R[k, 1]) * delta[k] for k in best)
    return theta + config.step_size / (config.top * sigma) * step, np.concatenate(seen)


@pytest.mark.parametrize("paired", [True, False])
def test_one_iteration_is_the_update_of_its_episodes(paired):
    env = PointMassEnv()
    config = ArsConfig(directions=4, top=2, step_size=0.3, noise=0.5, shift=0.7,
                       episode_length=60, chunk=7, paired_starts=paired)  # fmt: skip
    trainer = ArsTrainer(env, config, seed=3, theta0=np.array([0.2, -0.4]))
    row = trainer.iterate()
    theta, seen = _by_hand(env, config, 3, np.array([0.2, -0.4]), np.zeros(2), np.ones(2))
    np.testing.assert_allclose(trainer.state.theta, theta, rtol=1e-12, atol=1e-14)
    assert row["env_steps"] == len(seen) == trainer.state.normalizer.count
    assert 0 < row["terminated"] < 8 and row["length_mean"] < 60  # some episodes ended early
    np.testing.assert_allclose(trainer.state.normalizer.mean, seen.mean(0), rtol=1e-12)
    np.testing.assert_allclose(trainer.state.normalizer.std, seen.std(0), rtol=1e-12)

    # the second iteration acts with the normaliser of the first one's observations
    before = trainer.state.theta.copy()
    mean, std = trainer.state.normalizer.mean, trainer.state.normalizer.std  # copies
    trainer.state.rng = np.random.default_rng(11)
    trainer.iterate()
    theta, _ = _by_hand(env, config, 11, before, mean, std)
    np.testing.assert_allclose(trainer.state.theta, theta, rtol=1e-12, atol=1e-14)


# ----- termination -----------------------------------------------------------------------------


@dataclass(frozen=True)
class OnePerStep:
    """r = 1 + u per step; the episode ends once the position p' reaches ``goal``."""

    nx: int = 2
    nu: int = 1
    goal: float = 10.0

    def transition(self, x, u, x_next):
        M = len(x)
        return 1.0 + u[:, 0], np.zeros((M, 2)), np.ones((M, 1)), np.zeros((M, 2))

    def terminal(self, x):
        return np.zeros(len(x)), np.zeros_like(x)

    def terminated(self, x_next):
        return x_next[:, 0] >= self.goal


@dataclass(frozen=True)
class Walk:
    """x = (p, 1): p grows by 1 per step whatever the action; starts at a whole p in 0 .. 9, so
    an episode lasts 10 - p steps."""

    stepper: LinearStepper = LinearStepper(np.array([[1.0, 1.0], [0.0, 1.0]]), np.zeros((2, 1)))
    reward: OnePerStep = OnePerStep()
    observation: LocomotionObservation = LocomotionObservation(1, 1, None, 0)
    n_obs: int = 2
    nu: int = 1

    def initial_states(self, rng, M):
        return np.stack([rng.integers(0, 10, M).astype(float), np.ones(M)], axis=1)

    def policy(self, inner):
        return ObservationPolicy(inner, self.observation)


@pytest.mark.parametrize("chunk", [1, 3, 25])
def test_an_episode_that_terminates_stops_counting_steps(chunk):
    env = Walk()
    starts = np.array([0.0, 9.0, 4.0, 7.0, 2.0])
    x0 = np.stack([starts, np.ones(5)], axis=1)
    inner = NormalizedLinearPolicy(2, 1)
    thetas = np.array([[0.0, 0.5]] * 5)  # u = 0.5 (the second observation is 1)
    ep = run_episodes(env, inner, thetas, x0, episode_length=8, chunk=chunk)
    lengths = np.minimum(10 - starts, 8)  # start 0 and 2 run out of time first
    np.testing.assert_array_equal(ep.lengths, lengths)
    np.testing.assert_array_equal(ep.terminated, 10 - starts <= 8)
    np.testing.assert_allclose(ep.returns, 1.5 * lengths)
    # the observations acted on: p = start .. start + L - 1, episode after episode
    acted = np.concatenate([s + np.arange(L) for s, L in zip(starts, lengths, strict=True)])
    np.testing.assert_array_equal(ep.observations[:, 0], acted)
    assert ep.used.all() and ep.unconverged == 0

    config = ArsConfig(directions=3, top=2, shift=1.0, episode_length=4, chunk=chunk)
    trainer = ArsTrainer(env, config, seed=0)
    rows = trainer.train(3)
    rng = np.random.default_rng(0)  # the first iteration's draws: directions, then the starts
    rng.standard_normal((3, 2))
    to_goal = 10 - env.initial_states(rng, 3)[:, 0]
    assert sorted(to_goal) == [1, 4, 5]  # ends early, at the last step, and runs out of time
    assert rows[0]["iteration_env_steps"] == 2 * np.minimum(to_goal, 4).sum()
    assert rows[0]["terminated"] == 2 * np.sum(to_goal <= 4)
    assert trainer.state.env_steps == sum(r["iteration_env_steps"] for r in rows)
    assert trainer.state.normalizer.count == trainer.state.env_steps
    assert trainer.state.normalizer.mean[0] < 9.0  # p = 10 (terminal) was never acted on
    assert all(r["length_mean"] <= 4 for r in rows)


# ----- resuming, seeds, settings ------------------------------------------------------------------


def _same_rows(a, b):
    assert len(a) == len(b)
    for ra, rb in zip(a, b, strict=True):
        assert {k: v for k, v in ra.items() if k != "seconds"} == {
            k: v for k, v in rb.items() if k != "seconds"
        }


def test_a_resumed_run_gives_the_numbers_of_an_uninterrupted_one(tmp_path):
    env = PointMassEnv()
    config = ArsConfig(directions=4, top=2, step_size=0.05, noise=0.1, shift=0.0,
                       episode_length=40, chunk=9)  # fmt: skip
    whole = ArsTrainer(env, config, seed=7)
    whole.train(6)
    path = tmp_path / "ars.ckpt"
    first = ArsTrainer(env, config, seed=7)
    first.train(2, checkpoint=path, checkpoint_every=1)
    first.train(3, checkpoint=path)
    resumed = ArsTrainer.load(path, env)
    assert resumed.state.iteration == 3
    resumed.train(6)
    np.testing.assert_array_equal(resumed.state.theta, whole.state.theta)
    for key, value in whole.state.normalizer.state().items():
        np.testing.assert_array_equal(resumed.state.normalizer.state()[key], value)
    assert resumed.state.env_steps == whole.state.env_steps
    _same_rows(resumed.state.rows, whole.state.rows)
    assert resumed.state.rng.bit_generator.state == whole.state.rng.bit_generator.state

    again = ArsTrainer(env, config, seed=7)
    again.train(6)
    np.testing.assert_array_equal(again.state.theta, whole.state.theta)
    other = ArsTrainer(env, config, seed=8)
    other.train(2)
    assert not np.array_equal(other.state.theta, ArsTrainer(env, config, seed=7).state.theta)
    assert not np.array_equal(
        other.state.rows[0]["return_mean"], whole.state.rows[0]["return_mean"]
    )

    limited = ArsTrainer(env, config, seed=7)
    rows = limited.train(100, max_env_steps=300)
    assert rows[-1]["env_steps"] >= 300 and (len(rows) == 1 or rows[-2]["env_steps"] < 300)
    with pytest.raises(ValueError, match="ars checkpoint"):
        (tmp_path / "other").write_bytes(b"not a checkpoint")
        ArsTrainer.load(tmp_path / "other", env)


def test_published_settings_and_bad_arguments():
    hopper = ArsConfig.published("Hopper-v5")
    assert (hopper.step_size, hopper.directions, hopper.top, hopper.noise, hopper.shift) == (
        0.01, 8, 4, 0.025, 1.0,
    )  # fmt: skip
    assert ArsConfig.published("HalfCheetah-v5").shift == 0.0
    assert ArsConfig.published("Walker2d-v5").top == 30
    assert ArsConfig.published("Ant-v5", directions=4, top=2).directions == 4
    with pytest.raises(ValueError, match="no published ARS settings"):
        ArsConfig.published("Humanoid-v5")
    with pytest.raises(ValueError, match="top must be in"):
        ArsConfig(directions=2, top=3)
    with pytest.raises(ValueError, match="shift"):
        ArsConfig(shift=float("nan"))
    with pytest.raises(ValueError, match="noise"):
        ArsConfig(noise=0.0)
    with pytest.raises(ValueError, match="theta0"):
        ArsTrainer(PointMassEnv(), ArsConfig(), 0, theta0=np.zeros(3))
    with pytest.raises(TypeError, match="env must have"):
        ArsTrainer(object(), ArsConfig(), 0)


# ----- the Hopper, exported ----------------------------------------------------------------------


def test_a_tiny_hopper_run_exports_the_policy_it_trained(tmp_path):
    gymnasium = pytest.importorskip("gymnasium")
    pytest.importorskip("mujoco")
    from drake_abs.policy.policy_files import load_policy_file
    from drake_abs.tasks.locomotion import locomotion_task
    from drake_abs.tasks.published_policies import task_policy_file

    task = locomotion_task("hopper")
    config = ArsConfig.published("Hopper-v5", directions=2, top=1, episode_length=30)
    trainer = ArsTrainer(task, config, seed=0)
    rows = trainer.train(3)
    assert len(rows) == 3 and all(np.isfinite(r["return_mean"]) for r in rows)
    assert rows[-1]["env_steps"] == sum(r["iteration_env_steps"] for r in rows) <= 3 * 4 * 30
    theta = trainer.state.theta
    assert np.any(theta != 0) and trainer.state.normalizer.count == rows[-1]["env_steps"]
    file = task_policy_file(task, trainer.full_state_policy(), theta, method="ars", seed=0,
                            training_steps=rows[-1]["env_steps"])  # fmt: skip
    loaded = load_policy_file(file.save(tmp_path / "seed0.npz"))

    env = gymnasium.make("Hopper-v5")  # gymnasium's own observations along a few episodes
    obs, rng = [], np.random.default_rng(0)
    for seed in range(3):
        o, _ = env.reset(seed=seed)
        for _ in range(20):
            obs.append(o)
            o, _, terminated, _, _ = env.step(rng.uniform(-1, 1, 3))
            if terminated:
                break
    env.close()
    obs = np.array(obs)
    ours = np.clip(trainer.inner_policy().act(theta, obs), -1, 1)
    assert np.ptp(ours) > 0
    np.testing.assert_allclose(loaded.act(obs), ours, rtol=0, atol=1e-12)
    assert loaded.metadata["env_id"] == "Hopper-v5" and loaded.metadata["method"] == "ars"
