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

from drake_abs._validation import as_count

#: A fit's ``status`` (:attr:`FitResult.status`): ``"converged"``, the optimiser's own stopping
#: test was met at a finite loss; ``"iteration_limit"``, it ran all its iterations without
#: meeting it (random search has no stopping test and always ends so); ``"stopped"``, the
#: optimiser gave up for another reason (e.g. no descent along its line search: see
#: ``message``); ``"no_finite_loss"``, no evaluation gave a finite loss, so nothing was fitted.
STATUSES = ("converged", "iteration_limit", "stopped", "no_finite_loss")


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
        status: one of :data:`STATUSES`; ``"converged"`` only when the optimiser's stopping
            test was met at a finite loss (a fit whose losses were all NaN or inf says
            ``"no_finite_loss"``, whatever the optimiser's ``message`` says).
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
    status: str = "iteration_limit"

    @property
    def converged(self) -> bool:
        """Whether the optimiser's stopping test was met at a finite loss."""
        return self.status == "converged"


def _bound(value, name: str, P: int, fill: float) -> np.ndarray:
    """A lower or upper bound: None (``fill``, no bound), a number for every parameter, or one
    number per parameter (P,); ``ValueError`` naming ``name`` otherwise."""
    if value is None:
        return np.full(P, fill)
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf":
        raise ValueError(
            f"{name} must be None, a number or ({P},) numbers (one per parameter); got {value!r}"
        )
    arr = arr.astype(float)
    if arr.shape in ((), (1,)):
        arr = np.full(P, float(arr.reshape(-1)[0]))
    if arr.shape != (P,) or np.any(np.isnan(arr)):
        raise ValueError(
            f"{name} must be None, a number or ({P},) numbers (one per parameter, not NaN); got "
            f"shape {arr.shape}"
        )
    return arr


def _setup(theta0, scale, lower, upper):
    raw = np.asarray(theta0)
    if raw.dtype.kind not in "iuf":
        raise ValueError(f"theta0 must be a vector of real numbers; got dtype {raw.dtype}")
    theta0 = raw.astype(float).reshape(-1)
    P = theta0.size
    if P == 0 or not np.all(np.isfinite(theta0)):
        raise ValueError(f"theta0 must be a non-empty vector of finite numbers; got {theta0}")
    scale_raw = np.asarray(scale)
    if scale_raw.dtype.kind not in "iuf" or scale_raw.shape not in ((), (1,), (P,)):
        raise ValueError(
            f"scale must be a number or ({P},) numbers (one per parameter), each > 0; got {scale!r}"
        )
    scale = np.broadcast_to(scale_raw.astype(float), (P,)).copy()
    if not np.all(np.isfinite(scale) & (scale > 0)):
        raise ValueError(f"scale must be > 0 and finite, one per parameter ({P}); got {scale}")
    lo = _bound(lower, "lower", P, -np.inf)
    hi = _bound(upper, "upper", P, np.inf)
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
    iterations = as_count(iterations, "iterations", minimum=1)
    directions = as_count(directions, "directions", minimum=1)
    top = directions if top is None else as_count(top, "top", minimum=1)
    if not 1 <= top <= directions:
        raise ValueError(f"top must be in [1, directions={directions}]; got {top}")
    for name, value in (("step_size", step_size), ("noise", noise)):
        if not _positive(value):
            raise ValueError(f"{name} must be a finite number > 0; got {value!r}")
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
        "iteration_limit" if np.isfinite(best) else "no_finite_loss",
    )  # fmt: skip


def _positive(value) -> bool:
    """Whether ``value`` is a real number (not a bool) that is finite and > 0."""
    return (isinstance(value, int | float | np.integer | np.floating)
            and not isinstance(value, bool) and bool(np.isfinite(value)) and value > 0)  # fmt: skip


def _status(res, best: float) -> str:
    """The :data:`STATUSES` entry of an L-BFGS-B result ``res`` whose best loss is ``best``."""
    if not np.isfinite(best):
        return "no_finite_loss"
    if res.status == 0:
        return "converged"
    return "iteration_limit" if res.status == 1 else "stopped"


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
    with the bounds ``[lower, upper]`` (None, a number, or one per parameter), at most
    ``iterations`` iterations (a whole number >= 1); ``tol`` > 0 is L-BFGS-B's ``ftol`` and
    ``gtol``. The result's ``status`` (:data:`STATUSES`) says whether it converged."""
    theta0, scale, lo, hi = _setup(theta0, scale, lower, upper)
    iterations = as_count(iterations, "iterations", minimum=1)
    if not _positive(tol):
        raise ValueError(f"tol must be a finite number > 0; got {tol!r}")
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
        _status(res, best[0]),
    )  # fmt: skip
