"""Paper 000 Figure 6, BS against randomised smoothing (experiments/smoothing_vs_rs.py).

Checks: (a) the exact derivative is an impulse-like ramp at the contact height whose mass is the
velocity jump; the smallest BS mu peaks near it with about that mass and tends to the GT (0)
away from contact on the flight side; first-order RS with many samples matches its predicted
bias (the GT convolved with the Gaussian) within its standard error, and with few samples it
mostly returns the constant 0 near contact. (b) the pushed box's exact gradient is the analytic
0 / slope step; RS's spread falls like 1/sqrt(N); BS is deterministic and smooth across the
threshold. The experiment at test size writes its files and reports against the paper.
"""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.contact.smoothing import Fixed
from drake_abs.experiments import smoothing_vs_rs as srs

CONFIG = srs.Config.test_size()


def test_exact_derivative_is_an_impulse_of_the_velocity_jump():
    y_c = srs.contact_height(CONFIG)
    ys = y_c + np.linspace(-0.02, 0.02, 2001)
    f, g, conv = srs.impact_values(CONFIG, ys)
    assert conv.all()
    jump = f[-1] - f[0]
    v_T = -CONFIG.drop_speed - srs.G * CONFIG.impact_time_step * CONFIG.impact_steps
    assert jump == pytest.approx(v_T, rel=1e-9)
    h = CONFIG.impact_time_step
    ramp = np.abs(g) > 1e-6
    assert np.abs(g).max() == pytest.approx(1 / h, rel=1e-6)  # the ramp: slope -1/h
    assert np.ptp(ys[ramp]) < 2 * abs(v_T) * h  # width about |v| h
    assert np.sum(g) * (ys[1] - ys[0]) == pytest.approx(jump, rel=0.02)


def test_barrier_smoothing_approximates_the_impulse_and_tends_to_the_gt():
    y_c = srs.contact_height(CONFIG)
    ys = y_c + np.linspace(-0.15, 0.15, 601)
    f_gt, g_gt, _ = srs.impact_values(CONFIG, ys)
    mu = min(CONFIG.impact_mus)
    f, g, conv = srs.impact_values(CONFIG, ys, Fixed(mu))
    assert conv.all()
    jump = f_gt[-1] - f_gt[0]
    assert abs(ys[np.argmin(g)] - y_c) < 0.02
    assert np.sum(g) * (ys[1] - ys[0]) == pytest.approx(jump, rel=0.1)
    level = 0.01 * np.abs(g_gt).max()  # smoothed: a wider peak
    assert np.sum(np.abs(g) > level) > 1.5 * np.sum(np.abs(g_gt) > level)
    above = ys > y_c + 0.02  # still in flight at T: the GT is 0, BS's error decays with height
    err = np.abs(g - g_gt)[above]
    assert err[-1] < 0.02 * np.abs(g).max()
    assert np.all(np.diff(err[::20]) < 0)


def test_first_order_rs_matches_its_predicted_bias_and_misses_with_few_samples():
    rng = np.random.default_rng(5)
    sigma = CONFIG.impact_sigma
    y_c = srs.contact_height(CONFIG)
    y0 = y_c + 1.5 * sigma  # the GT is 0 here; RS's expectation is not
    fine = y_c + np.linspace(-6 * sigma, 6 * sigma, 2401)
    _, g_fine, _ = srs.impact_values(CONFIG, fine)
    weights = np.exp(-0.5 * ((y0 - fine) / sigma) ** 2)
    predicted = float((weights * g_fine).sum() / weights.sum())
    _, g_gt, _ = srs.impact_values(CONFIG, np.array([y0]))
    assert g_gt[0] == pytest.approx(0.0, abs=1e-6)
    assert predicted < -1.0  # a bias of several 1/s against the GT
    N = 1000
    _, g_s, _ = srs.impact_values(CONFIG, y0 + sigma * rng.standard_normal(N))
    se = g_s.std() / np.sqrt(N)
    assert abs(g_s.mean() - predicted) < 4 * se
    # with N = 10 samples per estimate, most estimates near contact miss the ramp entirely
    _, g10, _ = srs.impact_values(CONFIG, y_c + sigma * rng.standard_normal(10 * 200))
    est = g10.reshape(200, 10).mean(axis=1)
    assert np.mean(np.abs(est) < srs.ZERO) > 0.4


def test_pushed_box_gradients_exact_rs_and_bs():
    rng = np.random.default_rng(2)
    u_c = CONFIG.friction * 1.0 * srs.G
    us = u_c + np.array([-2.0, -0.5, 0.5, 2.0])
    _, g, conv = srs.push_gradients(CONFIG, us)
    assert conv.all()
    T, h = CONFIG.push_steps, CONFIG.time_step
    slope = h * h * T * (T + 1) / 2
    np.testing.assert_allclose(g, [0, 0, slope, slope], atol=1e-6 * slope)
    stds = []
    for N in (4, 64):
        w = 0.5 * rng.standard_normal((40, N))
        _, gs, _ = srs.push_gradients(CONFIG, (u_c + w).ravel())
        stds.append(gs.reshape(40, N).mean(axis=1).std())
    assert stds[0] / stds[1] == pytest.approx(4.0, rel=0.4)  # sqrt(64 / 4)
    ug = u_c + np.linspace(-1.0, 1.0, 21)
    _, g_bs, conv = srs.push_gradients(CONFIG, ug, Fixed(1e-5))
    _, g_bs2, _ = srs.push_gradients(CONFIG, ug, Fixed(1e-5))
    np.testing.assert_array_equal(g_bs, g_bs2)
    assert conv.all()
    assert np.all(np.diff(g_bs) > 0) and 0.2 * slope < g_bs[10] < 0.8 * slope
    # mu = 1e-6: the frictional steps that the solver's default start lost are solved by its
    # second starts; the gradient is a smooth sigmoid across the threshold
    _, g6, conv6 = srs.push_gradients(CONFIG, ug, Fixed(1e-6))
    assert conv6.all() and np.all(np.diff(g6) > 0)
    # mu = 1e-4: every push converges since the solver holds a contact at its own target (the
    # friction rows' mu / h is 100 times the normal rows' mu; 10 of 121 pushes failed before),
    # and the gradient is a flatter sigmoid than at 1e-5 (larger mu: more smoothing)
    _, g4, conv4 = srs.push_gradients(CONFIG, ug, Fixed(1e-4))
    assert conv4.all() and np.all(np.diff(g4) > 0)
    assert g4[-1] - g4[0] < g_bs[-1] - g_bs[0]


def test_experiment_writes_its_results(tmp_path):
    config = srs.Config(
        heights=41, rs_heights=9, fine_heights=801, impact_samples=(10,), impact_repeats=3,
        pushes=9, push_samples=(4, 16), push_repeats=4, impact_mus=(1e-4,), friction_mus=(1e-5,),
    )  # fmt: skip
    summary = srs.run(config, tmp_path)
    for name in ("figure6.png", "rs_cost.png", "summary.json", "curves.json"):
        assert (tmp_path / name).is_file()
    assert set(summary["claims"]) == set(srs.PAPER_CLAIMS)
    assert summary["friction"]["rs_cost_for_tolerance"]["0.01"]["samples"] > 100
    assert "paper:" in srs.report(summary)
