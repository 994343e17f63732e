"""Tuning an MPC's cost parameters in closed loop: the evaluator the tuners call, which counts
what the MPC did, and the reference tuner with perfect model knowledge.

- :class:`ClosedLoopEvaluator`: ``evaluate(theta, with_gradient)`` of
  :func:`~drake_abs.mpc.graybox.graybox_optimize`: one :func:`~drake_abs.mpc.graybox.closed_loop`
  of its own controller (its own OSQP warm start, carried from one call to the next), counting
  the rollouts, the fallback steps (QP not solved) and the inaccurately solved steps.
- :func:`lbfgs_tune`: box-constrained L-BFGS-B (scipy) on the closed-loop total cost with an
  evaluator's gradient: with ``gradient="exact"`` (the plant's own Jacobians in eq. 8) the
  "optimised with perfect model knowledge" reference of Zuliani et al. 2025, section 7.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.optimize

from drake_abs._validation import as_count, as_finite_array
from drake_abs.engine import Stepper
from drake_abs.mpc.graybox import ClosedLoopResult, GradientSource, TrackingCost, closed_loop
from drake_abs.mpc.qp_mpc import MpcStatus, QpMpc


class ClosedLoopEvaluator:
    """The closed-loop cost of ``controller`` at any theta, counting the MPC's statuses.

    Args:
        controller: the MPC (its theta is set at each call; its warm start carries over).
        x0: (nx,) initial state.
        steps: the closed loop's horizon T >= 1.
        plant: the true system (a :class:`~drake_abs.engine.Stepper`).
        cost: the upper-level cost and penalty.
        gradient: the gradient source when one is asked for: ``"model"`` (the controller's own
            (A, B)) or ``"exact"`` (the plant's Jacobians).

    Attributes:
        rollouts, fallback_steps, inaccurate_steps: counts over every call so far.
    """

    def __init__(
        self,
        controller: QpMpc,
        x0,
        steps: int,
        plant: Stepper,
        cost: TrackingCost,
        gradient: GradientSource = "model",
    ):
        if gradient not in ("model", "exact"):
            raise ValueError(f"gradient must be 'model' or 'exact'; got {gradient!r}")
        self.controller, self.plant, self.cost, self.gradient = controller, plant, cost, gradient
        self.x0 = as_finite_array(x0, "x0", ndim=(1,))
        self.steps = as_count(steps, "steps", minimum=1)
        self.rollouts = self.fallback_steps = self.inaccurate_steps = 0

    def __call__(self, theta, with_gradient: bool) -> ClosedLoopResult:
        """One closed loop at ``theta`` (n_theta,); with the gradient d total / d theta when
        ``with_gradient``."""
        r = closed_loop(
            self.controller, theta, self.x0, self.steps, self.plant, self.cost,
            gradient=self.gradient if with_gradient else None,
        )  # fmt: skip
        self.rollouts += 1
        self.fallback_steps += r.fallback_steps
        self.inaccurate_steps += int(np.sum(r.status == int(MpcStatus.SOLVED_INACCURATE)))
        return r

    def counts(self) -> dict[str, int]:
        """``rollouts``, ``fallback_steps`` and ``inaccurate_steps`` so far."""
        keys = ("rollouts", "fallback_steps", "inaccurate_steps")
        return {key: getattr(self, key) for key in keys}


def lbfgs_tune(
    evaluate: Callable[[np.ndarray, bool], ClosedLoopResult],
    theta0,
    *,
    bound: float,
    iterations: int,
    callback: Callable[[float], None] | None = None,
) -> tuple[scipy.optimize.OptimizeResult, list[float]]:
    """L-BFGS-B on ``evaluate(theta, True).total`` with its gradient, from ``theta0``
    (n_theta,) within the box ``|theta_i| <= bound``, for at most ``iterations`` iterations.

    Returns scipy's result and the total cost after each iteration; ``callback`` is called
    with each of these totals as it comes.
    """
    theta0 = as_finite_array(theta0, "theta0", ndim=(1,))
    iterations = as_count(iterations, "iterations", minimum=1)
    if not (np.isfinite(bound) and bound > 0):
        raise ValueError(f"bound must be a finite number > 0; got {bound!r}")
    history: list[float] = []

    def fun(theta):
        r = evaluate(theta, True)
        return r.total, r.gradient

    def on_iteration(intermediate_result):
        history.append(float(intermediate_result.fun))
        if callback is not None:
            callback(history[-1])

    result = scipy.optimize.minimize(
        fun, theta0, jac=True, method="L-BFGS-B", bounds=[(-bound, bound)] * theta0.size,
        options={"maxiter": iterations}, callback=on_iteration,
    )  # fmt: skip
    return result, history
