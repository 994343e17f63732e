"""Forward kinematics of a pinocchio kinematic tree of one-degree-of-freedom joints, compiled
(numba) and batched over states: the placements of the joints that carry contacts, for a whole
batch in one call.

Reading a placement back from pinocchio's Python bindings costs more than the kinematics
themselves (about 2 us per joint frame against about 1 us for a whole ``forwardKinematics`` of a
7-joint planar robot), and a batched step reads every contact-carrying joint of every state, so
the batched contact model (:class:`~drake_abs.multibody.pinocchio_dynamics.PinocchioContactModel`)
takes the placements from here instead. Pinocchio stays the rigid-body library: the tables below
are read from its model (parents, joint placements, joint axes), the dynamics are its own, and a
test checks every placement against pinocchio's ``data.oMi`` on every shipped scene.

The recursion is pinocchio's (``forwardKinematics``, first pass): for joint j with parent p,

    liMi_j = jointPlacement_j * M_j(q_j),    oMi_j = oMi_p * liMi_j,

with M_j a rotation by the angle q_j about the joint's unit axis a (Rodrigues' formula,
``R = cos I + sin [a]x + (1 - cos) a a^T``) for a revolute joint, a translation q_j a (m) for a
prismatic one. Only trees made of these two kinds are handled (:meth:`TreeKinematics.of`
returns None for any other, e.g. a free flyer).
"""

from __future__ import annotations

import numba as nb
import numpy as np
import pinocchio as pin

__all__ = ["TreeKinematics"]

_REVOLUTE, _PRISMATIC = 0, 1
_KINDS = {"JointModelRevoluteUnaligned": _REVOLUTE, "JointModelPrismaticUnaligned": _PRISMATIC}
_ALIGNED = {  # pinocchio's axis-aligned joints: (kind, axis index)
    "JointModelRX": (_REVOLUTE, 0), "JointModelRY": (_REVOLUTE, 1),
    "JointModelRZ": (_REVOLUTE, 2), "JointModelPX": (_PRISMATIC, 0),
    "JointModelPY": (_PRISMATIC, 1), "JointModelPZ": (_PRISMATIC, 2),
}  # fmt: skip


class TreeKinematics:
    """The tables of a pinocchio model's tree (joints 1 .. njoints - 1, parents first) and the
    compiled batched kinematics over them.

    Attributes:
        parents: (nj,) each joint's parent (0: the world).
        kinds: (nj,) 0 revolute, 1 prismatic.
        axes: (nj, 3) unit joint axes in the joint frame.
        q_index: (nj,) each joint's coordinate in q.
        R0, p0: (nj, 3, 3), (nj, 3) the joint placements in the parent joint's frame (m).
    """

    def __init__(self, parents, kinds, axes, q_index, R0, p0):
        self.parents = np.asarray(parents, dtype=np.int64)
        self.kinds = np.asarray(kinds, dtype=np.int64)
        self.axes = np.asarray(axes, dtype=float)
        self.q_index = np.asarray(q_index, dtype=np.int64)
        self.R0 = np.asarray(R0, dtype=float)
        self.p0 = np.asarray(p0, dtype=float)

    @classmethod
    def of(cls, model: pin.Model) -> TreeKinematics | None:
        """The tables of ``model``, or None when a joint is neither revolute nor prismatic."""
        parents, kinds, axes, q_index, R0, p0 = (
            [0],
            [0],
            [np.zeros(3)],
            [0],
            [np.eye(3)],
            [np.zeros(3)],
        )  # joint 0: the world (placement identity)
        for j in range(1, model.njoints):
            joint = model.joints[j]
            name = joint.shortname()
            if name in _KINDS:
                kind, axis = _KINDS[name], np.asarray(joint.extract().axis, float)
            elif name in _ALIGNED:
                kind, i = _ALIGNED[name]
                axis = np.eye(3)[i]
            else:
                return None
            parents.append(int(model.parents[j]))
            kinds.append(kind)
            axes.append(axis / np.linalg.norm(axis))
            q_index.append(int(joint.idx_q))
            X = model.jointPlacements[j]
            R0.append(np.array(X.rotation))
            p0.append(np.array(X.translation))
        return cls(parents, kinds, axes, q_index, R0, p0)

    def placements(self, q: np.ndarray, joints: np.ndarray) -> np.ndarray:
        """The world placements (B, k, 4, 4) of ``joints`` (k,) (pinocchio joint ids) at the
        configurations q (B, nq): ``data.oMi[j].homogeneous`` after ``forwardKinematics``."""
        q = np.ascontiguousarray(q, dtype=float)
        joints = np.asarray(joints, dtype=np.int64)
        H = np.empty((q.shape[0], joints.size, 4, 4))
        _placements(q, self.parents, self.kinds, self.axes, self.q_index, self.R0, self.p0,
                    joints, H)  # fmt: skip
        return H


@nb.njit(cache=True)
def _placements(q, parents, kinds, axes, q_index, R0, p0, joints, H):
    """H[b, k] = oMi[joints[k]] at q[b] (see the module docstring)."""
    nj = parents.size
    R = np.empty((nj, 3, 3))
    p = np.empty((nj, 3))
    L = np.empty((3, 3))
    lp = np.empty(3)
    M = np.empty((3, 3))
    for b in range(q.shape[0]):
        for i in range(3):
            p[0, i] = 0.0
            for c in range(3):
                R[0, i, c] = 1.0 if i == c else 0.0
        for j in range(1, nj):
            a = axes[j]
            t = q[b, q_index[j]]
            # liMi = jointPlacement * M_j(t)
            if kinds[j] == 0:  # revolute: R0 * Rodrigues(a, t), p0
                s, c_ = np.sin(t), np.cos(t)
                v = 1.0 - c_
                M[0, 0] = c_ + a[0] * a[0] * v
                M[1, 1] = c_ + a[1] * a[1] * v
                M[2, 2] = c_ + a[2] * a[2] * v
                M[0, 1] = a[0] * a[1] * v - a[2] * s
                M[1, 0] = a[0] * a[1] * v + a[2] * s
                M[0, 2] = a[0] * a[2] * v + a[1] * s
                M[2, 0] = a[0] * a[2] * v - a[1] * s
                M[1, 2] = a[1] * a[2] * v - a[0] * s
                M[2, 1] = a[1] * a[2] * v + a[0] * s
                for i in range(3):
                    lp[i] = p0[j, i]
                    for c in range(3):
                        L[i, c] = (
                            R0[j, i, 0] * M[0, c] + R0[j, i, 1] * M[1, c] + R0[j, i, 2] * M[2, c]
                        )
            else:  # prismatic: R0, p0 + R0 (t a)
                for i in range(3):
                    lp[i] = (
                        p0[j, i]
                        + (R0[j, i, 0] * a[0] + R0[j, i, 1] * a[1] + R0[j, i, 2] * a[2]) * t
                    )
                    for c in range(3):
                        L[i, c] = R0[j, i, c]
            # oMi = oMi[parent] * liMi
            par = parents[j]
            for i in range(3):
                p[j, i] = (
                    p[par, i] + R[par, i, 0] * lp[0] + R[par, i, 1] * lp[1] + R[par, i, 2] * lp[2]
                )
                for c in range(3):
                    R[j, i, c] = (
                        R[par, i, 0] * L[0, c] + R[par, i, 1] * L[1, c] + R[par, i, 2] * L[2, c]
                    )
        for k in range(joints.size):
            j = joints[k]
            for i in range(3):
                for c in range(3):
                    H[b, k, i, c] = R[j, i, c]
                H[b, k, i, 3] = p[j, i]
                H[b, k, 3, i] = 0.0
            H[b, k, 3, 3] = 1.0
