"""A point mass above flat ground as an LCS: the bouncing/thrown ball of Zhang et al. (2023)
(Figure 1a).

Semi-implicit Euler with an impulse lam (N s) along the vertical axis (docs/math.md section 6 with
J_n = e_vertical, M = m I, no friction):

    v+ = v + h (u / m - g e_v) + lam / m e_v,       p+ = p + h v+
    contact:  p_v + h v_v+ - ground >= 0   perp   lam >= 0

State ``x = (p, v)`` (positions in m, velocities in m/s), input ``u`` a force (N), one contact.
"""

from __future__ import annotations

import numpy as np

from drake_abs.contact.lcs import LCS


def point_mass_lcs(
    dim: int = 2,
    *,
    time_step: float = 0.01,
    mass: float = 1.0,
    gravity: float = 9.81,
    ground_height: float = 0.0,
) -> LCS:
    """The LCS of a point mass in ``dim`` dimensions (1, 2 or 3) above the ground.

    The last coordinate is vertical. ``dx = 2 dim``, ``du = dim``, ``d = 1``; ``F = h / m``.
    """
    if dim not in (1, 2, 3):
        raise ValueError(f"dim must be 1, 2 or 3; got {dim!r}")
    for name, value in (("time_step", time_step), ("mass", mass)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0; got {value!r}")
    for name, value in (("gravity", gravity), ("ground_height", ground_height)):
        if not np.isfinite(value):
            raise ValueError(f"{name} must be finite; got {value!r}")
    h, m = float(time_step), float(mass)
    eye = np.eye(dim)
    e_v = eye[-1]
    A = np.block([[eye, h * eye], [np.zeros((dim, dim)), eye]])
    B = np.vstack([h * h / m * eye, h / m * eye])
    C = np.concatenate([h / m * e_v, e_v / m])[:, None]
    c = np.concatenate([-h * h * gravity * e_v, -h * gravity * e_v])
    D = np.concatenate([e_v, h * e_v])[None, :]
    E = (h * h / m * e_v)[None, :]
    F = np.array([[h / m]])
    d = np.array([-h * h * gravity - ground_height])
    return LCS(A, B, C, c, D, E, F, d, time_step=h)
