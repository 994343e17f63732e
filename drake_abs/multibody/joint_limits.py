"""What a model declares about its joints and actuators, as the step uses it (docs/math.md
section 6c): position limits as unilateral complementarity rows, viscous damping and joint
springs (applied implicitly, :mod:`drake_abs.contact.damping`) and actuator effort limits.

A single-degree-of-freedom joint (revolute or prismatic) with a finite lower limit gives the row
``phi = q_i - lower >= 0`` and one with a finite upper limit ``phi = upper - q_i >= 0``, with the
velocity-space Jacobian ``+-e_j`` (for these joints ``qdot_i = v_j``): a frictionless "contact"
row, ``phi + h J v+ >= 0  perp  gamma >= 0`` with gamma the limit's impulse (N m s or N s). The
step solves them in the same LCP as the contacts, smoothed by the same policy (their distances are
in rad or m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    ForceElementIndex,
    JointActuatorIndex,
    JointIndex,
    PrismaticSpring,
    RevoluteSpring,
)

from drake_abs.contact.damping import JointSprings


@dataclass(frozen=True)
class JointLimitRows:
    """The limit rows of a plant: ``nl`` rows, each on position ``q_index`` and velocity
    ``v_index``, ``sign`` +1 (lower limit) or -1 (upper), at ``bound``; ``names`` say which
    joint and side (``"knee.lower"``)."""

    q_index: np.ndarray
    v_index: np.ndarray
    sign: np.ndarray
    bound: np.ndarray
    names: tuple[str, ...]

    @classmethod
    def of(cls, plant: MultibodyPlant | None) -> JointLimitRows:
        """The rows of every single-dof joint's finite position limits (none for None)."""
        q_index, v_index, sign, bound, names = [], [], [], [], []
        for j in plant.GetJointIndices() if plant is not None else ():
            joint = plant.get_joint(JointIndex(int(j)))
            if joint.num_positions() != 1 or joint.num_velocities() != 1:
                continue
            for side, s, value in (
                ("lower", 1.0, joint.position_lower_limits()[0]),
                ("upper", -1.0, joint.position_upper_limits()[0]),
            ):
                if np.isfinite(value):
                    q_index.append(joint.position_start())
                    v_index.append(joint.velocity_start())
                    sign.append(s)
                    bound.append(float(value))
                    names.append(f"{joint.name()}.{side}")
        return cls(
            np.array(q_index, dtype=np.int64),
            np.array(v_index, dtype=np.int64),
            np.array(sign),
            np.array(bound),
            tuple(names),
        )

    @property
    def size(self) -> int:
        return self.q_index.size

    def distances(self, q: np.ndarray) -> np.ndarray:
        """``phi`` (B, nl): how far each limit is (rad or m; negative beyond it)."""
        return self.sign * (q[:, self.q_index] - self.bound)

    def rows(
        self, q: np.ndarray, rows: np.ndarray, nv: int, P: int | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
        """``(phi (B, r), J (B, r, nv), dphi (B, r, P), dJ (B, r, nv, P))`` of the limit rows
        ``rows`` at the positions q (B, nq); the derivatives (with respect to P columns, q
        first) only when P is given."""
        B = q.shape[0]
        r = len(rows)
        phi = self.distances(q)[:, rows]
        J = np.zeros((B, r, nv))
        J[:, np.arange(r), self.v_index[rows]] = self.sign[rows]
        if P is None:
            return phi, J, None, None
        dphi = np.zeros((B, r, P))
        dphi[:, np.arange(r), self.q_index[rows]] = self.sign[rows]
        return phi, J, dphi, np.zeros((B, r, nv, P))


def joint_damping(plant: MultibodyPlant) -> np.ndarray:
    """Viscous damping per velocity (nv,): each joint's ``default_damping`` on its velocities
    (N m s / rad, N s / m; 0 where none)."""
    damping = np.zeros(plant.num_velocities())
    for j in plant.GetJointIndices():
        joint = plant.get_joint(JointIndex(int(j)))
        if joint.num_velocities() > 0:
            start = joint.velocity_start()
            damping[start : start + joint.num_velocities()] = joint.default_damping_vector()
    return damping


def spring_integration(springs: bool | str) -> str | bool:
    """The joint springs' treatment a stepper's ``springs`` argument asks for: ``"implicit"``
    (True or "implicit"), ``"explicit"``, or False (no springs); a ValueError naming the
    argument otherwise."""
    if springs is True or springs == "implicit":
        return "implicit"
    if springs is False:
        return False
    if springs == "explicit":
        return "explicit"
    raise ValueError(f"springs must be True, False, 'implicit' or 'explicit'; got {springs!r}")


def joint_springs(plant: MultibodyPlant, implicit: bool = True) -> JointSprings:
    """The plant's joint springs per velocity (:class:`~drake_abs.contact.damping.JointSprings`):
    every ``RevoluteSpring`` and ``PrismaticSpring`` force element (an SDF joint's
    ``spring_stiffness``, an MJCF joint's ``stiffness``: see
    :func:`~drake_abs.multibody.model_files.apply_mjcf`) on its joint's velocity, with its
    stiffness (N m / rad or N / m) and nominal position (rad or m). Several springs on one joint
    add up (their stiffnesses, and the stiffness-weighted mean of their references). Every
    one-velocity, one-position joint has its position coordinate in ``q_index`` (so that a
    stiffness can be given to it later); other velocities have -1. ``implicit``: the springs'
    treatment in the step (:class:`~drake_abs.contact.damping.JointSprings`)."""
    nv = plant.num_velocities()
    stiffness, moment, q_index = np.zeros(nv), np.zeros(nv), np.full(nv, -1, dtype=np.int64)
    for j in plant.GetJointIndices():
        joint = plant.get_joint(JointIndex(int(j)))
        if joint.num_velocities() == 1 and joint.num_positions() == 1:
            q_index[joint.velocity_start()] = joint.position_start()
    for i in range(plant.num_force_elements()):
        element = plant.get_force_element(ForceElementIndex(i))
        if isinstance(element, RevoluteSpring):
            k, ref = element.default_stiffness(), element.default_nominal_angle()
        elif isinstance(element, PrismaticSpring):
            k, ref = element.stiffness(), element.nominal_position()
        else:
            continue
        v = element.joint().velocity_start()
        stiffness[v] += k
        moment[v] += k * ref
    reference = np.divide(moment, stiffness, out=np.zeros(nv), where=stiffness > 0)
    return JointSprings(stiffness, reference, q_index, implicit)


def effort_limits(plant: MultibodyPlant) -> np.ndarray:
    """Each actuator's effort limit (nu,), in the order of the actuation input (inf: none)."""
    limits = np.full(plant.num_actuated_dofs(), np.inf)
    for a in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(JointActuatorIndex(int(a)))
        start = actuator.input_start()
        limits[start : start + actuator.num_inputs()] = actuator.effort_limit()
    return limits
