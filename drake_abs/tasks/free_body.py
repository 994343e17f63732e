"""MuJoCo's coordinates of a model whose root body is free, against our scene's, batched, with
the Jacobian of the map (for observations of MuJoCo's qpos and qvel and their derivatives).

Ours (a scene with ``floating_base: quaternion``, Drake's quaternion floating joint)::

    q = (qw, qx, qy, qz, x, y, z, joints...)     v = (w_W, v_W, joint rates...)

with w_W the body's angular velocity and v_W its origin's velocity, both in the world frame.
MuJoCo's free joint::

    qpos = (x, y, z, qw, qx, qy, qz, joints...)   qvel = (v_W, w_B, joint rates...)

with the angular velocity w_B = R^T w_W in the body's frame (R the body's orientation). The
other joints' coordinates are the same in both, in the same order (the scene keeps the file's
joint order). nq = 7 + n, nv = 6 + n in both.

The rotation is that of the normalised quaternion, ``R(e / |e|)``, as both MuJoCo's kinematics
and Drake's use it: a state whose quaternion is off the unit sphere (gymnasium's reset noise adds
noise to qpos, quaternion included, and leaves it for the first ``mj_step`` to normalise) maps
with the quaternion as it is, and its angular velocity through the normalised one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_count

__all__ = ["FreeBodyCoordinates", "rotation_matrix"]


def rotation_matrix(e: np.ndarray) -> np.ndarray:
    """R (B, 3, 3) of quaternions e (B, 4) = (w, x, y, z) of any nonzero norm (e is normalised)."""
    e = np.asarray(e, dtype=float)
    u = e / np.linalg.norm(e, axis=1, keepdims=True)
    w, x, y, z = u.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def _rotation_derivative(e: np.ndarray) -> np.ndarray:
    """dR/de (B, 3, 3, 4) of R(e / |e|) at quaternions e (B, 4)."""
    e = np.asarray(e, dtype=float)
    norm = np.linalg.norm(e, axis=1)
    u = e / norm[:, None]
    w, x, y, z = u.T
    zero = np.zeros_like(w)
    # dR/du_k for the unit quaternion's entries u = (w, x, y, z), each (B, 3, 3)
    dw = 2 * np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1),
                       np.stack([-y, x, zero], -1)], 1)  # fmt: skip
    dx = 2 * np.stack([np.stack([zero, y, z], -1), np.stack([y, -2 * x, -w], -1),
                       np.stack([z, w, -2 * x], -1)], 1)  # fmt: skip
    dy = 2 * np.stack([np.stack([-2 * y, x, w], -1), np.stack([x, zero, z], -1),
                       np.stack([-w, z, -2 * y], -1)], 1)  # fmt: skip
    dz = 2 * np.stack([np.stack([-2 * z, -w, x], -1), np.stack([w, -2 * z, y], -1),
                       np.stack([x, y, zero], -1)], 1)  # fmt: skip
    dR_du = np.stack([dw, dx, dy, dz], axis=-1)  # (B, 3, 3, 4)
    du_de = (np.eye(4)[None] - u[:, :, None] * u[:, None, :]) / norm[:, None, None]
    return dR_du @ du_de[:, None]  # (B, 3, 3, 4) x (B, 1, 4, 4)


@dataclass(frozen=True)
class FreeBodyCoordinates:
    """The map between our state x = (q, v) and MuJoCo's (qpos, qvel) of a model with one free
    root body and ``joints`` one-dof joints (see the module docstring).

    Args:
        joints: the number of one-dof joints after the free one (n; nq = 7 + n, nv = 6 + n).
    """

    joints: int

    def __post_init__(self):
        as_count(self.joints, "joints", minimum=0)

    @property
    def nq(self) -> int:
        return 7 + self.joints

    @property
    def nv(self) -> int:
        return 6 + self.joints

    @property
    def nx(self) -> int:
        return self.nq + self.nv

    def _x(self, x, name: str) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] != self.nx:
            raise ValueError(f"{name} must have shape (M, nx) = (M, {self.nx}); got {x.shape}")
        return x

    def to_mujoco(self, x) -> np.ndarray:
        """MuJoCo's (qpos, qvel) (M, nx) of our states x (M, nx)."""
        x = self._x(x, "x")
        nq = self.nq
        q, v = x[:, :nq], x[:, nq:]
        R = rotation_matrix(q[:, 0:4])
        w_body = np.einsum("bji,bj->bi", R, v[:, 0:3])
        qpos = np.concatenate([q[:, 4:7], q[:, 0:4], q[:, 7:]], axis=1)
        qvel = np.concatenate([v[:, 3:6], w_body, v[:, 6:]], axis=1)
        return np.concatenate([qpos, qvel], axis=1)

    def from_mujoco(self, xm) -> np.ndarray:
        """Our states x (M, nx) of MuJoCo's (qpos, qvel) (M, nx)."""
        xm = self._x(xm, "xm")
        nq = self.nq
        qpos, qvel = xm[:, :nq], xm[:, nq:]
        R = rotation_matrix(qpos[:, 3:7])
        w_world = np.einsum("bij,bj->bi", R, qvel[:, 3:6])
        q = np.concatenate([qpos[:, 3:7], qpos[:, 0:3], qpos[:, 7:]], axis=1)
        v = np.concatenate([w_world, qvel[:, 0:3], qvel[:, 6:]], axis=1)
        return np.concatenate([q, v], axis=1)

    def jacobian(self, x) -> np.ndarray:
        """d to_mujoco(x) / dx (M, nx, nx): a permutation but for the angular velocity,
        ``w_B = R(e)^T w_W``, which depends on w_W and the quaternion e."""
        x = self._x(x, "x")
        M, nq, nx = x.shape[0], self.nq, self.nx
        J = np.zeros((M, nx, nx))
        rows = np.arange(nq)
        cols = np.concatenate([np.arange(4, 7), np.arange(0, 4), np.arange(7, nq)])
        J[:, rows, cols] = 1.0
        e, w = x[:, 0:4], x[:, nq : nq + 3]
        J[:, nq : nq + 3, nq + 3 : nq + 6] = np.eye(3)  # qvel's v_W
        J[:, nq + 3 : nq + 6, nq : nq + 3] = np.transpose(rotation_matrix(e), (0, 2, 1))
        dR = _rotation_derivative(e)  # (M, 3, 3, 4): d R_ij / d e_k
        J[:, nq + 3 : nq + 6, 0:4] = np.einsum("bjik,bj->bik", dR, w)
        J[:, nq + 6 :, nq + 6 :] = np.eye(self.joints)
        return J
