"""Learning the toy's ground height (drake_abs.learning.ground_height_fit): the data put the
asked fraction near the ground, the mean losses' derivatives match central differences, the
fits and the descent recover the true height from noise-free data with every loss, and the
explicit loss needs over 100 times the data to match the violation loss's bound."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.learning import GroundToy
from drake_abs.learning import ground_height_fit as fit
from drake_abs.learning.generalization import (
    data_ratio,
    generalization_bound,
    lipschitz_table,
    loss_lipschitz,
    toy_bounds,
)

TOY = GroundToy()
EPS = 0.25


def test_sample_puts_the_asked_fraction_near_the_ground():
    z, v, y = fit.sample_near_ground(TOY, np.random.default_rng(0), 4000, noise=0.0, near=0.5)
    close = z <= 2 * TOY.v_max * TOY.dt
    assert 0.45 < close.mean() < 0.55 and np.all(z >= 0)
    np.testing.assert_allclose(y, TOY.f(0.0, z, v), atol=1e-12)  # noise-free: the exact model
    with pytest.raises(ValueError, match="near"):
        fit.sample_near_ground(TOY, np.random.default_rng(0), 10, noise=0.0, near=1.5)


@pytest.mark.parametrize(("kind", "mu"), [("explicit", 0.0), ("explicit", 1e-3), ("violation", 0)])
def test_mean_loss_derivative_matches_central_differences(kind, mu):
    data = fit.sample_near_ground(TOY, np.random.default_rng(1), 200, noise=0.05, near=0.5)
    theta, h = 0.013, 1e-7
    _, g = fit.mean_loss(TOY, kind, theta, data, eps=EPS, mu=mu)
    up, down = (fit.mean_loss(TOY, kind, theta + s, data, eps=EPS, mu=mu)[0] for s in (h, -h))
    assert g == pytest.approx((up - down) / (2 * h), rel=1e-4, abs=1e-6)
    landscape = fit.loss_landscape(TOY, kind, [theta, 0.0], data, eps=EPS, mu=mu)
    assert landscape[0] == fit.mean_loss(TOY, kind, theta, data, eps=EPS, mu=mu)[0]


def test_noise_free_data_give_the_true_height_with_every_loss():
    data = fit.sample_near_ground(TOY, np.random.default_rng(0), 300, noise=0.0, near=0.5)
    for kind in fit.KINDS:
        assert abs(fit.fit_height(TOY, kind, data, eps=EPS, search=0.1)) < 1e-6, kind
        for t0 in (-0.05, 0.02):
            final = fit.descend_height(TOY, kind, data, t0, eps=EPS, steps=200)
            assert abs(final) < 1e-4, (kind, t0, final)
        assert fit.descend_height(TOY, kind, data, 0.05, eps=EPS, steps=0) == 0.05


def test_explicit_loss_needs_two_orders_of_magnitude_more_data():
    bounds = toy_bounds(TOY, EPS)
    lip = loss_lipschitz(lipschitz_table(TOY, EPS), bounds, EPS)
    ratio = data_ratio(lip, bounds, 1e4, 0.05)
    assert ratio > 100
    target = generalization_bound(lip["vimp"], bounds.B_theta, bounds.B_vimp, 1e4)
    at = generalization_bound(lip["exp"], bounds.B_theta, bounds.B_exp, 1e4 * ratio)
    assert at == pytest.approx(target, rel=1e-9)
    with pytest.raises(ValueError, match="n0"):
        data_ratio(lip, bounds, 0.5)


def test_bad_arguments_are_named():
    data = fit.sample_near_ground(TOY, np.random.default_rng(0), 20, noise=0.0, near=0.5)
    with pytest.raises(ValueError, match="kind"):
        fit.mean_loss(TOY, "implicit", 0.0, data, eps=EPS)
    with pytest.raises(ValueError, match="search"):
        fit.fit_height(TOY, "explicit", data, eps=EPS, search=0.0)
    with pytest.raises(ValueError, match="thetas"):
        fit.loss_landscape(TOY, "explicit", [[0.0]], data, eps=EPS)
