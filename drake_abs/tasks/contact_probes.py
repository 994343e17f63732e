"""Two scalar responses of contact with their exact derivatives through the engine: an impact
(a dropped point mass) and stiction (a pushed box), what Zhang et al. (2023, Figure 6) probe to
compare smoothings.

- :func:`drop_response`: a 1-D point mass of 1 kg starts at heights y0 (m) moving down at
  ``drop_speed`` (m/s); the response is its vertical velocity after ``steps`` steps (m/s) and
  its derivative in y0 (1/s). Masses starting at or below :func:`drop_contact_height` have
  landed (inelastic: v = 0), those above are still falling, so the exact derivative is a ramp of
  slope -1/h and width about ``|v| h`` at that height, 0 elsewhere.
- :func:`push_response`: a :class:`~drake_abs.tasks.box_lcs.TranslatingBox` resting on the
  ground is pushed by a constant force u (N) for ``steps`` steps; the response is its final
  position (m) and its derivative in u (m/N): 0 below the friction threshold ``friction m g``,
  :func:`push_slope` above.

Both run every probe of a batch in one :func:`~drake_abs.engine.open_loop`. A probe whose
rollout took an unconverged step has ``converged`` False and a NaN derivative (the engine's
``on_unconverged="drop"``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from drake_abs._validation import as_count, as_finite_array
from drake_abs.contact.lcs import LcsStepper
from drake_abs.contact.smoothing import Smoothing
from drake_abs.engine import open_loop
from drake_abs.tasks.box_lcs import TranslatingBox
from drake_abs.tasks.point_mass import point_mass_lcs

#: Gravity (m/s^2) of the dropped point mass.
GRAVITY = 9.81


class Response(NamedTuple):
    """A batch of probes: ``value`` (B,), its ``derivative`` in the probe's input (B,), and
    whether each probe's rollout ``converged`` (B,)."""

    value: np.ndarray
    derivative: np.ndarray
    converged: np.ndarray


def drop_contact_height(drop_speed: float, steps: int, time_step: float) -> float:
    """y_c (m): the exact discrete model lands within ``steps`` steps iff y0 <= y_c (to within
    the last step's ramp). After k free steps of h (s) from y0 at the downward speed s (m/s) the
    height is y0 - k h s - g h^2 k (k + 1) / 2."""
    if not (np.isfinite(time_step) and time_step > 0):
        raise ValueError(f"time_step must be a finite number > 0 (s); got {time_step!r}")
    if not np.isfinite(drop_speed):
        raise ValueError(f"drop_speed must be a finite number (m/s); got {drop_speed!r}")
    h, T, v0 = time_step, as_count(steps, "steps", minimum=1), -drop_speed
    return -(T * h * v0 - GRAVITY * h * h * T * (T + 1) / 2)


def drop_response(
    heights,
    *,
    drop_speed: float,
    steps: int,
    time_step: float,
    smoothing: Smoothing | None = None,
) -> Response:
    """The dropped point mass from each height (B,) (m): its vertical velocity after ``steps``
    steps of ``time_step`` s (m/s) and the derivative in the height (1/s), under ``smoothing``
    (default exact contact)."""
    heights = as_finite_array(heights, "heights", ndim=(1,))
    steps = as_count(steps, "steps", minimum=1)
    if not np.isfinite(drop_speed):
        raise ValueError(f"drop_speed must be a finite number (m/s); got {drop_speed!r}")
    lcs = point_mass_lcs(1, time_step=time_step)
    x0 = np.column_stack([heights, np.full(heights.size, -drop_speed)])
    ro = open_loop(LcsStepper(lcs, smoothing), x0, np.zeros((steps, 1)))
    return Response(ro.x[:, -1, 1], ro.dxH_dx0[:, 1, 0], ro.converged.all(axis=1))


def push_response(
    box: TranslatingBox, forces, *, steps: int, smoothing: Smoothing | None = None
) -> Response:
    """``box`` from rest pushed by each constant force (B,) (N) for ``steps`` steps: its final
    position (m) and the derivative in the force (m/N), under the per-contact ``smoothing``
    (default exact contact)."""
    forces = as_finite_array(forces, "forces", ndim=(1,))
    steps = as_count(steps, "steps", minimum=1)
    x0 = np.tile(box.resting_state(), (forces.size, 1))
    u = np.repeat(forces[:, None, None], steps, axis=1)
    ro = open_loop(box.stepper(smoothing), x0, u)
    return Response(ro.x[:, -1, 0], ro.dxH_du[:, :, 0, 0].sum(axis=1), ro.converged.all(axis=1))


def push_slope(box: TranslatingBox, steps: int) -> float:
    """d p_T / d u (m/N) while the pushed box slides: sum over the steps of h^2 (T - t) / m."""
    T, h = as_count(steps, "steps", minimum=1), box.time_step
    return h * h * T * (T + 1) / 2 / box.mass
