"""DrakeAbsVecEnv (drake_abs.tasks.sb3_vec_env): n_envs copies of a task in one batched step.

It gives what sb3's ``DummyVecEnv`` of n_envs independent ``DrakeAbsEnv`` gives, for the same
actions and seed: observations, float64 rewards, dones, infos (``converged``,
``TimeLimit.truncated``, ``terminal_observation``), reset infos and states, bit for bit, over
episodes that end by termination and by truncation and through steps whose contact solve did
not converge (the batched solve of our scenes rounds exactly as a batch of one: equality, not a
tolerance). Inside stable-baselines3, PPO and SAC trained on it and on the ``DummyVecEnv`` end
with the same parameters to the last bit. Needs stable-baselines3: skipped without it.
"""

from __future__ import annotations

import dataclasses

import gymnasium
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402

from drake_abs.lcp.ipm import LCPConvergenceWarning  # noqa: E402
from drake_abs.tasks.gym_env import DrakeAbsEnv  # noqa: E402
from drake_abs.tasks.locomotion import locomotion_task  # noqa: E402
from drake_abs.tasks.sb3_vec_env import DrakeAbsVecEnv  # noqa: E402

N_ENVS, EPISODE = 4, 25


@pytest.fixture(scope="module")
def hopper():
    return locomotion_task("hopper")


class _Reward(gymnasium.Wrapper):
    """Keeps the float64 reward of the last step (DummyVecEnv stores float32 copies)."""

    def step(self, action):
        out = self.env.step(action)
        self.last_reward = out[1]
        return out


def _independent(task, n_envs, episode, seed):
    envs = [_Reward(DrakeAbsEnv(task, max_episode_steps=episode)) for _ in range(n_envs)]
    dummy = DummyVecEnv([lambda env=env: env for env in envs])
    dummy.seed(seed)
    return dummy, envs


def _assert_same_infos(ours, theirs):
    assert len(ours) == len(theirs)
    for a, b in zip(ours, theirs, strict=True):
        assert a.keys() == b.keys()
        for key in a:
            if key == "terminal_observation":
                np.testing.assert_array_equal(a[key], b[key])
            else:
                assert a[key] == b[key], key


def _compare(task, n_steps, seed, rng, episode=EPISODE, n_envs=N_ENVS):
    """Step DrakeAbsVecEnv and the DummyVecEnv with the same actions; returns what happened."""
    vec = DrakeAbsVecEnv(task, n_envs, max_episode_steps=episode, seed=seed)
    dummy, envs = _independent(task, n_envs, episode, seed)
    np.testing.assert_array_equal(vec.reset(), dummy.reset())
    assert vec.reset_infos == dummy.reset_infos
    seen = {"terminated": 0, "truncated": 0, "unconverged": 0}
    for _ in range(n_steps):
        actions = rng.uniform(-1, 1, (n_envs, task.nu)).astype(np.float32)
        obs, rewards, dones, infos = vec.step(actions)
        obs_d, _, dones_d, infos_d = dummy.step(actions)
        np.testing.assert_array_equal(obs, obs_d)
        assert rewards.dtype == np.float64 and obs.dtype == np.float64
        np.testing.assert_array_equal(rewards, [env.last_reward for env in envs])
        np.testing.assert_array_equal(dones, dones_d)
        _assert_same_infos(infos, infos_d)
        assert vec.reset_infos == dummy.reset_infos
        np.testing.assert_array_equal(vec.states, [env.unwrapped.state for env in envs])
        for done, info in zip(dones, infos, strict=True):
            seen["unconverged"] += not info["converged"]
            if done:
                seen["truncated" if info["TimeLimit.truncated"] else "terminated"] += 1
    return seen


def test_the_batched_env_gives_the_independent_envs_transitions(hopper, rng):
    seen = _compare(hopper, 70, 7, rng)
    # both ends of an episode happened (random actions topple the Hopper; 25-step episodes)
    assert seen["terminated"] >= 2 and seen["truncated"] >= 2, seen


def test_unconverged_steps_are_reported_and_kept_as_drake_abs_env_does(rng):
    capped = locomotion_task("hopper", max_iterations=4)  # the solver stops early
    with pytest.warns(LCPConvergenceWarning):
        seen = _compare(capped, 20, 3, rng, n_envs=3)
    assert seen["unconverged"] >= 5, seen


def test_seeding_follows_sb3s_convention(hopper):
    vec = DrakeAbsVecEnv(hopper, 3, seed=11)
    first, second = vec.reset(), vec.reset()
    for m in range(3):
        env = DrakeAbsEnv(hopper)
        np.testing.assert_array_equal(first[m], env.reset(seed=11 + m)[0])
        np.testing.assert_array_equal(second[m], env.reset()[0])  # the generator goes on
    again = DrakeAbsVecEnv(hopper, 3)
    again.seed(11)
    np.testing.assert_array_equal(again.reset(), first)
    other = DrakeAbsVecEnv(hopper, 3, seed=12)
    assert not np.array_equal(other.reset()[0], first[0])


def test_bad_input_is_refused(hopper):
    with pytest.raises(ValueError, match="n_envs must be"):
        DrakeAbsVecEnv(hopper, 0)
    with pytest.raises(ValueError, match="max_episode_steps must be"):
        DrakeAbsVecEnv(hopper, 2, max_episode_steps=0)
    with pytest.raises(ValueError, match="task_options"):
        DrakeAbsVecEnv(hopper, 2, smoothing=None)
    vec = DrakeAbsVecEnv(hopper, 2, seed=0)
    vec.reset()
    with pytest.raises(ValueError, match=r"actions must have shape \(n_envs, nu\) = \(2, 3\)"):
        vec.step_async(np.zeros((3, 3)))
    with pytest.raises(RuntimeError, match="step_wait needs a step_async"):
        vec.step_wait()
    assert vec.get_attr("dt") == [hopper.dt] * 2 and vec.env_is_wrapped(gymnasium.Wrapper, 1) == [
        False]  # fmt: skip
    with pytest.raises(NotImplementedError):
        vec.set_attr("dt", 1.0)


class _NanRow:
    """A task whose stepper returns a non-finite next state in its last row (else the task)."""

    def __init__(self, task):
        self._task = task

    def __getattr__(self, name):
        return getattr(self._task, name)

    @property
    def stepper(self):
        return self

    def step(self, x, u, **options):
        step = self._task.stepper.step(x, u, **options)
        x_next = np.array(step.x_next)
        x_next[-1, 0] = np.nan
        return dataclasses.replace(step, x_next=x_next)


def test_a_non_finite_state_raises_naming_the_row(hopper):
    vec = DrakeAbsVecEnv(_NanRow(hopper), 3, seed=0)
    vec.reset()
    with pytest.raises(FloatingPointError, match=r"row\(s\) \[2\] is not finite"):
        vec.step(np.zeros((3, 3), dtype=np.float32))
    with pytest.raises(FloatingPointError, match="is not finite"):  # as DrakeAbsEnv raises
        _independent(_NanRow(hopper), 3, EPISODE, 0)[0].step(np.zeros((3, 3), np.float32))


# ---------------------------------------------------------------------- inside the libraries


def _parameters(model):
    return [p.detach().numpy().copy() for p in model.policy.parameters()]


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_the_library_trains_the_same_policy_on_both(algo, hopper):
    """PPO (two rollouts of 2 x 32 steps) and SAC (learning from step 40) on the batched env
    and on the DummyVecEnv, same seed: the same parameters, bit for bit. 20-step episodes, so
    the terminal-observation bootstrap and the truncation flags are used."""
    torch = pytest.importorskip("torch")
    from stable_baselines3 import PPO, SAC

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        models = []
        for kind in ("batched", "dummy"):
            if kind == "batched":
                venv = DrakeAbsVecEnv(hopper, 2, max_episode_steps=20)
            else:
                venv = _independent(hopper, 2, 20, 0)[0]
            if algo == "ppo":
                model = PPO("MlpPolicy", venv, n_steps=32, batch_size=32, n_epochs=2, seed=5,
                            device="cpu", policy_kwargs={"net_arch": [16]})  # fmt: skip
            else:
                model = SAC("MlpPolicy", venv, learning_starts=40, batch_size=16, seed=5,
                            gradient_steps=2, device="cpu",
                            policy_kwargs={"net_arch": [16]})  # fmt: skip
            model.learn(128)
            models.append(model)
    finally:
        torch.set_num_threads(threads)
    a, b = (_parameters(m) for m in models)
    assert len(a) == len(b) > 0
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert models[0].num_timesteps == models[1].num_timesteps == 128


def test_a_snapshot_restored_continues_the_same_episodes(hopper):
    """Two environments stepped, snapshot, stepped on; another restored from the snapshot and
    given the same actions (crossing a reset) gives the same observations, rewards and dones."""
    rng = np.random.default_rng(2)
    a = DrakeAbsVecEnv(hopper, 2, max_episode_steps=5, seed=7)
    a.reset()
    for _ in range(3):
        a.step(rng.uniform(-1, 1, (2, hopper.nu)))
    snap = a.snapshot()
    b = DrakeAbsVecEnv(hopper, 2, max_episode_steps=5, seed=99)
    b.reset()
    b.restore(snap)
    for _ in range(4):  # the episodes end (truncated) and new ones are drawn
        u = rng.uniform(-1, 1, (2, hopper.nu))
        for x, y in zip(a.step(u)[:3], b.step(u)[:3], strict=True):
            np.testing.assert_array_equal(x, y)
    with pytest.raises(ValueError, match="snapshot is of 2 environments; this has 3"):
        DrakeAbsVecEnv(hopper, 3).restore(snap)
