"""Randomised smoothing of a derivative (drake_abs.policy.randomized_smoothing) on functions
whose Gaussian-smoothed derivative is known: both estimates are unbiased, the first order has
no variance where f' is constant, the zeroth order is noisier, and the convolution on a grid
gives the smoothed derivative of a step (a Gaussian density)."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.policy.randomized_smoothing import gaussian_smoothed, randomized_smoothing


def cubic(x):
    """f = x^3: E[f'(x + w)] = 3 (x^2 + sigma^2)."""
    return x**3, 3 * x**2, np.ones(x.shape, bool)


def test_both_estimates_are_unbiased_and_the_first_order_is_less_noisy():
    x, sigma, N = np.array([-1.0, 0.0, 0.5]), 0.3, 20000
    est = randomized_smoothing(cubic, x, sigma, N, np.random.default_rng(0), values_at=x**3)
    exact = 3 * (x**2 + sigma**2)
    np.testing.assert_allclose(est.first_order, exact, atol=0.02)
    np.testing.assert_allclose(est.zeroth_order, exact, atol=0.15)
    assert est.converged.shape == (3, N) and est.converged.all()
    draws = [randomized_smoothing(cubic, x, sigma, 50, np.random.default_rng(s), values_at=x**3)
             for s in range(40)]  # fmt: skip
    spread_fo = np.std([d.first_order for d in draws], axis=0)
    spread_zo = np.std([d.zeroth_order for d in draws], axis=0)
    assert np.all(spread_fo < spread_zo)


def test_seeded_and_in_row_major_order():
    seen = []

    def probe(points):
        seen.append(points.copy())
        return cubic(points)

    x = np.array([0.0, 10.0])
    a = randomized_smoothing(probe, x, 0.1, 4, np.random.default_rng(3))
    b = randomized_smoothing(cubic, x, 0.1, 4, np.random.default_rng(3))
    np.testing.assert_array_equal(a.first_order, b.first_order)
    assert np.all(np.abs(seen[0][:4]) < 1) and np.all(np.abs(seen[0][4:] - 10) < 1)
    w = 0.1 * np.random.default_rng(3).standard_normal((2, 4))
    np.testing.assert_array_equal(seen[0], (x[:, None] + w).ravel())


def test_gaussian_smoothed_step_is_the_gaussian_density():
    grid = np.linspace(-1.0, 1.0, 20001)
    dx = grid[1] - grid[0]
    delta = np.where(np.abs(grid) < dx / 2, 1.0 / dx, 0.0)  # the derivative of a unit step
    sigma, x = 0.1, np.array([-0.1, 0.0, 0.2])
    density = np.exp(-0.5 * (x / sigma) ** 2) / (sigma * np.sqrt(2 * np.pi))
    np.testing.assert_allclose(gaussian_smoothed(x, grid, delta, sigma), density, rtol=1e-3)


def test_bad_arguments_are_named():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="sigma"):
        randomized_smoothing(cubic, [0.0], 0.0, 3, rng)
    with pytest.raises(ValueError, match="samples"):
        randomized_smoothing(cubic, [0.0], 0.1, 0, rng)
    with pytest.raises(ValueError, match="values_at"):
        randomized_smoothing(cubic, [0.0, 1.0], 0.1, 3, rng, values_at=[0.0])
    with pytest.raises(ValueError, match="x must be 1-D"):
        randomized_smoothing(cubic, [[0.0]], 0.1, 3, rng)
    with pytest.raises(ValueError, match="derivative"):
        gaussian_smoothed([0.0], [0.0, 1.0], [1.0], 0.1)
