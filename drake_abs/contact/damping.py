"""Joint damping and joint springs treated implicitly in the step (docs/math.md section 6c).

A viscous joint damping ``tau_d = -D v`` (D diagonal, N m s / rad or N s / m per velocity) and
a linear joint spring ``tau_k = -K (q - q_ref)`` (K diagonal, N m / rad or N / m, on one-velocity
joints where ``qdot_i = v_j``) taken at the end of the step, with ``q+ = q + h v+``:

    M (v+ - v) = h (tau - n - D v+ - K (q + h v+ - q_ref)) + J' lam,

are stable at any time step (an explicit ``-D v`` diverges once ``h D / M > 2``, an explicit
spring once ``h^2 K / M > 4``: a model's light links with heavy damping or stiff springs). The
spring is a damping ``h K`` at the step's end plus the explicit torque ``tau_k(q)``, so with the
effective damping ``D' = D + h K`` and ``A = (I + h W D')^-1`` (W = M^-1) the step's quantities
become

    W' = (M + h D')^-1 = A W,        v_free' = A (v_free + h W tau_k(q)),

and the rest of the step is unchanged. Their derivatives, for D and K constant:

    dW' . f   = A dW . (f - h D' W' f),
    dv_free'  = A (dv_free - h dW . (D' v_free' - tau_k) + h W dtau_k),   dtau_k/dq = -K,

so a provider's ``dW . f`` (or ``dW_times``) carries over without forming dW.

Springs may instead be explicit (``JointSprings(..., implicit=False)``): the torque
``tau_k(q)`` at the step's start only, ``D' = D``, as MuJoCo's default Euler integrator takes
them (it takes the damping implicitly and the springs explicitly). The formulas above hold with
``D' = D``. An explicit spring is stable only while ``h^2 K / M < 4``; it keeps the oscillation's
energy, where the implicit one removes some each step (at the HalfCheetah's 10 ms and stiffness
240 N m / rad the two differ by about 0.09 rad after one swing in the air). Choose explicit to
match MuJoCo, implicit for stability at large time steps.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from drake_abs.contact.step_data import ParameterDerivatives, StepQuantities


@dataclass(frozen=True)
class JointSprings:
    """Linear springs on one-velocity joints, one entry per velocity (nv,): the spring on
    velocity j pulls position ``q[q_index[j]]`` towards ``reference[j]`` with ``stiffness[j]``,
    ``tau_j = -stiffness[j] (q[q_index[j]] - reference[j])``.

    Attributes:
        stiffness: (nv,) N m / rad or N / m, >= 0 (0: no spring).
        reference: (nv,) rad or m, where the spring exerts no torque.
        q_index: (nv,) the position coordinate of each velocity's joint (``qdot = v`` there), or
            -1 where the velocity has no single position coordinate (a free body's); the
            stiffness must be 0 there.
        implicit: True (default): the spring is taken at the step's end (stable at any h);
            False: at its start, as MuJoCo's Euler integrator (module docstring).
    """

    stiffness: np.ndarray
    reference: np.ndarray
    q_index: np.ndarray
    implicit: bool = True

    def __post_init__(self):
        K = np.asarray(self.stiffness, dtype=float)
        ref = np.asarray(self.reference, dtype=float)
        idx = np.asarray(self.q_index)
        nv = K.shape[0] if K.ndim == 1 else -1
        if K.ndim != 1 or ref.shape != (nv,) or idx.shape != (nv,):
            raise ValueError(
                "JointSprings: stiffness, reference and q_index must be three arrays of one "
                f"entry per velocity; got shapes {K.shape}, {ref.shape}, {idx.shape}"
            )
        if not (np.all(np.isfinite(K)) and np.all(K >= 0)):
            raise ValueError(f"JointSprings: stiffness must be finite numbers >= 0; got {K!r}")
        if not np.all(np.isfinite(ref)):
            raise ValueError(f"JointSprings: reference must be finite; got {ref!r}")
        if not np.issubdtype(idx.dtype, np.integer) or np.any(idx < -1):
            raise ValueError(f"JointSprings: q_index must be integers >= -1; got {idx!r}")
        if np.any((K > 0) & (idx < 0)):
            raise ValueError(
                "JointSprings: a spring (stiffness > 0) needs its velocity's position coordinate "
                f"(q_index >= 0); got stiffness {K!r} with q_index {idx!r}"
            )
        object.__setattr__(self, "stiffness", K)
        object.__setattr__(self, "reference", ref)
        object.__setattr__(self, "q_index", idx.astype(np.int64))
        if not isinstance(self.implicit, (bool, np.bool_)):
            raise ValueError(f"JointSprings: implicit must be True or False; got {self.implicit!r}")
        object.__setattr__(self, "implicit", bool(self.implicit))

    @classmethod
    def none(cls, nv: int) -> JointSprings:
        """No spring on any of nv velocities."""
        return cls(np.zeros(nv), np.zeros(nv), np.full(nv, -1, dtype=np.int64))

    @property
    def active(self) -> bool:
        """True when some stiffness is > 0."""
        return bool(self.stiffness.any())

    def torque(self, q: np.ndarray) -> np.ndarray:
        """The springs' torques ``-K (q_i - q_ref)`` (B, nv) at positions q (B, nq); 0 on the
        velocities without a spring."""
        q = np.asarray(q, dtype=float)
        on = self.stiffness > 0
        out = np.zeros((q.shape[0], self.stiffness.size))
        out[:, on] = -self.stiffness[on] * (q[:, self.q_index[on]] - self.reference[on])
        return out

    def torque_jacobian(self, nq: int) -> np.ndarray:
        """``d tau_k / dq`` (nv, nq): ``-K_j`` at (j, q_index[j]), constant."""
        out = np.zeros((self.stiffness.size, nq))
        on = np.flatnonzero(self.stiffness > 0)
        out[on, self.q_index[on]] = -self.stiffness[on]
        return out


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


def check_springs(springs: JointSprings | None, nv: int) -> JointSprings | None:
    """``springs`` (a :class:`JointSprings` over nv velocities) or None; None also when no
    stiffness is > 0. Raises a ValueError naming the argument for anything else."""
    if springs is None:
        return None
    if not isinstance(springs, JointSprings) or springs.stiffness.shape != (nv,):
        raise ValueError(
            f"springs must be None or a JointSprings over {nv} velocities; got {springs!r}"
        )
    return springs if springs.active else None


def effective_damping(
    damping: np.ndarray | None, springs: JointSprings | None, nv: int, h: float
) -> np.ndarray:
    """``D' = D + h K`` (nv,): the damping of the implicit step with the springs' stiffness
    taken at the step's end (module docstring); ``D' = D`` for explicit springs; zeros for no
    damping and no springs."""
    D = np.zeros(nv) if damping is None else check_damping(damping, nv, h)
    springs = check_springs(springs, nv)
    return D if springs is None or not springs.implicit else D + h * springs.stiffness


def implicit_damping(
    quant: StepQuantities,
    damping: np.ndarray,
    h: float,
    parameters: ParameterDerivatives | None = None,
    springs: JointSprings | None = None,
) -> tuple[StepQuantities, ParameterDerivatives | None]:
    """The quantities (and model-parameter derivatives) of a step with the joint damping
    ``damping`` (nv,) and the joint ``springs`` applied implicitly (module docstring). Returns
    them unchanged when every damping is 0 and no spring is stiff."""
    W = np.asarray(quant.W, dtype=float)
    B, nv = quant.v_free.shape
    springs = check_springs(springs, nv)
    D = effective_damping(damping, springs, nv, h)
    if not D.any() and springs is None:
        return quant, parameters
    A = np.linalg.inv(np.eye(nv) + h * W * D[None, None, :])  # (I + h W D')^-1, (B, nv, nv)
    W2 = A @ W
    g = quant.v_free
    tau_k = None
    if springs is not None:
        tau_k = springs.torque(quant.q)
        g = g + h * np.einsum("bij,bj->bi", W, tau_k)
    v_free2 = np.einsum("bij,bj->bi", A, g)
    values = dict(W=W2, v_free=v_free2)
    if quant.has_derivatives:
        inner_dW_dot = quant.dW_dot

        def dW_times(f: np.ndarray) -> np.ndarray:
            g = f - h * D * np.einsum("bij,bj->bi", W2, f)
            return A @ inner_dW_dot(g)

        load = D * v_free2 if tau_k is None else D * v_free2 - tau_k
        dv = quant.dv_free - h * inner_dW_dot(load)
        if springs is not None:  # h W dtau_k/dq on the q columns
            nq = quant.q.shape[1]
            dv = dv.copy()
            dv[..., :nq] += h * W @ springs.torque_jacobian(nq)
        values.update(dW=None, dW_times=dW_times, dv_free=A @ dv)
    out = replace(quant, **values)
    if parameters is not None:
        parameters = damped_parameters(parameters, W2, v_free2, D, h, tau_k)
    return out, parameters


def damped_parameters(
    parameters: ParameterDerivatives,
    W_damped: np.ndarray,
    v_free_damped: np.ndarray,
    damping: np.ndarray,
    h: float,
    spring_torque: np.ndarray | None = None,
) -> ParameterDerivatives:
    """Model-parameter derivatives of the undamped W and v_free carried to the damped step's
    (module docstring), given the damped ``W_damped`` (B, nv, nv), ``v_free_damped`` (B, nv),
    the effective damping ``damping`` (nv,) (``D' = D + h K``, :func:`effective_damping`) and
    the springs' torques ``spring_torque`` (B, nv) at the step's q (None: no springs):
    ``dW'_t = A dW_t (I - h D' W')``, ``dv_free'_t = A (dv_t - h dW_t (D' v_free' - tau_k))``
    with ``A = (I + h W D')^-1 = I - h W' D'``. Unchanged where no parameter moves W or
    v_free."""
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
    load = D * v_free_damped if spring_torque is None else D * v_free_damped - spring_torque
    dv2 = np.einsum("bij,bjt->bit", A, dv_t - h * np.einsum("bjkt,bk->bjt", dW_t, load))
    return replace(parameters, dW=dW2, dv_free=dv2)
