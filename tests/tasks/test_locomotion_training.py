"""Training on a locomotion task by a method of the registry (drake_abs.tasks.locomotion_training):
the first row scores the start on the true task, the samples counted are the environment steps,
the registry's estimator is the one used, and bad input is named."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.policy.methods import method
from drake_abs.policy.policies import LinearPolicy
from drake_abs.tasks.locomotion import locomotion_task
from drake_abs.tasks.locomotion_training import LocomotionTraining, evaluate, train_method

CONFIG = LocomotionTraining(iterations=2, rollouts=3, horizon=4, eval_horizon=5)


@pytest.fixture(scope="module")
def cheetah():
    return locomotion_task("half_cheetah")


def test_a_gradient_method_trains_with_the_registrys_estimate(cheetah):
    x_eval = cheetah.initial_states(np.random.default_rng(0), 2)
    run = train_method(cheetah, "fopg_exact", CONFIG, 7, x_eval)
    rows = run["rows"]
    assert [r["iteration"] for r in rows] == [0, 1, 2] and run["skipped"] == 0
    zero = np.zeros(run["theta"].size)
    assert rows[0]["return"] == evaluate(cheetah, zero, x_eval, CONFIG.eval_horizon)
    assert rows[-1]["samples"] == 2 * 3 * 4  # the half-cheetah never ends early
    # the first update is Adam's step on the registry's FOPG estimate from the run's seed
    obj = cheetah.objective(LinearPolicy(cheetah.n_obs, cheetah.nu), CONFIG.horizon, CONFIG.sigma)
    est = method("fopg_exact").estimate(obj, zero, np.random.default_rng(7), CONFIG.rollouts)
    assert rows[1]["batch_return"] == est.value
    assert rows[1]["grad_norm"] == float(np.linalg.norm(est.grad))


def test_evaluate_is_the_deterministic_return(cheetah):
    """The mean return of the environment's episodes from the same states, stepped by hand."""
    from drake_abs.tasks.gym_env import DrakeAbsEnv

    x0s = cheetah.initial_states(np.random.default_rng(1), 2)
    inner = LinearPolicy(cheetah.n_obs, cheetah.nu)
    theta = 0.05 * np.random.default_rng(2).standard_normal(inner.n_params)
    env, returns = DrakeAbsEnv(cheetah, max_episode_steps=None), []
    for x0 in x0s:
        env.set_state(x0[: cheetah.nq], x0[cheetah.nq :])
        obs, total = cheetah.observation(x0[None])[0], 0.0
        for _ in range(6):
            obs, r, *_ = env.step(inner.act(theta, obs[None])[0])
            total += r
        returns.append(total)
    assert evaluate(cheetah, theta, x0s, 6) == pytest.approx(np.mean(returns), rel=1e-9)


def test_bad_input_is_named(cheetah):
    x_eval = cheetah.initial_states(np.random.default_rng(0), 1)
    with pytest.raises(ValueError, match="theta0 must have shape"):
        train_method(cheetah, "fopg_abs", CONFIG, 0, x_eval, theta0=np.zeros(3))
    with pytest.raises(ValueError, match="unknown method"):
        train_method(cheetah, "fopg_sideways", CONFIG, 0, x_eval)
