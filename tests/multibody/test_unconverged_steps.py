"""Contact steps that are hard for the interior point: the solver's second starts solve them,
and a smoothed step that still does not converge moves the state by the exact (mu = 0) solution
of the same step, never by its unconverged iterate (it stays flagged)."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from drake_abs.contact.smoothing import Exact, Fixed
from drake_abs.lcp import ipm, solve_lcp
from drake_abs.lcp.ipm import LCPConvergenceWarning
from drake_abs.multibody import Scene, build_scene_model
from drake_abs.multibody.posture import STANDING_GAINS, standing_controller

# The frictional LCP of the hopper's foot at rest 4.4 cm above the ground at h = 1e-4 s:
# (gamma, beta+, beta-, omega). Exact answer: no impulse; every friction row degenerate.
F_HOP = np.array([[2.0e-4, 0.0, 0.0, 0.0], [0.0, 2.8648, -2.8648, 1.0],
                  [0.0, -2.8648, 2.8648, 1.0], [0.8, -1.0, -1.0, 0.0]])  # fmt: skip
Z_HOP = np.array([0.044, 0.0, 0.0, 0.0])


@pytest.fixture
def default_start_only(monkeypatch):
    monkeypatch.setattr(ipm, "SECOND_START", False)


@pytest.mark.parametrize("mu", [0.0, 1e-8, 1e-4, 1e-2])
def test_a_resting_frictional_contact_above_the_ground_converges(mu):
    r = solve_lcp(F_HOP, Z_HOP, np.full(4, mu), on_bad_matrix="attempt")
    assert r.converged
    assert r.lam[0] <= 30 * mu + 1e-20  # lam_n s_n = mu with s_n >= 0.044: no push
    np.testing.assert_allclose(r.lam * r.slack, mu, rtol=1e-9, atol=1e-20)


def test_the_default_start_alone_fails_there(default_start_only):
    with pytest.warns(LCPConvergenceWarning):
        assert not solve_lcp(F_HOP, Z_HOP, 0.0, on_bad_matrix="attempt").converged


def test_the_hopper_at_a_tiny_step_gets_no_impulse_from_the_air():
    """The case found from outside: an 81 N s impulse from a 4x4 LCP at residual 7e11."""
    model = build_scene_model(replace(Scene.load("hopper"), time_step=1e-4))
    x = model.x0.copy()
    nq = model.contact_model.nq
    x[1] += 0.044 - model.contact_model.distances(x[None, :nq])[0, 0]
    with warnings.catch_warnings():
        warnings.simplefilter("error", LCPConvergenceWarning)
        r = model.stepper().step(x[None], np.zeros((1, model.contact_model.nu)))
    assert r.converged.all() and r.impulse.max() < 1e-12


def test_an_unconverged_smoothed_step_takes_the_exact_step():
    """solo12 standing on noisy PD torques under Fixed(1e-6), with the solver starved to 8
    iterations per start, so that some smoothed steps do not converge while their exact steps
    do (through the crossover, whose check takes no iterations): those steps' next states are
    the exact step's. (With the default budget the solver now converges on every step of this
    case.)"""
    model = build_scene_model("solo12_drop")
    hold, _ = standing_controller(model, *STANDING_GAINS["solo12_drop"])
    smoothed = model.stepper(smoothing=Fixed(1e-6), max_iterations=8)
    exact = model.stepper(smoothing=Exact())
    rng = np.random.default_rng(0)
    nq, nv = model.contact_model.nq, model.contact_model.nv
    x = np.tile(model.x0, (16, 1))
    x[:, nq:] += 0.1 * rng.standard_normal((16, nv))
    flagged = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LCPConvergenceWarning)
        for _ in range(40):
            u = hold(x) + 0.05 * rng.standard_normal((16, model.contact_model.nu))
            r = smoothed.step(x, u, jacobians=False)
            bad = np.flatnonzero(~r.converged)
            if bad.size:
                e = exact.step(x[bad], u[bad], jacobians=False)
                assert e.converged.all()
                # the same exact solve, reached through the fallback and directly
                np.testing.assert_allclose(r.x_next[bad], e.x_next, rtol=1e-12, atol=1e-15)
                flagged += bad.size
            x = r.x_next
    assert flagged > 0  # the case does occur here (else this test would check nothing)


def test_pruning_never_lets_a_fast_impact_through():
    """The shipped ball (activation distance 0.1 m, h = 10 ms) dropped at up to 100 m/s from
    heights beyond the activation distance: every exact step with pruning equals the step with
    every candidate in the LCP, and nothing penetrates (was: 0.55 m deep, then 49 m up)."""
    model = build_scene_model("ball_throw")
    cm = model.contact_model
    nq = cm.nq
    pruned = model.stepper()
    full = model.stepper(activation_distance=np.inf)
    heights = np.repeat([0.06, 0.15, 0.2, 0.5, 1.2], 4)
    speeds = np.tile([1.0, 15.0, 50.0, 100.0], 5)
    x = np.tile(model.x0, (heights.size, 1))  # q = (quaternion, x, y, z), v = (w, vx, vy, vz)
    x[:, 6], x[:, nq:] = heights, 0.0
    x[:, nq + 5] = -speeds
    x[:, nq + 4] = 2.0  # and sliding sideways
    for _ in range(20):
        a = pruned.step(x, np.zeros((len(x), cm.nu)), jacobians=False)
        b = full.step(x, np.zeros((len(x), cm.nu)), jacobians=False)
        assert a.converged.all() and b.converged.all()
        np.testing.assert_allclose(a.x_next, b.x_next, rtol=1e-9, atol=1e-12)
        assert cm.distances(a.x_next[:, :nq]).min() > -1e-9
        x = a.x_next


def test_a_step_that_runs_out_of_repairs_is_flagged(monkeypatch):
    """With no repair allowed, the fast ball's pruned step passes through the ground: it must
    come back flagged, never labelled converged."""
    from drake_abs.multibody import stepper as stepper_module

    monkeypatch.setattr(stepper_module, "MAX_REPAIRS", 0)
    model = build_scene_model("ball_throw")
    nq = model.contact_model.nq
    x = model.x0.copy()  # q = (quaternion, x, y, z), v = (w, vx, vy, vz)
    x[6], x[nq:] = 0.5, 0.0
    x[nq + 5] = -100.0
    for _ in range(3):
        with pytest.warns(stepper_module.StepOverflowWarning, match="repairs"):
            r = model.stepper().step(x[None], np.zeros((1, model.contact_model.nu)))
        if model.contact_model.distances(r.x_next[:, :nq]).min() < -1e-6:
            assert not r.converged[0]
            return
        x = r.x_next[0]
    raise AssertionError("the ball never reached the ground")
