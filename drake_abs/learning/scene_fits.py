"""Fitting a multibody scene's model parameters to recorded transitions (Zhang et al. 2023,
section 6 and Algorithm 2's model update; Bianchini et al. 2022's losses): which parameters are
learned, where a fit starts (seeded, off the model file's values), and the fits by name.

- :func:`learned_names`: the ground height, one friction coefficient tied across the contacts,
  each body's mass, and the damping of each joint the model file damps;
- :func:`perturbed_start`: the fit's start, scales and bounds: the ground ``ground_offset`` m
  higher, the others scaled by seeded factors 1 +- perturbation * U(0.5, 1);
- :func:`fit_parameters`: one of :data:`FITS`: ``random_search`` on eq. 6.1 through the exact
  model (the paper's model update), or L-BFGS-B on the ``explicit`` loss through adaptive
  (contact-aware) smoothing, on the ``naive_implicit`` loss or on the ``violation_implicit``
  loss (:mod:`drake_abs.learning.scene_losses`, :mod:`drake_abs.learning.fitting`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from drake_abs.contact.smoothing import ContactAware, Exact
from drake_abs.learning.fitting import FitResult, fit_gradient, fit_random_search
from drake_abs.learning.scene_losses import ModelLoss

__all__ = ["FITS", "fit_parameters", "learned_names", "perturbed_start"]

#: The fits :func:`fit_parameters` runs, by name.
FITS = ("random_search", "explicit", "naive_implicit", "violation_implicit")


def learned_names(stepper) -> list[str]:
    """The parameters fitted on a scene stepper (its ``parameter_names`` and
    ``parameter_values``): ``ground_height``, ``friction[*]`` (one coefficient for every
    contact, where the scene has friction columns), each body's ``mass[...]``, and each
    ``damping[...]`` whose value in the model file is > 0."""
    names = stepper.parameter_names
    out = ["ground_height"]
    if any(n.startswith("friction[") for n in names):
        out.append("friction[*]")
    out += [n for n in names if n.startswith("mass[")]
    values = stepper.parameter_values()
    out += [n for n, v in zip(names, values, strict=True) if n.startswith("damping[") and v > 0]
    return out


def perturbed_start(
    names: Sequence[str],
    truth,
    *,
    ground_offset: float,
    perturbation: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A fit's (start, scale, lower, upper), each (P,), for the parameters ``names`` whose
    model-file values are ``truth`` (P,).

    Per parameter, in order, one factor 1 + perturbation * (+-1) * U(0.5, 1) is drawn from
    ``rng`` (two draws: the sign, the size). The ground height starts ``ground_offset`` m above
    its value (scale 0.01 m, bounds +- 0.2 m); a damping starts at value * factor (0.5 where the
    file has none; scale 0.1 max(value, 1), bounds [0, 10 max(value, 1)]); a friction
    coefficient or a mass at value * factor (scale 10 %, bounds [0.02, 5] times the value)."""
    truth = np.asarray(truth, dtype=float)
    if truth.shape != (len(names),):
        raise ValueError(f"truth must have shape ({len(names)},) (one per name); got {truth.shape}")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy Generator; got {type(rng).__name__}")
    start, scale, lo, hi = [], [], [], []
    for name, value in zip(names, truth, strict=True):
        factor = 1.0 + perturbation * rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 1.0)
        if name == "ground_height":
            start.append(value + ground_offset)
            scale.append(0.01)
            lo.append(value - 0.2)
            hi.append(value + 0.2)
        elif name.startswith("damping"):
            start.append(value * factor if value > 0 else 0.5)
            scale.append(0.1 * max(value, 1.0))
            lo.append(0.0)
            hi.append(10.0 * max(value, 1.0))
        else:  # friction, mass
            start.append(value * factor)
            scale.append(0.1 * value)
            lo.append(0.02 * value)
            hi.append(5.0 * value)
    return tuple(np.array(a, dtype=float) for a in (start, scale, lo, hi))


def fit_parameters(
    stepper,
    x,
    u,
    x_next,
    fit: str,
    names: Sequence[str],
    start,
    scale,
    lower,
    upper,
    *,
    eps: float = 1e-3,
    contact_aware: tuple[float, float] = (1e-3, 0.02),
    search_iterations: int = 15,
    search_directions: int = 4,
    gradient_iterations: int = 30,
    max_transitions: int = 800,
    seed: int = 0,
) -> FitResult:
    """One fit (``fit`` in :data:`FITS`) of the parameters ``names`` of the scene stepper
    ``stepper`` (exact contact) to the transitions x (N, nx), u (N, nu) -> x_next (N, nx), from
    ``start`` with ``scale``, within [lower, upper] (each (P,)).

    At most ``max_transitions`` transitions are used (a seeded subset, kept in order);
    ``eps`` is the violation loss's relaxation (larger: looser complementarity);
    ``contact_aware`` (mu_max, length m) the smoothing the explicit fit differentiates
    through; random search runs ``search_iterations`` x ``search_directions``, L-BFGS-B at most
    ``gradient_iterations``. ``seed`` seeds the subset and the search."""
    rng = np.random.default_rng(seed)
    x, u, x_next = (np.asarray(a, dtype=float) for a in (x, u, x_next))
    if x.shape[0] > max_transitions:
        keep = np.sort(rng.choice(x.shape[0], max_transitions, replace=False))
        x, u, x_next = x[keep], u[keep], x_next[keep]
    if fit == "random_search":
        loss = ModelLoss(stepper.with_smoothing(Exact()), x, u, x_next, names, "explicit",
                         gradient=False)  # fmt: skip
        return fit_random_search(loss, start, scale, iterations=search_iterations,
                                 directions=search_directions, lower=lower, upper=upper,
                                 seed=seed)  # fmt: skip
    if fit == "explicit":
        smoothed = stepper.with_smoothing(ContactAware(*contact_aware))
        loss = ModelLoss(smoothed, x, u, x_next, names, "explicit")
    elif fit == "naive_implicit":
        loss = ModelLoss(stepper, x, u, x_next, names, "naive_implicit")
    elif fit == "violation_implicit":
        loss = ModelLoss(stepper, x, u, x_next, names, "violation_implicit", eps=eps)
    else:
        raise ValueError(f"fit must be one of {FITS}; got {fit!r}")
    return fit_gradient(loss, start, scale, iterations=gradient_iterations, lower=lower,
                        upper=upper)  # fmt: skip
