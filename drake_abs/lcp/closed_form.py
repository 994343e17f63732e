"""Closed-form solution of the one-contact mu-softened LCP (docs/math.md section 2).

For one contact the softened complementarity conditions

    lam >= 0,  s = z + F lam >= 0,  lam * s = mu

have the unique solution ``lam = (-z + sqrt(z^2 + 4 F mu)) / (2 F)``, and ``max(0, -z / F)`` at
``mu = 0``. These functions are the test oracle for the interior-point solver and are evaluated in
a cancellation-free form so that they stay accurate to machine precision for all signs of z.
"""

from __future__ import annotations

import numpy as np


def _root(z: np.ndarray, F: np.ndarray, mu: np.ndarray) -> np.ndarray:
    return np.hypot(z, 2.0 * np.sqrt(F * mu))


def softened_lcp_1d(z, F, mu) -> np.ndarray:
    """Impulse ``lam`` of the one-contact softened LCP; broadcasts over its arguments.

    Args:
        z: contact distance before the impulse acts (any shape).
        F: positive compliance ``F > 0`` (broadcastable to ``z``).
        mu: central-path value ``mu >= 0`` (broadcastable); larger mu is more smoothing.
    """
    z, F, mu = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (z, F, mu)))
    r = _root(z, F, mu)
    out = np.empty_like(z)
    neg = z <= 0
    # z <= 0: (-z + r) / (2F) has no cancellation; z > 0: rationalise to 2 mu / (z + r).
    out[neg] = (-z[neg] + r[neg]) / (2.0 * F[neg])
    pos = ~neg
    out[pos] = 2.0 * mu[pos] / (z[pos] + r[pos])
    return out


def softened_lcp_1d_dlam_dz(z, F, mu) -> np.ndarray:
    """``d lam / d z`` at fixed mu: ``-lam / sqrt(z^2 + 4 F mu)`` (-> -1/F active, 0 inactive).

    At ``mu = 0`` and ``z = 0`` the derivative does not exist; this returns the one-sided value
    of the active side, ``-1/F``, there.
    """
    z, F, mu = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (z, F, mu)))
    lam = softened_lcp_1d(z, F, mu)
    r = _root(z, F, mu)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = -lam / r
    return np.where(r > 0, out, -1.0 / F)


def softened_lcp_1d_dlam_dmu(z, F, mu) -> np.ndarray:
    """``d lam / d mu`` at fixed z: ``1 / sqrt(z^2 + 4 F mu)``."""
    z, F, mu = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (z, F, mu)))
    return 1.0 / _root(z, F, mu)
