"""Randomised smoothing of a scalar function's derivative (Suh et al. 2022; Zhang et al. 2023,
section 5): estimates of d/dx E_w[f(x + w)], w ~ N(0, sigma^2), at a batch of points.

- first order ("bundled"): ``(1/N) sum_i f'(x + w_i)``, from the function's exact derivative;
- zeroth order: ``(1/N) sum_i (f(x + w_i) - f(x)) w_i / sigma^2`` (Gaussian finite
  differences), from values only.

Both are unbiased for the derivative of the Gaussian-smoothed f, which
:func:`gaussian_smoothed` computes from the derivative on a fine grid. With few samples the
first-order estimate of a derivative concentrated on a narrow set (an impact's impulse) is
mostly the value away from it: an empirical bias.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from drake_abs._validation import as_count, as_finite_array

#: ``fun(points (K,)) -> (values (K,), derivatives (K,), converged (K,))``
Probe = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


class SmoothedDerivative(NamedTuple):
    """Estimates at B points from N samples each: ``first_order`` (B,), ``zeroth_order`` (B,)
    (None when no values at the points were given), ``converged`` (B, N) of the probe."""

    first_order: np.ndarray
    zeroth_order: np.ndarray | None
    converged: np.ndarray


def _sigma(sigma: float) -> float:
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma must be a finite number > 0; got {sigma!r}")
    return sigma


def randomized_smoothing(
    fun: Probe,
    x,
    sigma: float,
    samples: int,
    rng: np.random.Generator,
    *,
    values_at=None,
) -> SmoothedDerivative:
    """Randomised-smoothing estimates of the derivative at each point of ``x`` (B,).

    Args:
        fun: the probe, called once on all B * N perturbed points (row-major: point b's samples
            are ``b * N ... b * N + N - 1``).
        x: (B,) points, in the probe's input units.
        sigma: the Gaussian's standard deviation (same units), > 0.
        samples: N >= 1 per point.
        rng: the perturbations ``w = sigma * rng.standard_normal((B, N))``.
        values_at: (B,) f(x), for the zeroth-order estimate (None: first order only).
    """
    x = as_finite_array(x, "x", ndim=(1,))
    sigma = _sigma(sigma)
    N = as_count(samples, "samples", minimum=1)
    if values_at is not None:
        values_at = as_finite_array(values_at, "values_at", ndim=(1,))
        if values_at.shape != x.shape:
            raise ValueError(f"values_at must have shape (B,) = {x.shape}; got {values_at.shape}")
    w = sigma * rng.standard_normal((x.size, N))
    f, g, ok = fun((x[:, None] + w).ravel())
    f, g = np.reshape(f, w.shape), np.reshape(g, w.shape)
    zeroth = None if values_at is None else ((f - values_at[:, None]) * w).mean(axis=1) / sigma**2
    return SmoothedDerivative(g.mean(axis=1), zeroth, np.reshape(ok, w.shape))


def gaussian_smoothed(x, grid, derivative, sigma: float) -> np.ndarray:
    """The expectation of both estimates: the derivative (G,) given on a fine ``grid`` (G,)
    convolved with the Gaussian of standard deviation ``sigma``, at the points ``x`` (B,)
    (weights normalised over the grid, which should extend a few sigma past x)."""
    x = as_finite_array(x, "x", ndim=(1,))
    grid = as_finite_array(grid, "grid", ndim=(1,))
    derivative = np.asarray(derivative, dtype=float)
    if derivative.shape != grid.shape:
        raise ValueError(f"derivative must have the grid's shape {grid.shape}; got "
                         f"{derivative.shape}")  # fmt: skip
    kernel = np.exp(-0.5 * ((x[:, None] - grid[None]) / _sigma(sigma)) ** 2)
    return (kernel * derivative).sum(axis=1) / kernel.sum(axis=1)
