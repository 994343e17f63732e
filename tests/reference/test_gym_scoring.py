"""Scoring in MuJoCo's own gymnasium environments (drake_abs.reference.gym_scoring).

A zero policy scores the zero floor; the floors reproduce with the same seeds and change with
others; actions are clipped to the action space before gymnasium charges their cost; a bad
action is refused. Episodes are short here (max_steps); the full-size numbers are measured by
``drake-abs evaluate``.
"""

from __future__ import annotations

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from drake_abs.reference.gym_scoring import (  # noqa: E402
    floors,
    reset_observations,
    score_policy,
)

STEPS = 40


@pytest.mark.parametrize("env_id", ["Hopper-v5", "HalfCheetah-v5"])
def test_a_zero_policy_scores_the_zero_floor(env_id):
    nu = gymnasium.make(env_id).action_space.shape[0]
    score = score_policy(lambda obs: np.zeros(nu), env_id, seeds=[0, 1, 2], max_steps=STEPS)
    floor = floors(env_id, [0, 1, 2], STEPS)
    assert score["returns"] == floor["zero"]["returns"]
    assert score["lengths"] == floor["zero"]["lengths"]
    assert score["mean"] == pytest.approx(np.mean(score["returns"]), abs=0)
    assert score["std"] == np.std(score["returns"])
    assert (score["min"], score["max"]) == (min(score["returns"]), max(score["returns"]))
    assert score["time_limit"] == 1000 and score["max_steps"] == STEPS


def test_floors_reproduce_with_the_same_seeds_and_differ_with_others():
    a, b = floors("Hopper-v5", [0, 1], STEPS), floors("Hopper-v5", [0, 1], STEPS)
    assert a == b
    c = floors("Hopper-v5", [2, 3], STEPS)
    assert c["random"]["returns"] != a["random"]["returns"]
    assert c["zero"]["returns"] != a["zero"]["returns"]  # other reset states


def test_the_random_floor_draws_from_the_seeds_generator():
    """The random floor's episode of seed s is the loop below, by hand."""
    env = gymnasium.make("HalfCheetah-v5")
    low, high = env.action_space.low.astype(float), env.action_space.high.astype(float)
    expected = []
    for seed in (4, 5):
        rng, total = np.random.default_rng(seed), 0.0
        env.reset(seed=seed)
        for _ in range(STEPS):
            total += env.step(rng.uniform(low, high))[1]
        expected.append(total)
    env.close()
    assert floors("HalfCheetah-v5", [4, 5], STEPS)["random"]["returns"] == expected


def test_actions_are_clipped_before_gymnasium_charges_them():
    """An action of 5 scores as an action of 1 (the control cost of 1, not of 25)."""
    big = score_policy(lambda obs: np.full(6, 5.0), "HalfCheetah-v5", seeds=[0], max_steps=10)
    one = score_policy(lambda obs: np.ones(6), "HalfCheetah-v5", seeds=[0], max_steps=10)
    assert big["returns"] == one["returns"]


def test_episodes_end_where_gymnasium_terminates_them():
    # the Hopper pushed hard falls: its episodes terminate before the step limit
    score = score_policy(lambda obs: np.array([1.0, -1.0, 1.0]), "Hopper-v5", seeds=[0, 1],
                         max_steps=500)  # fmt: skip
    assert all(score["terminated"]) and max(score["lengths"]) < 500


def test_bad_actions_and_arguments_are_refused():
    with pytest.raises(ValueError, match=r"act must return a finite action of shape \(3,\)"):
        score_policy(lambda obs: np.zeros(2), "Hopper-v5", seeds=[0], max_steps=5)
    with pytest.raises(ValueError, match="act must return a finite action"):
        score_policy(lambda obs: np.full(3, np.nan), "Hopper-v5", seeds=[0], max_steps=5)
    with pytest.raises(ValueError, match="act must be a function"):
        score_policy(None, "Hopper-v5")
    with pytest.raises(ValueError, match="seeds must be whole numbers >= 0"):
        score_policy(lambda obs: np.zeros(3), "Hopper-v5", seeds=[-1])
    with pytest.raises(ValueError, match="max_steps must be a whole number >= 1"):
        score_policy(lambda obs: np.zeros(3), "Hopper-v5", max_steps=0)


def test_reset_observations_are_the_first_observations():
    obs = reset_observations("Hopper-v5", [0, 7])
    env = gymnasium.make("Hopper-v5")
    np.testing.assert_array_equal(obs[1], env.reset(seed=7)[0])
    assert obs.shape == (2, 11)
