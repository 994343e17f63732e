"""Policy files and the locomotion tasks (drake_abs.tasks.published_policies).

A file written from a task's policy acts, on gymnasium's own observation of a state, as the
task's policy acts on that state; the task's observation is gymnasium's; full-state ARS
policies are written only where they are policies of the observation; a file's score on our
plant is the score of gymnasium's loop over our plant (DrakeAbsEnv), and its MuJoCo score
(gym_scoring) is the engine's episodes on the MuJoCo stepper.
"""

from __future__ import annotations

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from drake_abs.policy.ars_v2 import NormalizedLinearPolicy  # noqa: E402
from drake_abs.policy.policies import LinearPolicy, MLPPolicy  # noqa: E402
from drake_abs.policy.policy_files import PolicyFile, load_policy_file  # noqa: E402
from drake_abs.reference.gym_scoring import score_policy  # noqa: E402
from drake_abs.reference.gymnasium_mujoco import reset_states  # noqa: E402
from drake_abs.reference.mujoco_plant import MujocoStepper  # noqa: E402
from drake_abs.tasks.episodes import score_episodes  # noqa: E402
from drake_abs.tasks.gym_env import register_envs  # noqa: E402
from drake_abs.tasks.locomotion import locomotion_task  # noqa: E402
from drake_abs.tasks.published_policies import (  # noqa: E402
    file_policy,
    load_for_task,
    score_on_plant,
    task_name_for_env,
    task_policy_file,
)
from drake_abs.tasks.saved_policies import reset_state, run_episode  # noqa: E402

ENVS = {"hopper": "Hopper-v5", "half_cheetah": "HalfCheetah-v5"}


@pytest.fixture(scope="module")
def tasks():
    return {name: locomotion_task(name) for name in ENVS}


def _gym_states_and_obs(env_id: str, rng, count: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """States x = (qpos, qvel) and gymnasium's observation of each: reset states and random
    ones with large velocities (beyond the Hopper's clip at 10)."""
    env = gymnasium.make(env_id)
    raw = env.unwrapped
    xs, obs = [], []
    for k in range(count):
        env.reset(seed=k)
        if k % 2:
            raw.set_state(raw.init_qpos + 0.1 * rng.standard_normal(raw.model.nq),
                          15.0 * rng.standard_normal(raw.model.nv))  # fmt: skip
        xs.append(np.concatenate([raw.data.qpos, raw.data.qvel]))
        obs.append(raw._get_obs())
    env.close()
    return np.array(xs), np.array(obs)


def test_env_ids_name_their_tasks():
    assert {env: task_name_for_env(env) for env in ENVS.values()} == {v: k for k, v in ENVS.items()}
    with pytest.raises(ValueError, match="env_id 'Humanoid-v5' has no scene on our plant"):
        task_name_for_env("Humanoid-v5")


@pytest.mark.parametrize("name", list(ENVS))
def test_the_tasks_observation_is_gymnasiums(name, tasks, rng):
    task = tasks[name]
    xs, obs = _gym_states_and_obs(ENVS[name], rng)
    np.testing.assert_array_equal(task.observation(xs), obs)
    if name == "hopper":
        assert np.any(np.abs(xs[:, 6:]) > 10)  # the clip is exercised


@pytest.mark.parametrize("name", list(ENVS))
@pytest.mark.parametrize("kind", ["linear", "mlp", "ars"])
def test_a_file_acts_on_gymnasiums_observation_as_the_task_policy_on_the_state(
    name, kind, tasks, rng, tmp_path
):
    task = tasks[name]
    if kind == "linear":
        inner = LinearPolicy(task.n_obs, task.nu)
        theta = 0.2 * rng.standard_normal(inner.n_params)
    elif kind == "mlp":
        inner = MLPPolicy(task.n_obs, task.nu, hidden=(16,), output_scale=2.0)
        theta = inner.init(rng)
    else:
        mean, std = rng.standard_normal(task.n_obs), rng.uniform(0.5, 3.0, task.n_obs)
        inner = NormalizedLinearPolicy(task.n_obs, task.nu, mean=mean, std=std, bias=True)
        theta = 0.3 * rng.standard_normal(inner.n_params)
    policy = task.policy(inner)
    file = task_policy_file(task, policy, theta, method="test", seed=1)
    assert dict(file.metadata) | {"drake_abs_version": "-"} == {
        "env_id": ENVS[name], "method": "test", "seed": 1, "policy_kind": type(inner).__name__,
        "drake_abs_version": "-",
    }  # fmt: skip
    back = load_policy_file(file.save(tmp_path / f"{name}.npz"))
    xs, obs = _gym_states_and_obs(ENVS[name], rng)
    ours = np.clip(policy.act(theta, xs), -1.0, 1.0)
    np.testing.assert_allclose(back.act(obs), ours, rtol=1e-12, atol=1e-13)
    assert np.any(np.abs(ours) == 1.0) and np.any(np.abs(ours) < 1.0)  # clipped and free
    # and as the task's full-state policy of the file (theta empty)
    np.testing.assert_allclose(file_policy(task, back).act(np.zeros(0), xs), ours, rtol=1e-12,
                               atol=1e-13)  # fmt: skip


def test_full_state_ars_policies_are_written_only_when_exact(tasks, rng):
    cheetah, hopper = tasks["half_cheetah"], tasks["hopper"]
    policy = NormalizedLinearPolicy(cheetah.nx, cheetah.nu, mean=rng.standard_normal(cheetah.nx),
                                    std=rng.uniform(0.5, 2.0, cheetah.nx))  # fmt: skip
    theta = rng.standard_normal(policy.n_params)
    with pytest.raises(ValueError, match=r"nonzero weights on state entries \[0\]"):
        task_policy_file(cheetah, policy, theta)
    theta.reshape(cheetah.nu, cheetah.nx)[:, 0] = 0.0  # no weight on the forward position
    file = task_policy_file(cheetah, policy, theta)
    xs, obs = _gym_states_and_obs("HalfCheetah-v5", rng)
    np.testing.assert_allclose(file.output(obs), policy.act(theta, xs), rtol=1e-12, atol=1e-13)
    # the same with the forward position's std below min_std (ARS drops it): exact too
    dropped = policy.with_stats(policy.mean, np.where(np.arange(cheetah.nx) == 0, 0.0,
                                                      policy.std))  # fmt: skip
    task_policy_file(cheetah, dropped, rng.standard_normal(policy.n_params))
    hop = NormalizedLinearPolicy(hopper.nx, hopper.nu)
    with pytest.raises(ValueError, match=r"clips the velocities at \+-10.0"):
        task_policy_file(hopper, hop, np.zeros(hop.n_params))


def test_policies_that_do_not_fit_are_refused(tasks):
    hopper, cheetah = tasks["hopper"], tasks["half_cheetah"]
    inner = LinearPolicy(hopper.n_obs, hopper.nu)
    with pytest.raises(ValueError, match="not task 'half_cheetah''s observation"):
        task_policy_file(cheetah, hopper.policy(inner), np.zeros(inner.n_params))
    with pytest.raises(ValueError, match=r"a policy of the full state \(nx = 18\)"):
        task_policy_file(cheetah, inner, np.zeros(inner.n_params))
    wrong = PolicyFile.linear(np.zeros((3, 17)), np.zeros(3))
    with pytest.raises(ValueError, match=r"maps 17 observations to 3 actions; task 'hopper'"):
        file_policy(hopper, wrong)


def test_a_files_plant_score_is_gymnasiums_loop_over_our_plant(tasks, rng):
    """score_on_plant (the engine's episodes) against gymnasium's own loop over DrakeAbsEnv
    (drake_abs/Hopper-v0) from the same reset seeds, through gym_scoring."""
    task = tasks["hopper"]
    inner = LinearPolicy(task.n_obs, task.nu)
    file = task_policy_file(task, task.policy(inner), 0.3 * rng.standard_normal(inner.n_params))
    seeds, steps = [0, 3], 60
    ours = score_on_plant(task, file, seeds=seeds, max_steps=steps)
    register_envs()
    loop = score_policy(file.output, "drake_abs/Hopper-v0", seeds=seeds, max_steps=steps)
    assert ours["lengths"] == loop["lengths"] and ours["terminated"] == loop["terminated"]
    np.testing.assert_allclose(ours["returns"], loop["returns"], rtol=1e-12)
    assert ours["unconverged_episodes"] == 0 and ours["dt"] == task.dt
    assert ours["mean"] == pytest.approx(np.mean(ours["returns"]), rel=1e-15)


@pytest.mark.parametrize("name", list(ENVS))
def test_a_files_mujoco_score_is_the_engines_episodes_on_mujoco(name, tasks, rng):
    """gym_scoring's env.step loop against score_episodes on gymnasium's MuJoCo model."""
    task = tasks[name]
    inner = LinearPolicy(task.n_obs, task.nu)
    file = task_policy_file(task, task.policy(inner), 0.3 * rng.standard_normal(inner.n_params))
    seeds, steps = [1, 2], 50
    theirs = score_policy(file.output, ENVS[name], seeds=seeds, max_steps=steps)
    stepper = MujocoStepper.from_gymnasium(ENVS[name])
    engine = score_episodes(task, file_policy(task, file), np.zeros(0),
                            reset_states(ENVS[name], seeds), steps, stepper=stepper)  # fmt: skip
    np.testing.assert_allclose([e["return"] for e in engine], theirs["returns"], rtol=1e-12)
    assert [e["length"] for e in engine] == theirs["lengths"]


def test_load_for_task_runs_on_our_plant(tasks, rng, tmp_path):
    task = tasks["half_cheetah"]
    inner = LinearPolicy(task.n_obs, task.nu)
    theta = 0.2 * rng.standard_normal(inner.n_params)
    path = task_policy_file(task, task.policy(inner), theta).save(tmp_path / "c.npz")
    saved = load_for_task(path, task=task)
    assert saved.task is task and saved.theta.shape == (0,) and saved.acts_on == "observation"
    episode = run_episode(task, saved.policy, saved.theta, reset_state(task, 0), 5)
    expected = run_episode(task, task.policy(inner), theta, reset_state(task, 0), 5)
    np.testing.assert_allclose(episode.states, expected.states, rtol=1e-12, atol=1e-12)
    bare = PolicyFile.linear(np.zeros((task.nu, task.n_obs)), np.zeros(task.nu)).save(
        tmp_path / "bare.npz"
    )
    with pytest.raises(ValueError, match="names no env_id"):
        load_for_task(bare)
    with pytest.raises(ValueError, match="models HalfCheetah-v5, not env_id 'Hopper-v5'"):
        load_for_task(bare, env_id="Hopper-v5", task=task)
