"""The 12-state quadcopter of Zuliani et al. (2025) (section 7), stepped by forward Euler, with its
Jacobians.

State x (12,), in this order and these units::

    p_x, p_y, p_z         position of the centre of mass in the world frame W (m); z points up
    v_x, v_y, v_z         velocity in W (m/s)
    phi, theta, psi       roll, pitch, yaw (rad): Z-Y-X (yaw-pitch-roll) Euler angles, the
                          body-to-world rotation is R_WB = Rz(psi) Ry(theta) Rx(phi) (Drake's
                          RollPitchYaw(phi, theta, psi) is the same rotation)
    p, q, r               body angular velocity, expressed in the body frame B (rad/s)

Input u (4,): rotor speeds omega_1..omega_4 (rad/s). Rotor i produces the thrust k omega_i^2
along body +z. Rotor layout in the body frame (arm length l): rotor 1 at +x, rotor 2 at -y,
rotor 3 at -x, rotor 4 at +y, so the body torques are

    tau_phi   = l k (omega_4^2 - omega_2^2)                          (roll, about body x)
    tau_theta = l k (omega_3^2 - omega_1^2)                          (pitch, about body y)
    tau_psi   = b (-omega_1^2 + omega_2^2 - omega_3^2 + omega_4^2)   (yaw, about body z)

i.e. the drag reaction torque of rotors 2 and 4 turns the body towards +psi, that of rotors 1
and 3 towards -psi. The continuous dynamics are (c = cos, s = sin, t = tan, T = k sum omega_i^2)::

    d(p)/dt     = v
    m d(v)/dt   = T R_WB e_z - m g e_z - diag(A_x, A_y, A_z) v        (linear drag)
    d(phi)/dt   = p + s(phi) t(theta) q + c(phi) t(theta) r
    d(theta)/dt = c(phi) q - s(phi) r
    d(psi)/dt   = (s(phi) q + c(phi) r) / c(theta)
    I_xx dp/dt  = (I_yy - I_zz) q r - J_r q omega_r + tau_phi
    I_yy dq/dt  = (I_zz - I_xx) p r + J_r p omega_r + tau_theta
    I_zz dr/dt  = (I_xx - I_yy) p q + tau_psi

with the rotor-speed imbalance omega_r = omega_2 - omega_1 + omega_4 - omega_3 in the gyroscopic
terms (the sign used by the model of Zuliani et al.'s (2025) authors; it vanishes at hover, and
with J_r =
3.4e-5 kg m^2 it is about 1e-3 of the control torques in this experiment). The discrete model is
one forward-Euler step, x+ = x + dt f(x, u), dt = 0.1 s; its Jacobians are analytic.

The constants are those of the paper authors' 12-state model: m 0.468 kg, l 0.225 m,
k 2.98e-6 N s^2, b 1.14e-7 N m s^2, I = diag(4.856e-3, 4.856e-3, 8.801e-3) kg m^2, J_r 3.357e-5
kg m^2, linear drag 0.25 kg/s per axis; hover at omega = sqrt(m g / (4 k)) = 620.6 rad/s.

The constraints of Zuliani et al. 2025, section 7 are in :class:`QuadcopterConstraints`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.contact.step import Step, contact_free_step

NX = 12
NU = 4
STATE_NAMES = (
    "p_x", "p_y", "p_z", "v_x", "v_y", "v_z", "phi", "theta", "psi", "p", "q", "r",
)  # fmt: skip
INPUT_NAMES = ("omega_1", "omega_2", "omega_3", "omega_4")
_GYRO = np.array([-1.0, 1.0, -1.0, 1.0])  # d omega_r / d omega_i
_YAW = np.array([-1.0, 1.0, -1.0, 1.0])  # sign of each rotor's yaw reaction torque


@dataclass(frozen=True)
class QuadcopterParams:
    """Physical constants (SI units) and the Euler time step of the quadcopter."""

    mass: float = 0.468  # kg
    arm_length: float = 0.225  # m, rotor to centre of mass
    thrust_coefficient: float = 2.98e-6  # N s^2: thrust of one rotor = k omega^2
    drag_coefficient: float = 1.14e-7  # N m s^2: yaw reaction torque of one rotor = b omega^2
    inertia: tuple[float, float, float] = (4.856e-3, 4.856e-3, 8.801e-3)  # kg m^2, body axes
    rotor_inertia: float = 3.357e-5  # kg m^2
    linear_drag: tuple[float, float, float] = (0.25, 0.25, 0.25)  # kg/s, world axes
    gravity: float = 9.81  # m/s^2
    time_step: float = 0.1  # s

    def __post_init__(self):
        scalars = ("mass", "arm_length", "thrust_coefficient", "drag_coefficient")
        for name in (*scalars, "rotor_inertia", "gravity", "time_step"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"QuadcopterParams.{name} must be finite and >= 0; got {value!r}")
        for name in ("mass", "thrust_coefficient", "time_step"):
            if getattr(self, name) <= 0:
                raise ValueError(f"QuadcopterParams.{name} must be > 0")
        for name in ("inertia", "linear_drag"):
            arr = np.asarray(getattr(self, name), dtype=float)
            if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ValueError(f"QuadcopterParams.{name} must be 3 finite numbers >= 0")
        if min(self.inertia) <= 0:
            raise ValueError("QuadcopterParams.inertia must be > 0")

    @property
    def hover_speed(self) -> float:
        """Rotor speed (rad/s) at which the four rotors together carry the weight."""
        return float(np.sqrt(self.mass * self.gravity / (4.0 * self.thrust_coefficient)))

    def hover_input(self) -> np.ndarray:
        """u_ref (4,): all rotors at :attr:`hover_speed` (rad/s)."""
        return np.full(NU, self.hover_speed)


@dataclass(frozen=True)
class QuadcopterConstraints:
    """The state and input constraints of Zuliani et al. 2025, section 7 (boxes).

    Rotor speeds in [0, 630] rad/s; ``|v_x|, |v_y|, |v_z| <= 2`` m/s;
    ``|phi|, |theta|, |psi| <= pi/4``; ``|p|, |q|, |r| <= pi/8`` rad/s; positions unconstrained.
    """

    rotor_speed_max: float = 630.0  # rad/s
    velocity_max: float = 2.0  # m/s
    angle_max: float = np.pi / 4  # rad
    rate_max: float = np.pi / 8  # rad/s

    def state_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(x_min, x_max), each (12,); -inf/+inf for the unconstrained positions."""
        hi = np.concatenate(
            [
                np.full(3, np.inf),
                np.full(3, self.velocity_max),
                np.full(3, self.angle_max),
                np.full(3, self.rate_max),
            ]
        )
        return -hi, hi

    def input_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(u_min, u_max), each (4,) rad/s."""
        return np.zeros(NU), np.full(NU, self.rotor_speed_max)


def _inputs(x, u) -> tuple[np.ndarray, np.ndarray]:
    x = as_finite_array(x, "x")
    u = as_finite_array(u, "u")
    if x.ndim == 0 or x.shape[-1] != NX:
        raise ValueError(f"x must have shape (..., {NX}); got {x.shape}")
    if u.ndim == 0 or u.shape[-1] != NU:
        raise ValueError(f"u must have shape (..., {NU}); got {u.shape}")
    if x.shape[:-1] != u.shape[:-1]:
        raise ValueError(
            f"x and u must have the same leading (batch) shape; got x {x.shape}, u {u.shape}"
        )
    return x, u


def dynamics(
    x, u, params: QuadcopterParams | None = None, *, jacobians: bool = False
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The continuous-time vector field f(x, u) and, optionally, its Jacobians.

    Args:
        x: S + (12,) states (see the module docstring for order and units).
        u: S + (4,) rotor speeds (rad/s).
        params: physical constants (default :class:`QuadcopterParams`).
        jacobians: also return df/dx S + (12, 12) and df/du S + (12, 4).

    Returns:
        (f, df_dx, df_du); the Jacobians are None unless requested.
    """
    x, u = _inputs(x, u)
    prm = params or QuadcopterParams()
    m, g = prm.mass, prm.gravity
    k, b, arm, jr = prm.thrust_coefficient, prm.drag_coefficient, prm.arm_length, prm.rotor_inertia
    ixx, iyy, izz = prm.inertia
    drag = np.asarray(prm.linear_drag, dtype=float) / m

    v = x[..., 3:6]
    phi, th, psi = x[..., 6], x[..., 7], x[..., 8]
    p, q, r = x[..., 9], x[..., 10], x[..., 11]
    cf, sf, ct, st, cp, sp = (
        np.cos(phi),
        np.sin(phi),
        np.cos(th),
        np.sin(th),
        np.cos(psi),
        np.sin(psi),
    )
    tt = st / ct
    w2 = u**2
    thrust = k * w2.sum(axis=-1) / m  # m/s^2
    # body z axis in the world: third column of R_WB = Rz(psi) Ry(theta) Rx(phi)
    zb = np.stack([cp * st * cf + sp * sf, sp * st * cf - cp * sf, ct * cf], axis=-1)
    omega_r = u @ _GYRO
    a1, a2, a3 = (iyy - izz) / ixx, (izz - ixx) / iyy, (ixx - iyy) / izz
    b1, b2 = jr / ixx, jr / iyy
    c1, c2, c3 = arm * k / ixx, arm * k / iyy, b / izz

    f = np.empty(x.shape)
    f[..., 0:3] = v
    f[..., 3:6] = thrust[..., None] * zb - drag * v
    f[..., 5] -= g
    f[..., 6] = p + sf * tt * q + cf * tt * r
    f[..., 7] = cf * q - sf * r
    f[..., 8] = (sf * q + cf * r) / ct
    f[..., 9] = a1 * q * r - b1 * q * omega_r + c1 * (w2[..., 3] - w2[..., 1])
    f[..., 10] = a2 * p * r + b2 * p * omega_r + c2 * (w2[..., 2] - w2[..., 0])
    f[..., 11] = a3 * p * q + c3 * (w2 @ _YAW)
    if not jacobians:
        return f, None, None

    S = x.shape[:-1]
    fx = np.zeros(S + (NX, NX))
    fu = np.zeros(S + (NX, NU))
    fx[..., 0, 3] = fx[..., 1, 4] = fx[..., 2, 5] = 1.0
    for i in range(3):
        fx[..., 3 + i, 3 + i] = -drag[i]
    # d zb / d(phi, theta, psi)
    dzb = np.stack(
        [
            np.stack([-cp * st * sf + sp * cf, cp * ct * cf, -sp * st * cf + cp * sf], axis=-1),
            np.stack([-sp * st * sf - cp * cf, sp * ct * cf, cp * st * cf + sp * sf], axis=-1),
            np.stack([-ct * sf, -st * cf, np.zeros_like(ct)], axis=-1),
        ],
        axis=-2,
    )  # S + (3, 3): rows x, y, z; columns phi, theta, psi
    fx[..., 3:6, 6:9] = thrust[..., None, None] * dzb
    fu[..., 3:6, :] = (2 * k / m) * zb[..., :, None] * u[..., None, :]
    sec2 = 1.0 / ct**2
    fx[..., 6, 6] = cf * tt * q - sf * tt * r
    fx[..., 6, 7] = (sf * q + cf * r) * sec2
    fx[..., 6, 9] = 1.0
    fx[..., 6, 10] = sf * tt
    fx[..., 6, 11] = cf * tt
    fx[..., 7, 6] = -sf * q - cf * r
    fx[..., 7, 10] = cf
    fx[..., 7, 11] = -sf
    fx[..., 8, 6] = (cf * q - sf * r) / ct
    fx[..., 8, 7] = (sf * q + cf * r) * st * sec2
    fx[..., 8, 10] = sf / ct
    fx[..., 8, 11] = cf / ct
    fx[..., 9, 10] = a1 * r - b1 * omega_r
    fx[..., 9, 11] = a1 * q
    fx[..., 10, 9] = a2 * r + b2 * omega_r
    fx[..., 10, 11] = a2 * p
    fx[..., 11, 9] = a3 * q
    fx[..., 11, 10] = a3 * p
    fu[..., 9, :] = -b1 * q[..., None] * _GYRO
    fu[..., 9, 3] += 2 * c1 * u[..., 3]
    fu[..., 9, 1] -= 2 * c1 * u[..., 1]
    fu[..., 10, :] = b2 * p[..., None] * _GYRO
    fu[..., 10, 2] += 2 * c2 * u[..., 2]
    fu[..., 10, 0] -= 2 * c2 * u[..., 0]
    fu[..., 11, :] = 2 * c3 * u * _YAW
    return f, fx, fu


def step(x, u, params: QuadcopterParams | None = None, *, jacobians: bool = False) -> Step:
    """One forward-Euler step x+ = x + dt f(x, u) (dt = ``params.time_step``), batched: the
    contact-free :class:`~drake_abs.contact.step.Step` (every step converged, no impulses).

    Args:
        x: S + (12,) states; u: S + (4,) rotor speeds (rad/s). Non-finite values or wrong shapes
            raise ``ValueError`` naming the argument.
        params: physical constants (default :class:`QuadcopterParams`).
        jacobians: also return dx+/dx = I + dt df/dx and dx+/du = dt df/du.
    """
    prm = params or QuadcopterParams()
    f, fx, fu = dynamics(x, u, prm, jacobians=jacobians)
    x = np.asarray(x, dtype=float)
    dt = prm.time_step
    x_next = x + dt * f
    if not jacobians:
        return contact_free_step(x_next)
    return contact_free_step(x_next, np.eye(NX) + dt * fx, dt * fu)


@dataclass(frozen=True)
class QuadcopterStepper:
    """The quadcopter as a batched stepper (:class:`drake_abs.engine.Stepper`) of
    :func:`step`, for the closed-loop engine."""

    params: QuadcopterParams = QuadcopterParams()

    parameter_names: ClassVar[tuple[str, ...]] = ()

    def step(self, x, u, *, jacobians: bool = True, parameters: bool = False) -> Step:
        """:func:`step` with these parameters: x (M, 12), u (M, 4)."""
        if parameters:
            raise ValueError("parameters=True: QuadcopterStepper names no model parameters")
        return step(x, u, self.params, jacobians=jacobians)


#: The tracking task of Zuliani et al. 2025, section 7, as the target state (m, rad, m/s,
#: rad/s; position (-6, -3.5, 0), at rest), the diagonals of the stage weights Q (12) and R (4),
#: of the terminal weight P (12), and the weight of the constraint violation's 1-norm in the
#: cost.
TRACKING_TARGET = (-6.0, -3.5, 0.0) + (0.0,) * 9
TRACKING_STAGE_Q = (1.0,) * 6 + (0.1,) * 6
TRACKING_STAGE_R = (0.01,) * 4
TRACKING_TERMINAL_P = (1.0,) * 6 + (1e3,) * 3 + (1.0,) * 3
TRACKING_PENALTY = 300.0


def hover_linearization(
    params: QuadcopterParams | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of the Euler step at hover (any position, zero velocity, angles and rates; all
    rotors at the hover speed): the exact Jacobians, (12, 12) and (12, 4)."""
    prm = params or QuadcopterParams()
    s = step(np.zeros(NX), prm.hover_input(), prm, jacobians=True)
    return s.dx_dx, s.dx_du
