"""Moving between AutoDiffXd arrays and (value, gradient) pairs of float arrays.

Drake systems of this package solve in double and inject the implicit-function-theorem Jacobians
into the derivatives, instead of pushing AutoDiffXd through the interior-point iterations.
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff

from drake_abs.contact.unconverged import apply_on_unconverged


def is_autodiff(arr: np.ndarray) -> bool:
    """True for an object array of AutoDiffXd (as Drake hands state and ports under AutoDiffXd)."""
    return arr.dtype == object and arr.size > 0 and isinstance(arr.flat[0], AutoDiffXd)


def split(arrays: list[np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Values (n_i,) and gradients (n_i, k) of AutoDiffXd vectors.

    Vectors whose entries carry no derivatives get zero gradients of width k; non-empty
    derivative vectors of different lengths raise ``ValueError`` (they cannot be combined).
    """
    values = [ExtractValue(a).ravel() if a.size else np.zeros(0) for a in arrays]
    grads = [ExtractGradient(a) if a.size else np.zeros((0, 0)) for a in arrays]
    widths = {g.shape[1] for g in grads if g.shape[1] > 0}
    if len(widths) > 1:
        raise ValueError(
            f"AutoDiffXd inputs carry derivative vectors of different lengths {sorted(widths)}; "
            "seed every input with the same number of derivatives (as Drake requires)"
        )
    k = widths.pop() if widths else 0
    grads = [g if g.shape[1] == k else np.zeros((g.shape[0], k)) for g in grads]
    return values, grads


def join(value: np.ndarray, gradient: np.ndarray) -> np.ndarray:
    """An AutoDiffXd vector (n,) with the given value (n,) and gradient (n, k)."""
    return InitializeAutoDiff(value.reshape(-1, 1), gradient).ravel()


def chain(value: np.ndarray, d_dx: np.ndarray, d_du: np.ndarray, gx, gu) -> np.ndarray:
    """An AutoDiffXd vector with ``value`` and the chain rule ``d_dx gx + d_du gu``: a step's
    Jacobians (computed in double) applied to the derivatives its inputs x, u carried in."""
    return join(value, d_dx @ gx + d_du @ gu)


def guarded_jacobians(converged, on_unconverged: str, *jacobians: np.ndarray) -> list[np.ndarray]:
    """A step's Jacobians as the ``on_unconverged`` policy allows (see
    :mod:`drake_abs.contact.unconverged`): unchanged when every solve ``converged``; NaN under
    ``"drop"`` (the derivatives a Drake system passes on are then visibly unusable), unchanged
    under ``"flag"`` (both warn), an exception under ``"raise"``."""
    used = apply_on_unconverged(np.atleast_1d(converged).reshape(1, -1), on_unconverged)
    if used[0]:
        return list(jacobians)
    return [np.full_like(J, np.nan) for J in jacobians]
