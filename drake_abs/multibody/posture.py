"""A posture-holding joint controller for a scene's robot: feed-forward torques that balance
the initial posture on its feet, plus a PD law on the actuated joints (docs/math.md section 6).

    u(x) = u_ff + kp (q_ref - q_a) - kd v_a

with ``q_a``, ``v_a`` the actuated joints' positions and velocities, ``q_ref`` their initial
values, and ``u_ff`` the torques for which gravity, the actuation and normal forces at the given
feet are in balance at the initial posture: the forces closest to an equal share of the robot's
weight that balance the unactuated (floating-base) directions too (equal shares when the centre
of mass is over the feet's centroid, e.g. solo12; go1's is 3 cm behind it). Batched
over states. Shipped gains per scene in :data:`STANDING_GAINS` (light robots, such as solo12's
31 g lower legs, need light gains: the PD is explicit in the time step).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drake_abs.multibody.builder import SceneModel

GRAVITY = 9.81  # m/s^2

#: feet (contact indices) and (kp, kd) per actuated joint, for the shipped robots standing
STANDING_GAINS: dict[str, tuple[list[int], list[float], list[float]]] = {
    "hopper": ([0], [50.0, 500.0], [2.0, 40.0]),  # hip (N m/rad), leg (N/m); N m s/rad, N s/m
    "half_cheetah": ([0, 1], [100.0, 100.0, 10.0] * 2, [1.0, 1.0, 0.05] * 2),  # 0.4 kg feet
    "solo12_drop": ([0, 1, 2, 3], [5.0] * 12, [0.1] * 12),  # 31 g lower legs, h = 5 ms
    "go1_drop": ([0, 1, 2, 3], [20.0] * 12, [0.5] * 12),  # 0.2 kg lower legs, h = 10 ms
}


def total_mass(model: SceneModel) -> float:
    """The robot's mass (kg)."""
    return model.plant.CalcTotalMass(model.plant.CreateDefaultContext())


def actuated_indices(model: SceneModel) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity index of each actuator's (one-degree-of-freedom) joint."""
    plant = model.plant
    joints = [plant.get_joint_actuator(a).joint() for a in plant.GetJointActuatorIndices()]
    return (
        np.array([j.position_start() for j in joints], int),
        np.array([j.velocity_start() for j in joints], int),
    )


def standing_controller(
    model: SceneModel, feet, kp, kd
) -> tuple[Callable[[np.ndarray], np.ndarray], np.ndarray]:
    """``(u, u_ff)``: the controller ``u(x)`` (x (nx,) or (B, nx) -> (nu,) or (B, nu)) that holds
    the initial posture, and its feed-forward torques. ``feet``: contact indices that carry the
    weight; ``kp``, ``kd``: per actuated joint (scalars broadcast)."""
    plant = model.plant
    nq, nu = plant.num_positions(), plant.num_actuators()
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, model.q0)
    tau_g = plant.CalcGravityGeneralizedForces(context)
    feet = np.asarray(feet, int)
    quant = model.contact_model.quantities(
        model.q0[None], model.v0[None], np.zeros((1, nu)), feet, derivatives=False
    )
    Jn = quant.Jn[0]
    equal = np.full(feet.size, total_mass(model) * GRAVITY / feet.size)
    B = plant.MakeActuationMatrix()
    # the unactuated directions (the left null space of B) must balance without actuation:
    # N^T (tau_g + Jn^T f) = 0, solved for the f nearest the equal share (min-norm correction)
    _, sv, Vt = np.linalg.svd(B.T)
    N = Vt[np.sum(sv > 1e-12) :].T
    f = equal
    if N.shape[1]:
        f = equal + np.linalg.lstsq(N.T @ Jn.T, -N.T @ (tau_g + Jn.T @ equal), rcond=None)[0]
    support = Jn.T @ f
    u_ff = np.linalg.lstsq(B, -(tau_g + support), rcond=None)[0]
    if f.min() < 0 or not np.allclose(B @ u_ff + tau_g + support, 0.0, atol=1e-9):
        raise ValueError("the initial posture cannot be balanced by the actuators on these feet")
    qi, vi = actuated_indices(model)
    kp, kd, q_ref = np.asarray(kp, float), np.asarray(kd, float), model.q0[qi]

    def u(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float)
        return u_ff + kp * (q_ref - x[..., qi]) - kd * x[..., nq + vi]

    return u, u_ff


#: a trot-like swing of solo12's reference (per leg HAA, HFE, KFE; legs FL, FR, HL, HR); hip and
#: knee pitch swung by 0.3 rad, diagonal legs together (phases 0 and pi), at 2 Hz
SOLO12_TROT: tuple[np.ndarray, np.ndarray, float] = (
    np.tile([0.0, 0.3, 0.3], 4),
    np.repeat([0.0, np.pi, np.pi, 0.0], 3),
    2.0,
)


def stepping_controller(
    model: SceneModel, feet, kp, kd, swing, phase, frequency: float
) -> Callable[[float, np.ndarray], np.ndarray]:
    """``u(t, x)``: the standing controller of :func:`standing_controller` with its joint
    reference swung as ``q_ref + swing sin(2 pi frequency t + phase)`` (swing in rad or m per
    actuated joint, phase in rad, frequency in Hz; t in s). x (nx,) or (B, nx)."""
    hold, _ = standing_controller(model, feet, kp, kd)
    nu = model.plant.num_actuators()
    kp = np.broadcast_to(np.asarray(kp, float), (nu,))
    swing = np.broadcast_to(np.asarray(swing, float), (nu,))
    phase = np.broadcast_to(np.asarray(phase, float), (nu,))

    def u(t: float, x: np.ndarray) -> np.ndarray:
        return hold(x) + kp * swing * np.sin(2.0 * np.pi * frequency * t + phase)

    return u
