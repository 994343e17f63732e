"""Episodes of a locomotion task in the engine (drake_abs.tasks.episodes) against the loops they
replace: gymnasium's own ``env.step`` loop for MuJoCo (Hopper-v5 with its termination,
HalfCheetah-v5; actions beyond the action space, unclipped, as a linear policy gives them and the
transfer experiment passes them) and :class:`~drake_abs.tasks.gym_env.DrakeAbsEnv` for our plant.
The reference loops are written out here, by hand."""

from __future__ import annotations

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from drake_abs.policy.policies import LinearPolicy  # noqa: E402
from drake_abs.reference.gymnasium_mujoco import reset_states  # noqa: E402
from drake_abs.reference.mujoco_plant import MujocoStepper  # noqa: E402
from drake_abs.tasks.episodes import TERMS, episode_statistics, score_episodes  # noqa: E402
from drake_abs.tasks.gym_env import DrakeAbsEnv  # noqa: E402
from drake_abs.tasks.locomotion import locomotion_task  # noqa: E402
from drake_abs.tasks.saved_policies import reset_state  # noqa: E402

SEEDS = (0, 3, 7)


def gymnasium_loop(env_id, act, seeds, steps, frame_skip=None) -> list[dict]:
    """gymnasium's own episodes, stepped here: return, length, terminated and the info terms."""
    options = {} if frame_skip is None else {"frame_skip": frame_skip}
    env = gymnasium.make(env_id, max_episode_steps=steps, **options)
    out = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        x_start = float(env.unwrapped.data.qpos[0])
        total, n, terms = 0.0, 0, dict.fromkeys(TERMS, 0.0)
        while True:
            obs, r, terminated, truncated, info = env.step(act(obs))
            total, n = total + r, n + 1
            for key in terms:
                terms[key] += float(info.get(key, 0.0))
            if terminated or truncated:
                break
        distance = float(env.unwrapped.data.qpos[0]) - x_start
        out.append({"return": total, "length": n, "terminated": terminated,
                    "forward_distance": distance, **terms})  # fmt: skip
    env.close()
    return out


@pytest.mark.parametrize(
    ("name", "env_id", "frame_skip"),
    [("hopper", "Hopper-v5", None), ("hopper", "Hopper-v5", 5),
     ("half_cheetah", "HalfCheetah-v5", None), ("half_cheetah", "HalfCheetah-v5", 1)],
)  # fmt: skip
def test_mujoco_episodes_are_gymnasiums_own(name, env_id, frame_skip):
    task = locomotion_task(name)
    inner = LinearPolicy(task.n_obs, task.nu)
    theta = 0.5 * np.random.default_rng(1).standard_normal(inner.n_params)
    steps = 120
    reference = gymnasium_loop(env_id, lambda obs: inner.act(theta, obs[None])[0], SEEDS, steps,
                               frame_skip)  # fmt: skip
    stepper = MujocoStepper.from_gymnasium(env_id, frame_skip=frame_skip)
    episodes = score_episodes(task, task.policy(inner), theta, reset_states(env_id, SEEDS), steps,
                              stepper=stepper)  # fmt: skip
    for ours, ref in zip(episodes, reference, strict=True):
        assert ours["return"] == pytest.approx(ref["return"], rel=1e-12, abs=0)
        for key in ("length", "terminated", "forward_distance", *TERMS):
            assert ours[key] == ref[key], key  # to the bit: the same terms, summed in order
        assert ours["seconds"] == ours["length"] * stepper.time_step
    assert any(e["saturated_fraction"] > 0 for e in episodes)  # actions beyond [-1, 1]
    if name == "hopper":  # the termination is exercised, and ends the episodes early
        assert all(e["terminated"] and e["length"] < steps for e in episodes)
    else:
        assert all(not e["terminated"] and e["length"] == steps for e in episodes)


def test_our_plant_episode_is_the_environments():
    """On our plant: the same episode as DrakeAbsEnv stepped by hand from reset(seed)."""
    task = locomotion_task("hopper")
    inner = LinearPolicy(task.n_obs, task.nu)
    theta = 0.1 * np.random.default_rng(2).standard_normal(inner.n_params)
    steps, seed = 25, 4
    env = DrakeAbsEnv(task, max_episode_steps=steps)
    obs, _ = env.reset(seed=seed)
    total, n, terminated = 0.0, 0, False
    while not terminated and n < steps:
        obs, r, terminated, _, _ = env.step(inner.act(theta, obs[None])[0])
        total, n = total + r, n + 1
    (ours,) = score_episodes(task, task.policy(inner), theta, reset_state(task, seed)[None], steps)
    assert (ours["return"], ours["length"], ours["terminated"]) == (total, n, terminated)
    assert ours["forward_distance"] == env.state[0] - reset_state(task, seed)[0]


def test_statistics_and_bad_input():
    task = locomotion_task("half_cheetah")
    zero = LinearPolicy(task.nx, task.nu)
    x0s = reset_states("HalfCheetah-v5", (0, 1))
    stepper = MujocoStepper.from_gymnasium("HalfCheetah-v5", frame_skip=1)
    episodes = score_episodes(task, zero, np.zeros(zero.n_params), x0s, 10, stepper=stepper)
    stats = episode_statistics(episodes)
    assert stats["episodes"] == 2 and stats["lengths"] == [10, 10]
    assert stats["return_mean"] == pytest.approx(np.mean(stats["returns"]), rel=1e-15)
    assert stats["reward_ctrl_mean"] == 0.0 and stats["action_rms_mean"] == 0.0
    with pytest.raises(ValueError, match="steps"):
        score_episodes(task, zero, np.zeros(zero.n_params), x0s, 0, stepper=stepper)
    with pytest.raises(ValueError, match="x0s"):
        score_episodes(task, zero, np.zeros(zero.n_params), x0s[0], 5, stepper=stepper)
    with pytest.raises(ValueError, match="time_step"):
        score_episodes(task, zero, np.zeros(zero.n_params), x0s, 5, time_step=-1.0)
    with pytest.raises(ValueError, match="at least one"):
        episode_statistics([])
