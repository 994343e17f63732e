"""The tuners' evaluator (one closed loop per call, counting the MPC's statuses) and the
L-BFGS-B reference tuner with the exact gradient."""

import numpy as np
import pytest
from mpc_setup import A_H, B_H, PRM, Q_D, R_D, THETA, U_MAX, U_MIN, U_REF, X_MAX, X_MIN, X_REF

from drake_abs.mpc.graybox import TrackingCost, closed_loop
from drake_abs.mpc.qp_mpc import MpcSpec, QpMpc
from drake_abs.mpc.tuning import ClosedLoopEvaluator, lbfgs_tune
from drake_abs.tasks import quadcopter as qc

COST = TrackingCost(
    np.diag(Q_D), np.diag(R_D), np.diag(np.r_[np.ones(6), 1e3 * np.ones(3), np.ones(3)]),
    X_REF, U_REF, X_MIN, X_MAX, 300.0,
)  # fmt: skip
SPEC = MpcSpec(A_H, B_H, 6, X_REF, U_REF, U_MIN, U_MAX, X_MIN, X_MAX)
PLANT = qc.QuadcopterStepper(PRM)


@pytest.mark.parametrize("source", ["model", "exact"])
def test_evaluator_is_the_closed_loop_and_counts_its_rollouts(source):
    evaluate = ClosedLoopEvaluator(QpMpc(SPEC, THETA), np.zeros(12), 8, PLANT, COST, source)
    direct = closed_loop(QpMpc(SPEC, THETA), THETA, np.zeros(12), 8, PLANT, COST, gradient=source)
    r = evaluate(THETA, True)
    assert r.total == direct.total and r.gradient_source == source
    np.testing.assert_array_equal(r.gradient, direct.gradient)
    assert evaluate(1.1 * THETA, False).gradient is None
    assert evaluate.counts() == {"rollouts": 2, "fallback_steps": 0, "inaccurate_steps": 0}


def test_evaluator_counts_fallback_steps():
    """OSQP stopped after one iteration solves no QP: every step is a fallback, counted."""
    mpc = QpMpc(SPEC, THETA, osqp_settings={"max_iter": 1})
    evaluate = ClosedLoopEvaluator(mpc, np.zeros(12), 3, PLANT, COST)
    assert evaluate(THETA, False).fallback_steps == 3
    assert evaluate(THETA, False).fallback_steps == 3
    assert evaluate.counts()["fallback_steps"] == 6 and evaluate.rollouts == 2


def test_lbfgs_tune_lowers_the_total_within_the_box():
    evaluate = ClosedLoopEvaluator(QpMpc(SPEC, THETA), np.zeros(12), 8, PLANT, COST, "exact")
    seen = []
    res, history = lbfgs_tune(evaluate, THETA, bound=100.0, iterations=3, callback=seen.append)
    start = evaluate(THETA, False).total
    assert history == seen and len(history) == res.nit >= 1
    assert res.fun < start and history[-1] == pytest.approx(res.fun)
    assert np.all(np.abs(res.x) <= 100.0)


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="gradient"):
        ClosedLoopEvaluator(QpMpc(SPEC, THETA), np.zeros(12), 8, PLANT, COST, "exactly")
    with pytest.raises(ValueError, match="steps"):
        ClosedLoopEvaluator(QpMpc(SPEC, THETA), np.zeros(12), 0, PLANT, COST)
    evaluate = ClosedLoopEvaluator(QpMpc(SPEC, THETA), np.zeros(12), 8, PLANT, COST)
    with pytest.raises(ValueError, match="bound"):
        lbfgs_tune(evaluate, THETA, bound=0.0, iterations=2)
    with pytest.raises(ValueError, match="iterations"):
        lbfgs_tune(evaluate, THETA, bound=1.0, iterations=0)
