"""Fitting model parameters theta to data: random search on a loss (Zhang et al. 2023,
Algorithm 2's model update, which minimises eq. 6.1 by random search) and gradient descent on
a loss with its gradient (L-BFGS-B from scipy, with bounds).

Both work in scaled coordinates ``z = (theta - theta0) / scale``: ``scale`` (P,) is each
parameter's typical size (e.g. 0.01 m for a ground height, 0.1 for a friction coefficient,
10 % of a mass), so that one step size suits parameters of different units.

A loss is any callable ``theta -> LossValue``
(:class:`~drake_abs.learning.scene_losses.ModelLoss` is one); random search reads only its
``loss``, gradient descent also its ``grad``.
Evaluations whose value is not fully converged (``all_converged`` False) are counted in the
result's history; they are not hidden.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize


@dataclass(frozen=True)
class FitResult:
    """A fit's outcome.

    Attributes:
        theta: (P,) the best parameters found.
        loss: the loss there.
        method: ``"random_search"`` or ``"gradient"``.
        evaluations: loss evaluations used (a gradient counts as part of its evaluation).
        history: one row per iteration: (evaluations so far, best loss so far).
        unconverged_evaluations: evaluations with some unconverged term.
        seconds: wall time.
        message: the optimiser's own status (gradient) or a summary (random search).
        thetas: (iterations + 1, P) the best parameters after each iteration.
        start_loss: the loss at theta0.
    """

    theta: np.ndarray
    loss: float
    method: str
    evaluations: int
    history: np.ndarray
    unconverged_evaluations: int
    seconds: float
    message: str = ""
    thetas: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    start_loss: float = float("nan")


def _setup(theta0, scale, lower, upper):
    theta0 = np.asarray(theta0, dtype=float).reshape(-1)
    P = theta0.size
    if P == 0 or not np.all(np.isfinite(theta0)):
        raise ValueError(f"theta0 must be a non-empty vector of finite numbers; got {theta0}")
    scale = np.broadcast_to(np.asarray(scale, dtype=float), (P,)).copy()
    if not np.all(np.isfinite(scale) & (scale > 0)):
        raise ValueError(f"scale must be > 0 and finite, one per parameter ({P}); got {scale}")
    lo = np.full(P, -np.inf) if lower is None else np.broadcast_to(np.asarray(lower, float), (P,))
    hi = np.full(P, np.inf) if upper is None else np.broadcast_to(np.asarray(upper, float), (P,))
    slack = 1e-9 * (1.0 + np.abs(theta0))  # a bound reached by a previous fit, to rounding
    if np.any(lo > hi) or np.any(theta0 < lo - slack) or np.any(theta0 > hi + slack):
        raise ValueError(f"need lower <= theta0 <= upper; got {lo}, {theta0}, {hi}")
    theta0 = np.clip(theta0, lo, hi)
    return theta0, scale, lo, hi


def fit_random_search(
    loss: Callable,
    theta0,
    scale,
    *,
    iterations: int = 50,
    directions: int = 8,
    top: int | None = None,
    step_size: float = 0.5,
    noise: float = 0.3,
    lower=None,
    upper=None,
    seed: int = 0,
) -> FitResult:
    """Random search (Mania et al.'s V1-t update, on a loss instead of a return): per
    iteration, ``directions`` Gaussian directions delta in scaled coordinates, the loss at
    ``z +- noise delta``, and ``z <- z - step_size / (top sigma) sum_top (L+ - L-) delta`` over
    the ``top`` directions with the smallest ``min(L+, L-)`` (sigma: the standard deviation of
    those 2 top losses). A direction with a non-finite loss (a failed evaluation) is left out;
    an iteration with none usable makes no step. Parameters are clipped to ``[lower, upper]``.
    Seeded; returns the best parameters evaluated. Uses ``1 + iterations (2 directions + 1)``
    evaluations."""
    theta0, scale, lo, hi = _setup(theta0, scale, lower, upper)
    if iterations < 1 or directions < 1:
        raise ValueError(f"iterations and directions must be >= 1; got {iterations}, {directions}")
    top = directions if top is None else int(top)
    if not 1 <= top <= directions:
        raise ValueError(f"top must be in [1, directions={directions}]; got {top}")
    if not (step_size > 0 and noise > 0):
        raise ValueError(f"step_size and noise must be > 0; got {step_size}, {noise}")
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    evals = unconverged = 0

    def value(z):
        nonlocal evals, unconverged
        theta = np.clip(theta0 + scale * z, lo, hi)
        r = loss(theta)
        evals += 1
        unconverged += not r.all_converged
        return float(r.loss) if np.isfinite(r.loss) else np.inf, theta

    z = np.zeros(theta0.size)
    best, best_theta = value(z)
    history, thetas = [(evals, best)], [best_theta]
    for _ in range(iterations):
        delta = rng.standard_normal((directions, theta0.size))
        plus = np.array([value(z + noise * d)[0] for d in delta])
        minus = np.array([value(z - noise * d)[0] for d in delta])
        # the directions whose two losses are finite (an evaluation that failed carries no
        # usable difference), the top ones of them by their better loss
        usable = np.flatnonzero(np.isfinite(plus) & np.isfinite(minus))
        keep = usable[np.argsort(np.minimum(plus, minus)[usable])][:top]
        sigma = np.concatenate([plus[keep], minus[keep]]).std() if keep.size else 0.0
        if sigma > 0:
            diff = plus[keep] - minus[keep]
            z = z - step_size / (keep.size * sigma) * (diff @ delta[keep])
        z = (np.clip(theta0 + scale * z, lo, hi) - theta0) / scale
        current, theta = value(z)
        if current < best:
            best, best_theta = current, theta
        history.append((evals, best))
        thetas.append(best_theta)
    return FitResult(
        best_theta, best, "random_search", evals, np.array(history), unconverged,
        time.perf_counter() - start, f"{iterations} iterations x {directions} directions",
        np.array(thetas), history[0][1],
    )  # fmt: skip


def fit_gradient(
    loss: Callable,
    theta0,
    scale,
    *,
    iterations: int = 50,
    lower=None,
    upper=None,
    tol: float = 1e-12,
) -> FitResult:
    """Gradient descent on a loss with its gradient: scipy's L-BFGS-B in scaled coordinates,
    with the bounds ``[lower, upper]``, at most ``iterations`` iterations."""
    theta0, scale, lo, hi = _setup(theta0, scale, lower, upper)
    start = time.perf_counter()
    evals = unconverged = 0
    best = [np.inf, theta0]
    history, thetas = [], []
    first = []

    def fun(z):
        nonlocal evals, unconverged
        theta = np.clip(theta0 + scale * z, lo, hi)  # L-BFGS-B keeps z in bounds, to rounding
        r = loss(theta)
        evals += 1
        unconverged += not r.all_converged
        f = float(r.loss)
        if not first:
            first.append(f)
        if not np.isfinite(f):
            return np.inf, np.zeros_like(z)
        if f < best[0]:
            best[:] = [f, theta]
        return f, np.asarray(r.grad, float) * scale

    def record(_z):
        history.append((evals, best[0]))
        thetas.append(best[1])

    bounds = list(zip((lo - theta0) / scale, (hi - theta0) / scale, strict=True))
    bounds = [(None if np.isinf(a) else a, None if np.isinf(b) else b) for a, b in bounds]
    res = minimize(fun, np.zeros(theta0.size), jac=True, method="L-BFGS-B", bounds=bounds,
                   callback=record, options={"maxiter": int(iterations), "ftol": tol,
                                             "gtol": tol})  # fmt: skip
    if not history:
        record(None)
    return FitResult(
        np.asarray(best[1], float), float(best[0]), "gradient", evals, np.array(history),
        unconverged, time.perf_counter() - start, str(res.message), np.array(thetas), first[0],
    )  # fmt: skip
