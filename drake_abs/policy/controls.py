"""Scripted inputs: seeded open-loop input schedules for :func:`drake_abs.engine.open_loop`, and
control laws of the step index and the state as time-varying engine policies.

- :func:`held_random_inputs`: inputs drawn uniformly at random from a seeded generator, each
  held for ``hold`` steps (an open-loop excitation, e.g. of gymnasium's MuJoCo models in ctrl
  units).
- :class:`TimeVaryingController`: any law ``u = control(t, x)`` (a servo, a gait, a schedule
  indexed by t) as a :class:`~drake_abs.engine.protocols.TimeVaryingPolicy`, which
  :func:`drake_abs.engine.rollout` runs forward (``gradient=False``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drake_abs._validation import as_count

__all__ = ["TimeVaryingController", "held_random_inputs"]


def held_random_inputs(
    steps: int, nu: int, *, scale: float = 0.5, hold: int = 5, seed: int = 0
) -> np.ndarray:
    """Seeded piecewise-constant random inputs (steps, nu): blocks drawn uniformly in
    ``[-scale, scale]`` (the input's units) by ``numpy.random.default_rng(seed)``, each held for
    ``hold`` steps. The blocks are drawn row by row, so the first k rows do not depend on
    ``steps`` (a longer schedule continues a shorter one)."""
    steps = as_count(steps, "steps")
    nu = as_count(nu, "nu", minimum=1)
    hold = as_count(hold, "hold", minimum=1)
    if not (np.isfinite(scale) and scale >= 0):
        raise ValueError(f"scale must be a finite number >= 0; got {scale!r}")
    rng = np.random.default_rng(seed)
    blocks = rng.uniform(-scale, scale, (-(-steps // hold), nu))
    return np.repeat(blocks, hold, axis=0)[:steps]


class TimeVaryingController:
    """A control law of the step index and the state as an engine policy (forward only).

    Args:
        control: ``control(t, x) -> u``: t the step index (int, from 0), x (M, nx) the batch of
            states, u (M, nu) or (nu,) (one input for every state).
        nx, nu: the state's and the input's sizes.

    ``act(theta, x, t)`` ignores theta (pass an empty array to the engine).
    """

    time_varying = True

    def __init__(self, control: Callable[[int, np.ndarray], np.ndarray], nx: int, nu: int):
        if not callable(control):
            raise TypeError(f"control must be callable as control(t, x); got {type(control)}")
        self.control = control
        self.nx = as_count(nx, "nx", minimum=1)
        self.nu = as_count(nu, "nu", minimum=1)

    def act(self, theta, x: np.ndarray, t: int) -> np.ndarray:
        """The inputs (M, nu) at step t for the states x (M, nx)."""
        x = np.asarray(x, dtype=float)
        u = np.asarray(self.control(t, x), dtype=float)
        if u.shape not in ((self.nu,), (x.shape[0], self.nu)):
            raise ValueError(
                f"control(t, x) must return (nu,) or (M, nu) with nu = {self.nu}, "
                f"M = {x.shape[0]}; got shape {u.shape}"
            )
        return np.broadcast_to(u, (x.shape[0], self.nu))
