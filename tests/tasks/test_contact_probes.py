"""The impact and push probes of Zhang et al. 2023, Figure 6 (drake_abs.tasks.contact_probes).

(a) the dropped mass's exact derivative is an impulse-like ramp at the contact height whose mass
is the velocity jump; the smallest BS mu peaks near it with about that mass and tends to the GT
(0) away from contact on the flight side; first-order randomised smoothing with many samples
matches its predicted bias (the GT convolved with the Gaussian) within its standard error, and
with few samples it mostly returns the constant 0 near contact. (b) the pushed box's exact
gradient is the analytic 0 / slope step; RS's spread falls like 1/sqrt(N); BS is deterministic
and smooth across the threshold.
"""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.contact.smoothing import Fixed
from drake_abs.policy.randomized_smoothing import gaussian_smoothed, randomized_smoothing
from drake_abs.tasks.box_lcs import TranslatingBox
from drake_abs.tasks.contact_probes import (
    GRAVITY,
    drop_contact_height,
    drop_response,
    push_response,
    push_slope,
)

H, SPEED, STEPS = 0.002, 2.0, 100  # the drop: time step (s), downward speed (m/s), steps
BOX = TranslatingBox(friction=0.5, time_step=0.01)
PUSH_STEPS = 50
Y_C = drop_contact_height(SPEED, STEPS, H)


def drop(heights, smoothing=None):
    return drop_response(heights, drop_speed=SPEED, steps=STEPS, time_step=H, smoothing=smoothing)


def push(forces, smoothing=None):
    return push_response(BOX, forces, steps=PUSH_STEPS, smoothing=smoothing)


def test_exact_derivative_is_an_impulse_of_the_velocity_jump():
    ys = Y_C + np.linspace(-0.02, 0.02, 2001)
    f, g, conv = drop(ys)
    assert conv.all()
    jump = f[-1] - f[0]
    v_T = -SPEED - GRAVITY * H * STEPS
    assert jump == pytest.approx(v_T, rel=1e-9)
    ramp = np.abs(g) > 1e-6
    assert np.abs(g).max() == pytest.approx(1 / H, rel=1e-6)  # the ramp: slope -1/h
    assert np.ptp(ys[ramp]) < 2 * abs(v_T) * H  # width about |v| h
    assert np.sum(g) * (ys[1] - ys[0]) == pytest.approx(jump, rel=0.02)
    assert not ramp[ys < Y_C - 2 * abs(v_T) * H].any()  # landed: v = 0 whatever y0


def test_barrier_smoothing_approximates_the_impulse_and_tends_to_the_gt():
    ys = Y_C + np.linspace(-0.15, 0.15, 601)
    f_gt, g_gt, _ = drop(ys)
    f, g, conv = drop(ys, Fixed(1e-4))
    assert conv.all()
    jump = f_gt[-1] - f_gt[0]
    assert abs(ys[np.argmin(g)] - Y_C) < 0.02
    assert np.sum(g) * (ys[1] - ys[0]) == pytest.approx(jump, rel=0.1)
    level = 0.01 * np.abs(g_gt).max()  # smoothed: a wider peak
    assert np.sum(np.abs(g) > level) > 1.5 * np.sum(np.abs(g_gt) > level)
    above = ys > Y_C + 0.02  # still in flight at T: the GT is 0, BS's error decays with height
    err = np.abs(g - g_gt)[above]
    assert err[-1] < 0.02 * np.abs(g).max()
    assert np.all(np.diff(err[::20]) < 0)


def test_first_order_rs_matches_its_predicted_bias_and_misses_with_few_samples():
    rng = np.random.default_rng(5)
    sigma = 0.05
    y0 = Y_C + 1.5 * sigma  # the GT is 0 here; RS's expectation is not
    fine = Y_C + np.linspace(-6 * sigma, 6 * sigma, 2401)
    predicted = float(gaussian_smoothed([y0], fine, drop(fine).derivative, sigma)[0])
    assert drop(np.array([y0])).derivative[0] == pytest.approx(0.0, abs=1e-6)
    assert predicted < -1.0  # a bias of several 1/s against the GT
    N = 1000
    est = randomized_smoothing(drop, [y0], sigma, N, rng)
    assert est.zeroth_order is None and est.converged.shape == (1, N) and est.converged.all()
    _, g_s, _ = drop(y0 + sigma * np.random.default_rng(5).standard_normal(N))  # the same draws
    assert est.first_order[0] == g_s.mean()
    se = g_s.std() / np.sqrt(N)
    assert abs(est.first_order[0] - predicted) < 4 * se
    # with N = 10 samples per estimate, most estimates near contact miss the ramp entirely
    est = randomized_smoothing(drop, np.full(200, Y_C), sigma, 10, rng).first_order
    assert np.mean(np.abs(est) < 1e-3) > 0.4


def test_pushed_box_gradients_exact_rs_and_bs():
    rng = np.random.default_rng(2)
    u_c = BOX.friction * BOX.mass * GRAVITY
    _, g, conv = push(u_c + np.array([-2.0, -0.5, 0.5, 2.0]))
    assert conv.all()
    slope = push_slope(BOX, PUSH_STEPS)
    assert slope == pytest.approx(0.01**2 * 50 * 51 / 2)
    np.testing.assert_allclose(g, [0, 0, slope, slope], atol=1e-6 * slope)
    stds = [randomized_smoothing(push, np.full(40, u_c), 0.5, N, rng).first_order.std()
            for N in (4, 64)]  # fmt: skip
    assert stds[0] / stds[1] == pytest.approx(4.0, rel=0.4)  # sqrt(64 / 4)
    ug = u_c + np.linspace(-1.0, 1.0, 21)
    _, g_bs, conv = push(ug, Fixed(1e-5))
    np.testing.assert_array_equal(g_bs, push(ug, Fixed(1e-5)).derivative)
    assert conv.all()
    assert np.all(np.diff(g_bs) > 0) and 0.2 * slope < g_bs[10] < 0.8 * slope
    # mu = 1e-6: the frictional steps that the solver's default start lost are solved by its
    # second starts; the gradient is a smooth sigmoid across the threshold
    _, g6, conv6 = push(ug, Fixed(1e-6))
    assert conv6.all() and np.all(np.diff(g6) > 0)
    # mu = 1e-4: every push converges since the solver holds a contact at its own target (the
    # friction rows' mu / h is 100 times the normal rows' mu; 10 of 121 pushes failed before),
    # and the gradient is a flatter sigmoid than at 1e-5 (larger mu: more smoothing)
    _, g4, conv4 = push(ug, Fixed(1e-4))
    assert conv4.all() and np.all(np.diff(g4) > 0)
    assert g4[-1] - g4[0] < g_bs[-1] - g_bs[0]


def test_bad_inputs_are_named():
    with pytest.raises(ValueError, match="heights"):
        drop(np.array([[0.1]]))
    with pytest.raises(ValueError, match="steps"):
        drop_response([0.1], drop_speed=SPEED, steps=0, time_step=H)
    with pytest.raises(ValueError, match="drop_speed"):
        drop_response([0.1], drop_speed=np.nan, steps=STEPS, time_step=H)
    with pytest.raises(ValueError, match="time_step"):
        drop_contact_height(SPEED, STEPS, 0.0)
    with pytest.raises(ValueError, match="forces"):
        push([np.inf])
