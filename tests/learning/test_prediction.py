"""A model's open-loop prediction error on recorded transitions (learning.prediction)."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.contact.unconverged import UnconvergedStepWarning
from drake_abs.learning.prediction import Predictor, prediction_error
from drake_abs.learning.transitions import Transitions


def _data(episodes: int = 2, steps: int = 5, drift: float = 0.0) -> Transitions:
    """x_{t+1} = x_t + u_t (+ drift in the first coordinate), seeded inputs."""
    rng = np.random.default_rng(0)
    xs, us, nxt, ep, t = [], [], [], [], []
    for e in range(episodes):
        x = rng.standard_normal(2)
        for k in range(steps):
            u = rng.standard_normal(2)
            xn = x + u + np.array([drift, 0.0])
            xs.append(x), us.append(u), nxt.append(xn), ep.append(e), t.append(k)
            x = xn
    return Transitions(x=xs, u=us, x_next=nxt, episode=ep, t=t, source="toy", time_step=0.1)


def _plus(x, u):
    return x + u, np.ones(len(x), bool)


def test_the_true_model_has_no_error_and_a_drift_grows_linearly():
    data = _data()
    err, lost = prediction_error(Predictor(_plus), data, 3, np.ones(2))
    assert np.allclose(err, 0.0, atol=1e-12) and np.all(lost == 0.0)
    # the data drift by 0.1 per step in one of two coordinates: after k steps the rms over the
    # coordinates is 0.1 k / sqrt(2), in units of spread 0.5
    err, _ = prediction_error(Predictor(_plus), _data(drift=0.1), 3, np.full(2, 0.5))
    assert np.allclose(err, 0.1 * np.arange(1, 4) / np.sqrt(2) / 0.5, rtol=1e-10)


def test_unconverged_and_nonfinite_rows_are_lost_not_averaged():
    calls = []

    def flaky(x, u):  # the first row of every batch is lost at the second step
        calls.append(len(x))
        converged = np.ones(len(x), bool)
        if len(calls) == 2:
            converged[0] = False
        return x + u, converged

    data = _data(episodes=1, steps=4)
    with pytest.warns(UnconvergedStepWarning):
        err, lost = prediction_error(Predictor(flaky), data, 2, np.ones(2))
    windows = data.windows(2).size
    assert calls == [windows, windows]
    assert np.allclose(err, 0.0, atol=1e-12)
    assert lost[0] == 0.0 and lost[1] == pytest.approx(1 / windows)
    step = Predictor(_plus).step(np.array([[np.nan, 0.0], [1.0, 2.0]]), np.ones((2, 2)))
    assert np.isnan(step.x_next[0]).all() and np.allclose(step.x_next[1], [2.0, 3.0])
    assert step.converged.tolist() == [False, True] and step.impulse.shape == (2, 0)


def test_of_stepper_and_of_ensemble():
    class Ensemble:
        size = 2

        def predict(self, x, u, members):
            return x + u + np.where(members == 0, 1.0, -1.0)[:, None]

    class Stepper:
        def step(self, x, u, jacobians=False):
            return Predictor(_plus).step(x, u)

    data = _data()
    for predictor in (Predictor.of_ensemble(Ensemble()), Predictor.of_stepper(Stepper())):
        err, lost = prediction_error(predictor, data, 2, np.ones(2))
        assert np.allclose(err, 0.0, atol=1e-12) and np.all(lost == 0.0)


def test_bad_input_is_named():
    data = _data(episodes=1, steps=3)
    with pytest.raises(ValueError, match="predict"):
        Predictor(3)
    with pytest.raises(ValueError, match="spread"):
        prediction_error(Predictor(_plus), data, 2, np.ones(3))
    with pytest.raises(ValueError, match="no test window"):
        prediction_error(Predictor(_plus), data, 4, np.ones(2))
