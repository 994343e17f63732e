"""Learning the toy's ground height from data with one of its losses (Bianchini et al. 2022,
sections 2-4): data concentrated near contact, a loss's mean over a data set and its landscape
in theta, the height that minimises it, and gradient descent on it.

Losses by name (``kind``): ``"explicit"``, the prediction error through the LCP solver at a
central-path value mu (mu = 0: the exact model, equal to the naive-implicit loss on this toy;
larger mu: smoother), and ``"violation"``, the violation-implicit loss at relaxation eps
(:meth:`~drake_abs.learning.ground_toy.GroundToy.violation_implicit_loss`; larger eps: looser
complementarity). theta is the ground height (m); the losses are in (m/s)^2.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from drake_abs._validation import as_count, as_finite_array
from drake_abs.learning.ground_toy import GroundToy

#: The losses by name.
KINDS = ("explicit", "violation")

#: A data set (z, v, y) of heights in m, velocities and next velocities in m/s, each (n,).
Data = tuple[np.ndarray, np.ndarray, np.ndarray]


def _kind(kind: str) -> str:
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}; got {kind!r}")
    return kind


def sample_near_ground(
    toy: GroundToy, rng: np.random.Generator, n: int, *, noise: float, near: float
) -> Data:
    """n data points at the true height 0:
    :meth:`~drake_abs.learning.ground_toy.GroundToy.sample` (heights uniform in [0, phi_max],
    which puts about 1% of the points in contact) with a fraction ``near`` in [0, 1] redrawn
    within one step's travel of the ground, ``[0, 2 v_max dt]``, and their next velocity from
    the exact model plus Gaussian noise ``noise`` (m/s)."""
    if not 0.0 <= near <= 1.0:
        raise ValueError(f"near must be a fraction in [0, 1]; got {near!r}")
    z, v, y = toy.sample(rng, as_count(n, "n", minimum=1), 0.0, noise)
    close = rng.random(n) < near
    z[close] = rng.uniform(0.0, 2 * toy.v_max * toy.dt, close.sum())
    y[close] = toy.f(0.0, z[close], v[close]) + noise * rng.standard_normal(close.sum())
    return z, v, y


def mean_loss(
    toy: GroundToy, kind: str, theta: float, data: Data, *, eps: float, mu: float = 0.0
) -> tuple[float, float]:
    """The mean loss over ``data`` at height ``theta`` (m) and its derivative in theta;
    ``mu`` is the explicit loss's central-path value, ``eps`` the violation loss's relaxation.
    ``RuntimeError`` when a solve did not converge."""
    z, v, y = data
    if _kind(kind) == "explicit":
        loss, grad, ok = toy.explicit_loss(theta, z, v, y, mu)
        if not ok.all():
            raise RuntimeError(f"{(~ok).sum()} LCP solves did not converge at theta={theta}")
        return float(loss.mean()), float(grad.mean())
    r = toy.violation_implicit_loss(theta, z, v, y, eps)
    if not r.converged.all():
        raise RuntimeError("the violation loss's inner minimisation did not converge")
    return float(r.loss.mean()), float(r.grad[:, 0].mean())


def loss_landscape(
    toy: GroundToy, kind: str, thetas, data: Data, *, eps: float, mu: float = 0.0
) -> np.ndarray:
    """The mean loss (:func:`mean_loss`) at each height of ``thetas`` (T,): (T,)."""
    thetas = as_finite_array(thetas, "thetas", ndim=(1,))
    return np.array([mean_loss(toy, kind, t, data, eps=eps, mu=mu)[0] for t in thetas])


def fit_height(
    toy: GroundToy, kind: str, data: Data, *, eps: float, search: float, grid: int = 201
) -> float:
    """The height (m) minimising the mean loss: the best of ``grid`` heights over
    [-search, search], refined by a bounded scalar search between its neighbours (kept only if
    it is lower), so that the fit's error is statistical, not an optimiser's."""
    if not (np.isfinite(search) and search > 0):
        raise ValueError(f"search must be a finite number > 0 (m); got {search!r}")
    thetas = np.linspace(-search, search, as_count(grid, "grid", minimum=3))
    values = [mean_loss(toy, kind, t, data, eps=eps)[0] for t in thetas]
    k = int(np.argmin(values))
    lo, hi = thetas[max(k - 1, 0)], thetas[min(k + 1, thetas.size - 1)]
    res = minimize_scalar(lambda t: mean_loss(toy, kind, t, data, eps=eps)[0], bounds=(lo, hi),
                          method="bounded", options={"xatol": 1e-9})  # fmt: skip
    return float(res.x) if res.fun <= values[k] else float(thetas[k])


def descend_height(
    toy: GroundToy,
    kind: str,
    data: Data,
    theta0: float,
    *,
    eps: float,
    steps: int,
    step: float = 5e-3,
) -> float:
    """Gradient descent on the mean loss from ``theta0`` (m) with a normalised step, so that the
    losses' scales do not matter: ``theta -= step * sign(grad)``, the step (m) halving on each
    sign change, for at most ``steps`` steps (stopping on a zero gradient: a flat landscape
    gives no information). Returns the final height (m)."""
    theta, last = theta0, 0.0
    for _ in range(as_count(steps, "steps")):
        _, g = mean_loss(toy, kind, theta, data, eps=eps)
        if g == 0.0:
            break
        s = np.sign(g)
        if last and s != last:
            step *= 0.5
        theta -= step * s
        last = s
    return theta
