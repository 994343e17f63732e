"""Joint damping treated implicitly in the step (docs/math.md section 6c).

A viscous joint damping ``tau_d = -D v`` (D diagonal, N m s / rad or N s / m per velocity) taken
at the end of the step, ``M (v+ - v) = h (tau - n - D v+) + J' lam``, is stable at any time step
(an explicit ``-D v`` diverges once ``h D / M > 2``: a model's light links with heavy damping).
With ``A = (I + h W D)^-1`` (W = M^-1) the step's quantities become

    W' = (M + h D)^-1 = A W,        v_free' = A v_free,

and the rest of the step is unchanged. Their derivatives, for D constant:

    dW' . f = A dW . (f - h D W' f),        dv_free' = A (dv_free - h dW . (D v_free')),

so a provider's ``dW . f`` (or ``dW_times``) carries over without forming dW.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from drake_abs.contact.step_data import ParameterDerivatives, StepQuantities


def check_damping(damping: np.ndarray, nv: int, h: float) -> np.ndarray:
    """``damping`` as nv finite numbers >= 0 (N m s / rad or N s / m per velocity); raises a
    ValueError naming the argument otherwise (and for a time step h that is not > 0)."""
    damping = np.asarray(damping, dtype=float)
    if damping.shape != (nv,) or not np.all(np.isfinite(damping)) or np.any(damping < 0):
        raise ValueError(
            f"damping must be {nv} finite numbers >= 0 (one per velocity); got {damping!r}"
        )
    if not (np.isfinite(h) and h > 0):
        raise ValueError(f"h must be a finite number > 0; got {h!r}")
    return damping


def implicit_damping(
    quant: StepQuantities,
    damping: np.ndarray,
    h: float,
    parameters: ParameterDerivatives | None = None,
) -> tuple[StepQuantities, ParameterDerivatives | None]:
    """The quantities (and model-parameter derivatives) of a step with the joint damping
    ``damping`` (nv,) applied implicitly (module docstring). Returns them unchanged when every
    entry is 0."""
    W = np.asarray(quant.W, dtype=float)
    B, nv = quant.v_free.shape
    D = check_damping(damping, nv, h)
    if not D.any():
        return quant, parameters
    A = np.linalg.inv(np.eye(nv) + h * W * D[None, None, :])  # (I + h W D)^-1, (B, nv, nv)
    W2 = A @ W
    v_free2 = np.einsum("bij,bj->bi", A, quant.v_free)
    values = dict(W=W2, v_free=v_free2)
    if quant.has_derivatives:
        inner_dW_dot = quant.dW_dot

        def dW_times(f: np.ndarray) -> np.ndarray:
            g = f - h * D * np.einsum("bij,bj->bi", W2, f)
            return A @ inner_dW_dot(g)

        dv = quant.dv_free - h * inner_dW_dot(D * v_free2)
        values.update(dW=None, dW_times=dW_times, dv_free=A @ dv)
    out = replace(quant, **values)
    if parameters is not None:
        parameters = damped_parameters(parameters, W2, v_free2, D, h)
    return out, parameters


def damped_parameters(
    parameters: ParameterDerivatives,
    W_damped: np.ndarray,
    v_free_damped: np.ndarray,
    damping: np.ndarray,
    h: float,
) -> ParameterDerivatives:
    """Model-parameter derivatives of the undamped W and v_free carried to the damped step's
    (module docstring), given the damped ``W_damped`` (B, nv, nv) and ``v_free_damped`` (B,
    nv): ``dW'_t = A dW_t (I - h D W')``, ``dv_free'_t = A (dv_t - h dW_t D v_free')`` with
    ``A = (I + h W D)^-1 = I - h W' D``. Unchanged where no parameter moves W or v_free."""
    if parameters.dW is None and parameters.dv_free is None:
        return parameters
    D = np.asarray(damping, dtype=float)
    B, nv = v_free_damped.shape
    T = parameters.dphi.shape[-1]
    A = np.eye(nv) - h * W_damped * D[None, None, :]
    dW_t = np.zeros((B, nv, nv, T)) if parameters.dW is None else parameters.dW
    dv_t = np.zeros((B, nv, T)) if parameters.dv_free is None else parameters.dv_free
    right = np.eye(nv) - h * D[None, :, None] * W_damped  # (B, nv, nv)
    dW2 = np.einsum("bij,bjkt,bkl->bilt", A, dW_t, right)
    dv2 = np.einsum(
        "bij,bjt->bit", A, dv_t - h * np.einsum("bjkt,bk->bjt", dW_t, D * v_free_damped)
    )
    return replace(parameters, dW=dW2, dv_free=dv2)
