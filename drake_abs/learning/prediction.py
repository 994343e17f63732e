"""A learned model's open-loop prediction error on recorded transitions: how far its k-step
prediction from a recorded state, under the recorded inputs, lands from the recorded states.

A model is anything that predicts one step of a batch: :class:`Predictor` wraps such a
function (or a stepper, or an ensemble's mean) as a stepper the engine's
:func:`~drake_abs.engine.open_loop` runs, so the k-step prediction is the engine's. A row that
is not finite is not stepped and stays NaN, and so does a row whose step did not converge: a
lost prediction is never passed off as one. :func:`prediction_error` rolls the predictor over
every window of ``horizon`` consecutive steps of the data's episodes.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drake_abs.contact.step import Step
from drake_abs.engine import open_loop
from drake_abs.learning.transitions import Transitions

__all__ = ["Predictor", "prediction_error"]

#: ``predict(x (B, nx), u (B, nu)) -> (x_next (B, nx), converged (B,) bool)``
PredictFn = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


class Predictor:
    """A model's one-step prediction ``predict(x, u) -> (x_next, converged)`` as a stepper (no
    Jacobians, no contact impulses) for the engine's open loop: only the finite rows of a batch
    are predicted; the others, and the rows whose prediction did not converge, come out NaN
    with ``converged`` False."""

    parameter_names = ()

    def __init__(self, predict: PredictFn):
        if not callable(predict):
            raise ValueError(f"predict must be callable (x, u) -> (x_next, converged); got "
                             f"{type(predict).__name__}")  # fmt: skip
        self.predict = predict

    def step(self, x: np.ndarray, u: np.ndarray, *, jacobians: bool = False,
             parameters: bool = False) -> Step:  # fmt: skip
        """x (B, nx), u (B, nu) -> :class:`~drake_abs.contact.step.Step` with x_next (B, nx)
        (NaN where lost), converged (B,), no impulses (B, 0)."""
        x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        out = np.full_like(x, np.nan)
        ok = np.isfinite(x).all(axis=1)
        if ok.any():
            x_next, converged = self.predict(x[ok], u[ok])
            x_next = np.array(x_next, dtype=float)
            x_next[~np.asarray(converged, bool)] = np.nan
            out[ok] = x_next
        B = x.shape[0]
        return Step(x_next=out, converged=np.isfinite(out).all(axis=1),
                    iterations=np.zeros(B, int), impulse=np.zeros((B, 0)),
                    mu=np.zeros((B, 0)))  # fmt: skip

    @classmethod
    def of_stepper(cls, stepper) -> Predictor:
        """A stepper's own step (``stepper.step(x, u, jacobians=False)``: x_next, converged)."""

        def predict(x, u):
            step = stepper.step(x, u, jacobians=False)
            return step.x_next, step.converged

        return cls(predict)

    @classmethod
    def of_ensemble(cls, ensemble) -> Predictor:
        """The mean over an ensemble's members (``ensemble.size`` of them,
        ``ensemble.predict(x, u, members (B,))``, e.g.
        :class:`drake_abs.policy.mbpo.MlpEnsemble`), always converged."""

        def predict(x, u):
            B = x.shape[0]
            preds = [ensemble.predict(x, u, np.full(B, e)) for e in range(ensemble.size)]
            return np.mean(preds, axis=0), np.ones(B, bool)

        return cls(predict)


def prediction_error(
    predictor: Predictor, data: Transitions, horizon: int, spread: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The open-loop prediction error of ``predictor`` on ``data``.

    From the start of every window of ``horizon`` consecutive steps of one episode
    (:meth:`Transitions.windows`), the predictor runs open loop (the engine's) under the
    recorded inputs; at step k the error of a window is the root mean square over the state's
    coordinates of ``(x_hat - x) / spread``. A window whose prediction is not finite (a step
    that did not converge, a diverging model) is lost from then on: counted, not averaged.

    Args:
        predictor: the model, as a :class:`Predictor` (or any stepper whose lost rows are NaN).
        data: the recorded (test) transitions.
        horizon: steps per window (>= 1).
        spread: (nx,) positive scale of each coordinate (e.g. its standard deviation in the
            data, so that 1 is as far off as the data's own spread).

    Returns:
        ``(error, lost)``, each (horizon,): the mean error over the windows still finite at
        step k (NaN when none is), and the fraction of windows lost by step k.
    """
    spread = np.asarray(spread, dtype=float)
    if spread.shape != (data.nx,) or not np.all(spread > 0):
        raise ValueError(f"spread must be (nx,) = ({data.nx},) positive scales; got {spread!r}")
    starts = data.windows(horizon)
    if starts.size == 0:
        raise ValueError(f"no test window of {horizon} steps: the test episodes are too short")
    rows = starts[:, None] + np.arange(horizon)
    run = open_loop(predictor, data.x[starts], data.u[rows], jacobians=False,
                    on_unconverged="flag")  # fmt: skip
    rms = np.sqrt(np.mean(((run.x[:, 1:] - data.x_next[rows]) / spread) ** 2, axis=2))
    finite = np.isfinite(rms)
    err = [float(np.mean(rms[finite[:, k], k])) if finite[:, k].any() else np.nan
           for k in range(horizon)]  # fmt: skip
    return np.array(err), 1.0 - finite.mean(axis=0)
