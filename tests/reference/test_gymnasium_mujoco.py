"""gymnasium's MuJoCo settings and reset states (drake_abs.reference.gymnasium_mujoco): read from
the environments themselves, checked against gymnasium's own reset and against our task's reset
noise (the same seeding)."""

from __future__ import annotations

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from drake_abs.reference.gymnasium_mujoco import reset_states, same_period_frame_skip  # noqa: E402


def test_frame_skip_of_a_control_period():
    hopper = same_period_frame_skip("Hopper-v5", 0.01)
    assert (hopper["timestep"], hopper["default_frame_skip"], hopper["frame_skip"]) == (
        0.002, 4, 5,
    )  # fmt: skip
    assert hopper["default_period"] == pytest.approx(0.008) and hopper["integrator"] == "RK4"
    cheetah = same_period_frame_skip("HalfCheetah-v5", 0.01)
    assert (cheetah["default_frame_skip"], cheetah["frame_skip"], cheetah["integrator"]) == (
        5, 1, "Euler",
    )  # fmt: skip
    with pytest.raises(ValueError, match="not a whole multiple"):
        same_period_frame_skip("Hopper-v5", 0.003)


@pytest.mark.parametrize("env_id", ["Hopper-v5", "HalfCheetah-v5"])
def test_reset_states_are_gymnasiums(env_id):
    seeds = (0, 5, 5, 11)
    x = reset_states(env_id, seeds)
    env = gymnasium.make(env_id)
    for row, seed in zip(x, seeds, strict=True):
        obs, _ = env.reset(seed=seed)
        data = env.unwrapped.data
        np.testing.assert_array_equal(row, np.concatenate([data.qpos, data.qvel, data.act]))
        np.testing.assert_array_equal(obs[: data.qpos.size - 1], row[1 : data.qpos.size])
    env.close()
    np.testing.assert_array_equal(x[1], x[2])  # the seed, not the call order, sets the state
    assert not np.array_equal(x[0], x[1])


def test_bad_seeds_are_named():
    for bad in ((), (-1,), (1.5,), (True,)):
        with pytest.raises(ValueError, match="seeds must be whole numbers"):
            reset_states("Hopper-v5", bad)
