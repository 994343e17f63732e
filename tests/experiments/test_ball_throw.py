"""Paper 000 section 8.3, the ball throw (experiments/ball_throw.py).

Checks: the throw stepper's release Jacobian and the whole return's pathwise derivative match
central differences; the ball lands before the goal and stops; FOPG-ABS and ZOPG at test size
improve the evaluated return; the same seed gives the same curve; the experiment writes its
files and reports against the paper's claims.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from numdiff import central_difference

from drake_abs.engine import rollout
from drake_abs.experiments import ball_throw as bt
from drake_abs.policy.estimators import first_order
from drake_abs.policy.training import Adam, train

CONFIG = bt.Config.test_size()


def _return(obj, angle: float) -> float:
    noise = np.zeros((1, CONFIG.horizon, 1))
    r = rollout(obj.stepper, obj.policy, np.array([angle]), obj.x0, noise, obj.reward,
                       sigma=0.0, gradient=False)  # fmt: skip
    return float(r.returns[0])


@pytest.mark.parametrize("method", ["fopg_exact", "fopg_bs"])
def test_return_derivative_matches_central_differences(method):
    """Exact and BS (constant mu): the frozen-mu gradient is the derivative of the return. (ABS
    trains with the frozen gradient of Algorithm 1, which leaves out d mu / d z.)"""
    obj = bt.objective(CONFIG, bt.smoothing_for(method, CONFIG))
    for angle in (0.9, 1.2):
        noise = np.zeros((1, CONFIG.horizon, 1))
        r = rollout(obj.stepper, obj.policy, np.array([angle]), obj.x0, noise,
                           obj.reward, sigma=0.0)  # fmt: skip
        fd = central_difference(lambda a, o=obj: np.array([_return(o, a[0])]), [angle], eps=1e-6)
        assert r.grad[0, 0] == pytest.approx(fd[0, 0], rel=1e-4, abs=1e-6)


def test_the_ball_lands_before_the_goal_and_stops():
    obj = bt.objective(CONFIG)
    noise = np.zeros((1, CONFIG.horizon, 1))
    for angle in (0.0, 0.8, 1.3):
        r = rollout(obj.stepper, obj.policy, np.array([angle]), obj.x0, noise,
                           obj.reward, sigma=0.0, gradient=False)  # fmt: skip
        x = r.x[0]
        on_ground = np.flatnonzero(x[:, 1] <= CONFIG.radius + 1e-9)
        assert on_ground.size and x[on_ground[0], 0] < CONFIG.goal  # contact before the goal
        assert abs(x[-1, 2]) < 1e-6  # at rest at the end of the horizon
        assert r.converged.all()


@pytest.mark.parametrize("method", ["fopg_abs", "zopg"])
def test_learning_improves_the_return_and_is_seeded(method):
    estimator = bt._estimator(method, CONFIG)

    def curve(seed):
        run = train(estimator, np.array([CONFIG.angle0]), Adam(lr=CONFIG.learning_rate),
                    CONFIG.iterations, seed=seed, progress=False,
                    evaluate=lambda th: float(bt.true_return(CONFIG, th[0])[0][0]))  # fmt: skip
        return np.array([row["eval_return"] for row in run.rows])

    a, b = curve(3), curve(3)
    np.testing.assert_array_equal(a, b)
    assert a[-1] > a[0] + 0.3  # from -0.72 m^2 at the start


def test_first_order_estimate_differs_between_seeds_but_not_within():
    obj = bt.objective(CONFIG, bt.smoothing_for("fopg_bs", CONFIG))
    g = [first_order(obj, np.array([1.0]), np.random.default_rng(s), 8).grad for s in (0, 0, 1)]
    assert g[0] == g[1] and g[0] != g[2]


def test_experiment_writes_its_results(tmp_path):
    config = bt.Config(rollouts=4, iterations=3, seeds=(0,), landscape_points=11)
    summary = bt.run(config, tmp_path)
    for name in ("learning_curves.png", "landscape.png", "summary.json", "curves.json"):
        assert (tmp_path / name).is_file()
    for method in bt.METHODS:
        for seed in config.seeds:
            log = json.loads((tmp_path / "runs" / f"{method}_seed{seed}.json").read_text())
            assert len(log["rows"]) == config.iterations + 1
    assert set(summary["claims"]) == {"bs_beats_zopg_and_fopg", "abs_beats_all"}
    assert "paper:" in bt.report(summary)


def test_the_gradient_mode_is_a_setting_and_frozen_by_default():
    """Algorithm 1's frozen mu is the default, and Config.gradient reaches the model: under ABS
    the two modes give different derivatives of the same return."""
    from dataclasses import replace

    assert bt.Config().gradient == "frozen"
    angles = np.array([0.9, 1.2])
    grads = {}
    for mode in ("frozen", "total"):
        config = replace(CONFIG, gradient=mode)
        obj = bt.objective(config, bt.smoothing_for("fopg_abs", config))
        assert obj.stepper.ball.gradient == mode
        grads[mode] = bt._throws(obj, angles, gradient=True).grad[:, 0]
    assert not np.allclose(grads["frozen"], grads["total"], rtol=1e-6, atol=0)
