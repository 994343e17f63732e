"""Baselines of stable-baselines3 and sb3-contrib trained on our plant
(drake_abs.tasks.sb3_baselines).

The settings are the RL Baselines3 Zoo's numbers with options laid over them. A tiny training run
of each algorithm on the Hopper (a few hundred environment steps) stops at the budget (PPO and
SAC exactly; ARS at the end of its iteration), logs its rows, and is bit-reproducible with its
seed. The exported policy file acts as the library's own ``predict(normalize_obs(o),
deterministic=True)`` (to 1e-6 in the library's float32 at observations within a few standard
deviations; to 1e-12 against a float64 forward pass of the library's own modules, far from the
statistics too: no clip of the normalised observation anywhere), and it scores in MuJoCo's own
Hopper-v5 as the library's model does there. Needs stable-baselines3 and sb3-contrib (the
``baselines`` extra): skipped without them.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

pytest.importorskip("gymnasium")

from drake_abs.tasks.sb3_baselines import (  # noqa: E402
    ZOO_SETTINGS,
    TrainingLog,
    baseline_settings,
    sb3_policy_file,
    train_baseline,
    vectorised_hyperparameters,
)

#: Tiny runs: a PPO rollout of 64 steps, SAC's first 100 steps random, two ARS directions.
TINY = {
    "ppo": {"n_steps": 64, "batch_size": 32},
    "sac": {"learning_starts": 100},
    "ars": {"n_delta": 2, "n_top": 1},
}
BUDGET, LOG_EVERY = 250, 50


def _libraries():
    pytest.importorskip("stable_baselines3")
    pytest.importorskip("sb3_contrib")
    return pytest.importorskip("torch")


# ------------------------------------------------------------------------------------ settings


def test_the_settings_are_the_zoos_with_options_laid_over():
    ppo = baseline_settings("hopper", "ppo")
    assert ppo["source"].endswith("ppo.yml (commit 208b6fd), Hopper-v4")
    h = ppo["hyperparameters"]
    assert (h["n_steps"], h["batch_size"], h["gamma"], h["learning_rate"]) == (
        512, 32, 0.999, 9.80828e-05)  # fmt: skip
    assert h["policy_kwargs"]["net_arch"] == {"pi": [256, 256], "vf": [256, 256]}
    assert ppo["normalize"] == {"clip_obs": np.inf, "norm_obs": True, "norm_reward": True}
    assert baseline_settings("half_cheetah", "ppo")["hyperparameters"]["n_epochs"] == 20
    assert baseline_settings("hopper", "sac") == {
        "source": "rl-baselines3-zoo hyperparams/sac.yml (commit c94924e), Hopper-v3",
        "hyperparameters": {"learning_starts": 10000}, "normalize": None,
    }  # fmt: skip
    ars = baseline_settings("half_cheetah", "ars", {"n_delta": 4, "normalize": {"clip_obs": 5}})
    assert ars["hyperparameters"] == {"policy": "LinearPolicy", "learning_rate": 0.02,
                                      "delta_std": 0.03, "n_delta": 4, "n_top": 4,
                                      "alive_bonus_offset": 0.0}  # fmt: skip
    assert ars["normalize"] == {"clip_obs": 5, "norm_obs": True, "norm_reward": False}
    assert baseline_settings("hopper", "ppo", {"normalize": False})["normalize"] is None
    assert baseline_settings("hopper", "sac", {"normalize": {}})["normalize"] == {
        "clip_obs": np.inf}  # fmt: skip
    assert all(set(table) == {"hopper", "half_cheetah", "walker2d", "ant"}
               for table in ZOO_SETTINGS.values())  # fmt: skip


def test_bad_names_and_options_are_refused():
    with pytest.raises(ValueError, match=r"algorithm must be one of \['ppo', 'sac', 'ars'\]"):
        baseline_settings("hopper", "td3")
    with pytest.raises(ValueError, match="task_name must be one of"):
        baseline_settings("swimmer", "ppo")
    with pytest.raises(ValueError, match=r"algorithm_options\['normalize'\] must be a dict"):
        baseline_settings("hopper", "ppo", {"normalize": True})
    with pytest.raises(ValueError, match="env_steps must be"):
        train_baseline("hopper", "ppo", 0, 0)
    with pytest.raises(ValueError, match="seed must be a whole number >= 0"):
        train_baseline("hopper", "ppo", -1, 10)


# ------------------------------------------------------------------------------- tiny training


@pytest.fixture(scope="module")
def runs():
    """One tiny run of each algorithm on the Hopper, seed 3."""
    _libraries()
    return {algo: train_baseline("hopper", algo, 3, BUDGET, algorithm_options=TINY[algo],
                                 log_every=LOG_EVERY) for algo in TINY}  # fmt: skip


@pytest.mark.parametrize("algo", list(TINY))
def test_a_tiny_run_keeps_to_its_budget_and_logs_its_rows(algo, runs):
    run = runs[algo]
    if algo == "ars":  # whole iterations of 2 n_delta episodes: over by less than one
        assert BUDGET <= run.env_steps < BUDGET + 2 * TINY["ars"]["n_delta"] * 1000
    elif algo == "ppo":  # whole rollouts of n_steps
        assert run.env_steps == -(-BUDGET // 64) * 64
    else:
        assert run.env_steps == BUDGET
    assert run.model.num_timesteps == run.env_steps  # the library counts the same steps
    assert not run.stopped_early
    steps = [row["env_steps"] for row in run.rows]
    assert steps[: BUDGET // LOG_EVERY] == list(range(LOG_EVERY, BUDGET + 1, LOG_EVERY))
    assert steps[-1] == run.env_steps and steps == sorted(set(steps))
    seconds = [row["seconds"] for row in run.rows]
    assert seconds == sorted(seconds) and 0 < seconds[-1] <= run.seconds
    assert sum(row["episodes"] for row in run.rows) >= 1
    for row in run.rows:
        assert (row["return_mean"] is None) == (row["episodes"] == 0)
        if row["episodes"]:
            assert np.isfinite(row["return_mean"]) and 1 <= row["length_mean"] <= 1000
    assert run.unconverged == run.rows[-1]["unconverged"] >= 0
    assert run.env_id == "Hopper-v5" and run.settings == baseline_settings(
        "hopper", algo, TINY[algo])  # fmt: skip


def _observations(run, rng, scale, M=200):
    vn = run.vec_normalize
    mean = np.zeros(11) if vn is None else vn.obs_rms.mean
    std = np.ones(11) if vn is None else np.sqrt(vn.obs_rms.var)
    return mean + scale * std * rng.standard_normal((M, 11))


def _library_float64(run, obs):
    """The deterministic action by the library's own torch modules, in float64 (written out per
    algorithm here, apart from the module's export)."""
    torch = _libraries()
    vn = run.vec_normalize
    z = obs if vn is None else (obs - vn.obs_rms.mean) / np.sqrt(vn.obs_rms.var + vn.epsilon)
    x = torch.as_tensor(z, dtype=torch.float64)
    policy = copy.deepcopy(run.model.policy).double()
    with torch.no_grad():
        if run.algorithm == "ppo":
            out = policy.action_net(policy.mlp_extractor.policy_net(x))
        elif run.algorithm == "sac":
            out = torch.tanh(policy.actor.mu(policy.actor.latent_pi(x)))
        else:
            out = policy.action_net(x)
    return np.clip(out.numpy(), -1.0, 1.0)


@pytest.mark.parametrize("algo", list(TINY))
def test_the_exported_file_acts_as_the_librarys_predict(algo, runs, rng, tmp_path):
    run = runs[algo]
    file = run.policy_file()
    expected = {"env_id": "Hopper-v5", "method": f"sb3_{algo}", "seed": 3,
                "training_steps": run.env_steps}  # fmt: skip
    assert dict(file.metadata).items() >= expected.items()
    assert (file.kind, file.output_activation) == {
        "ppo": ("mlp", None), "sac": ("mlp", "tanh"), "ars": ("linear", None)}[algo]  # fmt: skip
    vn = run.vec_normalize
    assert (vn is None) == (algo == "sac") and (vn is None or vn.clip_obs == np.inf)
    obs = _observations(run, rng, 2.0)
    inputs = obs if vn is None else vn.normalize_obs(obs)
    predicted, _ = run.model.predict(inputs, deterministic=True)
    actions = file.act(obs)
    np.testing.assert_allclose(actions, predicted, rtol=0, atol=1e-6)
    inside = np.abs(actions) < 1.0
    assert inside.mean() > 0.2 and np.std(actions[inside]) > 1e-3  # not all clipped, not constant
    far = _observations(run, rng, 100.0)  # |z| up to ~400: a clip at 10 would change actions
    both = np.concatenate([obs, far])
    np.testing.assert_allclose(file.act(both), _library_float64(run, both), rtol=0, atol=1e-12)
    back = type(file).from_arrays(np.load(file.save(tmp_path / "seed3.npz")))
    np.testing.assert_array_equal(back.act(both), file.act(both))


@pytest.mark.parametrize("algo", list(TINY))
def test_the_exported_file_scores_in_mujoco_as_the_librarys_model(algo, runs):
    pytest.importorskip("mujoco")
    from drake_abs.reference.gym_scoring import score_policy

    run = runs[algo]
    vn = run.vec_normalize

    def library(o):
        inputs = o[None] if vn is None else vn.normalize_obs(o[None])
        return run.model.predict(inputs, deterministic=True)[0][0]

    file = score_policy(run.policy_file().act, "Hopper-v5", seeds=[0, 1], max_steps=40)
    own = score_policy(library, "Hopper-v5", seeds=[0, 1], max_steps=40)
    assert file["lengths"] == own["lengths"] and all(1 <= n <= 40 for n in file["lengths"])
    np.testing.assert_allclose(file["returns"], own["returns"], rtol=1e-5)
    assert np.all(np.isfinite(file["returns"]))


def test_runs_are_bit_reproducible_with_their_seed(runs):
    for algo in TINY:
        again = train_baseline("hopper", algo, 3, BUDGET, algorithm_options=TINY[algo],
                               log_every=LOG_EVERY)  # fmt: skip
        a, b = runs[algo].policy_file().arrays(), again.policy_file().arrays()
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=f"{algo}: {key}")
        keep = ("env_steps", "episodes", "return_mean", "length_mean", "unconverged")
        assert [{k: r[k] for k in keep} for r in runs[algo].rows] == [
            {k: r[k] for k in keep} for r in again.rows]  # fmt: skip
    other = train_baseline("hopper", "ars", 4, BUDGET, algorithm_options=TINY["ars"])
    assert not np.array_equal(other.policy_file().weights[0], runs["ars"].policy_file().weights[0])


@pytest.mark.parametrize("algo", ["ppo", "ars"])
def test_max_seconds_stops_a_run_on_the_wall_clock(algo):
    _libraries()
    run = train_baseline("hopper", algo, 0, 10**6, algorithm_options=TINY[algo], log_every=10,
                         max_seconds=1.0)  # fmt: skip
    assert run.stopped_early and 0 < run.env_steps < 10**6
    assert 1.0 <= run.seconds < 10.0 and run.rows[-1]["env_steps"] == run.env_steps
    assert np.all(np.isfinite(run.policy_file().weights[0]))
    with pytest.raises(ValueError, match="max_seconds must be a number > 0"):
        train_baseline("hopper", algo, 0, 10, max_seconds=0)


# ---------------------------------------------------------------------------- what is refused


def test_a_finite_observation_clip_is_not_exported(runs):
    run = runs["ppo"]
    clipped = copy.deepcopy(run.vec_normalize)
    clipped.clip_obs = 10.0  # the zoo's default: the format cannot clip z
    with pytest.raises(ValueError, match=r"clips the normalised observation at \+-10\.0"):
        sb3_policy_file(run.model, clipped)
    with pytest.raises(ValueError, match="model must be a stable-baselines3 PPO or SAC"):
        sb3_policy_file(type("Model", (), {"action_space": run.model.action_space,
                                           "policy": run.model.policy})())  # fmt: skip


def test_other_actor_architectures_export_exactly(rng):
    """PPO's default actor (tanh hidden layers) and ARS's MLP (relu, squashed by a Tanh module)
    as built by the libraries, untrained, on MuJoCo's Hopper-v5 spaces."""
    torch = _libraries()
    gymnasium = pytest.importorskip("gymnasium")
    pytest.importorskip("mujoco")
    from sb3_contrib import ARS
    from stable_baselines3 import PPO

    torch.manual_seed(0)
    env = gymnasium.make("Hopper-v5")
    ppo = PPO("MlpPolicy", env, device="cpu", seed=0)
    ars = ARS("MlpPolicy", env, device="cpu", seed=0, zero_policy=False,
              policy_kwargs={"net_arch": [16]})  # fmt: skip
    obs = 2.0 * rng.standard_normal((100, 11))
    for model, kind in ((ppo, ("tanh", None)), (ars, ("relu", "tanh"))):
        file = sb3_policy_file(model)
        assert (file.activation, file.output_activation) == kind
        predicted, _ = model.predict(obs.astype(np.float32), deterministic=True)
        np.testing.assert_allclose(file.act(obs.astype(np.float32)), predicted, rtol=0,
                                   atol=1e-6)  # fmt: skip


# ------------------------------------------------------------------ several environments at once


def test_the_hyperparameters_keep_the_data_per_update_with_n_envs():
    ppo = baseline_settings("hopper", "ppo", n_envs=8)["hyperparameters"]
    assert (ppo["n_steps"], ppo["batch_size"], ppo["n_epochs"]) == (64, 32, 5)  # 8 x 64 = 512
    assert baseline_settings("hopper", "ppo", n_envs=1) == baseline_settings("hopper", "ppo")
    with pytest.raises(ValueError, match="n_envs must divide PPO's n_steps = 512"):
        baseline_settings("hopper", "ppo", n_envs=3)
    with pytest.raises(ValueError, match="n_envs must be 1 for ARS"):
        baseline_settings("hopper", "ars", n_envs=2)


def test_sacs_gradient_steps_follow_n_envs():
    pytest.importorskip("stable_baselines3")  # SAC's own defaults are read from the library
    sac = baseline_settings("half_cheetah", "sac", n_envs=16)["hyperparameters"]
    assert sac == {"learning_starts": 10000, "gradient_steps": 16}
    assert vectorised_hyperparameters("sac", {"gradient_steps": -1}, 4) == {"gradient_steps": -1}
    assert vectorised_hyperparameters("sac", {"train_freq": 4, "gradient_steps": 2}, 4) == {
        "train_freq": 4, "gradient_steps": 8}  # fmt: skip
    with pytest.raises(ValueError, match="train_freq must count steps"):
        vectorised_hyperparameters("sac", {"train_freq": (1, "episode")}, 2)
    with pytest.raises(ValueError, match="n_envs must be"):
        train_baseline("hopper", "ppo", 0, 10, n_envs=0)
    with pytest.raises(ValueError, match="n_envs must be 1 for ARS"):
        train_baseline("hopper", "ars", 0, 10, n_envs=2)
    _libraries()  # the library's defaults where the zoo has none (Ant: PPO's own n_steps 2048)
    assert baseline_settings("ant", "ppo", n_envs=16)["hyperparameters"] == {"n_steps": 128}


def test_the_log_counts_every_environment():
    log = TrainingLog(log_every=5, n_envs=3)
    info = [{"converged": True}, {"converged": False}, {}]
    log.record([1.0, 2.0, 3.0], [False, True, False], info)  # env 1 ends (return 2, length 1)
    log.record([1.0, 1.0, 1.0], [True, False, True], info)  # 6 steps: a row
    assert (log.steps, log.unconverged, log.returns, log.lengths) == (6, 2, [2.0, 2.0, 4.0],
                                                                      [1, 2, 2])  # fmt: skip
    assert [(r["env_steps"], r["episodes"], r["return_mean"]) for r in log.rows] == [
        (6, 3, 8.0 / 3)]  # fmt: skip
    log.record([0.5] * 3, [False] * 3, info)  # 9: no row
    log.record([0.5] * 3, [False] * 3, info)  # 12 passes 10: a row, no episode
    assert [(r["env_steps"], r["episodes"], r["length_mean"]) for r in log.rows][1:] == [
        (12, 0, None)]  # fmt: skip
    with pytest.raises(ValueError, match="must have n_envs = 3 entries"):
        log.record([1.0], [False], info[:1])


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_a_tiny_run_on_several_environments(algo):
    """PPO: rollouts of 2 x 32 = 64 steps (the same 64 as one environment's TINY rollout); SAC:
    2 gradient steps after each step of the two environments."""
    _libraries()
    run = train_baseline("hopper", algo, 3, BUDGET, algorithm_options=TINY[algo],
                         log_every=LOG_EVERY, n_envs=2)  # fmt: skip
    assert run.n_envs == 2 and run.model.n_envs == 2
    assert run.settings == baseline_settings("hopper", algo, TINY[algo], n_envs=2)
    if algo == "ppo":
        assert run.model.n_steps == 32 and run.env_steps == -(-BUDGET // 64) * 64
    else:
        assert run.model.gradient_steps == 2 and run.env_steps == BUDGET
    assert run.model.num_timesteps == run.env_steps
    steps = [row["env_steps"] for row in run.rows]
    assert steps[: BUDGET // LOG_EVERY] == list(range(LOG_EVERY, BUDGET + 1, LOG_EVERY))
    assert steps[-1] == run.env_steps and sum(row["episodes"] for row in run.rows) >= 2
    assert run.policy_file().metadata["n_envs"] == 2
    again = train_baseline("hopper", algo, 3, BUDGET, algorithm_options=TINY[algo],
                           log_every=LOG_EVERY, n_envs=2)  # fmt: skip
    for key, value in run.policy_file().arrays().items():
        np.testing.assert_array_equal(value, again.policy_file().arrays()[key], err_msg=key)


# -------------------------------------------------------------------------------- resumable runs


def _trainer(algo, seed=5, algorithm_options=None, **options):
    from drake_abs.tasks.sb3_baselines import Sb3Trainer

    chunk = {"ppo": None, "sac": 60, "ars": None}[algo]
    return Sb3Trainer("hopper", algo, seed, algorithm_options=algorithm_options or TINY[algo],
                      log_every=LOG_EVERY, chunk=chunk, **options)  # fmt: skip


@pytest.mark.parametrize(("algo", "n_envs"), [("ppo", 1), ("ppo", 2), ("sac", 2), ("ars", 1)])
def test_a_run_saved_and_loaded_between_chunks_is_the_run_never_stopped(algo, n_envs, tmp_path):
    """Three chunks in one go against one chunk, a checkpoint, a new trainer loaded from it, two
    chunks: the same policy, normalisation, log and step counts, to the last bit. SAC's chunks
    of 60 steps cross its first update (after 100 random steps); the checkpoint falls inside an
    episode for PPO and SAC (the environments' states and generators carry over)."""
    _libraries()
    whole = _trainer(algo, n_envs=n_envs)
    for _ in range(3):
        whole.iterate()
    part = _trainer(algo, n_envs=n_envs)
    part.iterate()
    if algo != "ars":  # ARS's iterations end with their episodes
        assert (part.raw_env.episode_steps > 0).any()  # mid-episode
    part.save(tmp_path / "run.pkl")
    other = _trainer(algo, n_envs=n_envs)  # another object, drawing nothing yet
    resumed = other.load(tmp_path / "run.pkl")
    assert resumed.state.iteration == 1 and resumed.state.env_steps == part.state.env_steps
    for _ in range(2):
        resumed.iterate()
    assert resumed.state.env_steps == whole.state.env_steps
    assert resumed.model.num_timesteps == whole.model.num_timesteps
    a, b = whole.policy_file().arrays(), resumed.policy_file().arrays()
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=f"{algo}: {key}")
    if whole.vec_normalize is not None:
        np.testing.assert_array_equal(whole.vec_normalize.returns, resumed.vec_normalize.returns)
    np.testing.assert_array_equal(whole.raw_env.states, resumed.raw_env.states)
    keep = ("env_steps", "episodes", "return_mean", "length_mean", "unconverged")
    assert [{k: r[k] for k in keep} for r in whole.state.rows] == [
        {k: r[k] for k in keep} for r in resumed.state.rows]  # fmt: skip
    assert resumed.state.seconds > part.state.seconds > 0


def test_a_checkpoint_of_another_run_or_a_schedule_is_refused(tmp_path):
    _libraries()
    run = _trainer("ppo")
    run.iterate()
    run.save(tmp_path / "run.pkl")
    other = _trainer("ppo", seed=6)
    with pytest.raises(ValueError, match="path holds a run of"):
        other.load(tmp_path / "run.pkl")
    with pytest.raises(ValueError, match="must be a 'drake-abs sb3 checkpoint' file"):
        other.load(tmp_path / "missing.pkl")
    with pytest.raises(ValueError, match=r"algorithm_options\['learning_rate'\] must be a const"):
        _trainer("ppo", algorithm_options={"learning_rate": lambda p: 1e-4 * p})
