"""Drake's coordinates of quaternion floating joints against pinocchio's free-flyer coordinates,
for :class:`~drake_abs.multibody.pinocchio_dynamics.PinocchioContactModel`.

A joint between the frames F (on the parent) and M (on the child), at Drake position index s and
velocity index t (the free flyer has the same offsets in pinocchio's model):

- Drake: ``q[s:s+7] = (qw, qx, qy, qz, p_FM)``, ``v[t:t+6] = (w_FM, v_FM)``, both vectors
  expressed in F; ``qdot = N(q) v`` with the quaternion rate ``0.5 (0, w_FM) (x) e``
  (quaternion product, e = (qw, qx, qy, qz)) and ``pdot = v_FM``;
- pinocchio: ``(p_FM, qx, qy, qz, qw)`` with a unit quaternion, and the twist in M,
  ``(R^T v_FM, R^T w_FM)`` (R = R_FM).

So ``v_pin = T(q) v`` with T orthogonal (``R^T`` blocks; 1 for the other joints, whose
coordinates are the same in both): the mass matrix is ``T^T M_pin T``, ``W = T^T W_pin T``, a
generalized force maps as ``tau_pin = T tau`` and a Jacobian as ``J = J_pin T``. Accelerations
differ by the rotation of the frame M: ``vdot = T^T a_pin + c(v)``, c being ``w_FM x v_FM`` in
each joint's translational rows.

Derivatives: pinocchio differentiates with respect to a tangent increment d of its configuration
(the free flyer's pose moved to ``X_FM exp(d)``, ``d = (dp, dtheta)`` in M). A change dq of
Drake's q is the increment ``d = D(q) dq``: ``dp = R^T dp_FM`` and, for the quaternion e of any
norm, ``dtheta = (2 / |e|^2) vec(conj(e) (x) de)``. That is how Drake's own AutoDiffXd
derivatives extend the quaternion off the unit sphere: its rotation is ``R(e / |e|)``, so every
quantity but N depends on ``e / |e|`` alone (the radial direction de = e gives d = 0), while N is
linear in the unnormalized e (so dN is constant). T depends on q through R: moving Drake's
quaternion coordinate k changes it by ``dT_k = -S_k T``, where S_k applies ``dtheta_k x`` to
each 3-vector of the joint's block (``dtheta_k = D[t+3:t+6, k]``).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import QuaternionFloatingJoint


class FreeJointCoordinates:
    """The maps between Drake's and pinocchio's coordinates of a finalized plant with
    quaternion floating joints (see the module docstring)."""

    def __init__(self, plant: MultibodyPlant):
        joints = [plant.get_joint(i) for i in plant.GetJointIndices()]
        free = sorted(
            (int(j.position_start()), int(j.velocity_start()))
            for j in joints
            if isinstance(j, QuaternionFloatingJoint)
        )
        #: Drake position and velocity start of each quaternion floating joint
        self.q_starts = np.array([s for s, _ in free], dtype=np.int64)
        self.v_starts = np.array([t for _, t in free], dtype=np.int64)
        self.nq, self.nv = plant.num_positions(), plant.num_velocities()
        single = [
            (j.position_start(), j.velocity_start()) for j in joints if j.num_velocities() == 1
        ]
        #: the 1-dof joints' position and velocity indices (N, D and T are 1 there)
        self._single = np.array(single, dtype=np.int64).reshape(-1, 2)
        #: dN/dq (nq, nv, nq), constant, N being linear in the quaternions
        self.dN = np.zeros((self.nq, self.nv, self.nq))
        for s, t in free:
            for m in range(4):
                e = np.zeros(4)
                e[m] = 1.0
                self.dN[s : s + 4, t : t + 3, s + m] = _quaternion_rate(e)

    def at(self, q: np.ndarray) -> FreeJointState:
        """The maps at Drake's configuration q (nq,)."""
        q_pin, T, D, N, G = _maps(
            np.ascontiguousarray(q, dtype=float), self.q_starts, self.v_starts,
            self._single[:, 0], self._single[:, 1], self.nv,
        )  # fmt: skip
        return FreeJointState(self, q_pin, T, D, N, G)


class FreeJointState:
    """:class:`FreeJointCoordinates` at one configuration: pinocchio's configuration ``q_pin``
    (nq,), ``T`` (nv, nv), ``D`` (nv, nq), Drake's ``N`` (nq, nv) and ``G`` (joints, 3, 4):
    dtheta/de of each joint."""

    __slots__ = ("coords", "q_pin", "T", "D", "N", "G")

    def __init__(self, coords, q_pin, T, D, N, G):
        self.coords, self.q_pin, self.T, self.D, self.N, self.G = coords, q_pin, T, D, N, G

    def rotation_columns(self, x: np.ndarray) -> np.ndarray:
        """(nv, nq): column k is ``S_k x`` for a vector x (nv,) of pinocchio's velocity space
        (non-zero in the quaternion columns only)."""
        c = self.coords
        return _rotation_columns(
            np.ascontiguousarray(x, dtype=float), c.q_starts, c.v_starts, self.G, c.nq
        )

    def acceleration_offset(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(c (nv,), dc/dv (nv, nv))`` at Drake's v: ``vdot = T^T a_pin + c``."""
        return _acceleration_offset(np.ascontiguousarray(v, dtype=float), self.coords.v_starts)

    def jacobian_derivative(self, J: np.ndarray, dJ: np.ndarray, P: int) -> np.ndarray:
        """d(J_pin T)/dp (r, nv, P), non-zero in the nq columns of q, from pinocchio's rows J
        (r, nv) and their derivatives with respect to its tangent increments dJ (r, nv, nv):
        ``(dJ D_k - J S_k) T`` per Drake coordinate k."""
        c = self.coords
        return _jacobian_derivative(J, dJ, self.D, self.T, c.q_starts, c.v_starts, self.G, P)

    def dynamics(self, v, a, W, da_dq, da_dv, tau_pin, B_act, h, derivatives: bool):
        """``(v_free (nv,), W (nv, nv), dv_free (nv, P))`` in Drake's coordinates from
        pinocchio's acceleration a, inverse mass matrix W and, with ``derivatives``, ABA's
        derivatives da_dq, da_dv, at ``(q_pin, T v, tau_pin = T B u)`` (dv_free is empty
        without ``derivatives``)."""
        c = self.coords
        v, a, tau_pin = (np.ascontiguousarray(x, dtype=float) for x in (v, a, tau_pin))
        return _dynamics(
            v, a, W, da_dq, da_dv, tau_pin, B_act, h, self.T, self.D, c.q_starts, c.v_starts,
            self.G, derivatives,
        )  # fmt: skip

    def inverse_mass_derivative(self, W, g, z, dM_z, P: int) -> np.ndarray:
        """d(W_drake f)/dp (nv, P) with ``W_drake = T^T W T``, g = T f, z = W g and dM_z the
        tangent derivative of ``M_pin z`` (``computeRNEADerivatives`` at zero velocity and
        gravity with acceleration z): ``T^T (S_k z - W dM_k z - W S_k g)`` per column k."""
        c = self.coords
        return _inverse_mass_derivative(
            W, g, z, dM_z, self.T, self.D, c.q_starts, c.v_starts, self.G, P
        )


def _quaternion_rate(e: np.ndarray) -> np.ndarray:
    """(4, 3): the quaternion rate ``0.5 (0, w) (x) e`` as a matrix acting on w."""
    out = np.empty((4, 3))
    out[0] = -0.5 * e[1:]
    out[1:] = 0.5 * (e[0] * np.eye(3) - _skew(e[1:]))
    return out


@nb.njit(cache=True)
def _skew(x):
    """``[x]x`` (3, 3): ``_skew(x) @ y = x x y``."""
    out = np.zeros((3, 3))
    out[0, 1], out[0, 2], out[1, 2] = -x[2], x[1], -x[0]
    out[1, 0], out[2, 0], out[2, 1] = x[2], -x[1], x[0]
    return out


@nb.njit(cache=True, error_model="numpy")  # a zero quaternion gives non-finite maps
def _maps(q, q_starts, v_starts, single_q, single_v, nv):
    """q_pin (nq,), T (nv, nv), D (nv, nq), N (nq, nv), G (joints, 3, 4) at Drake's q."""
    nq = q.shape[0]
    q_pin = q.copy()
    T = np.zeros((nv, nv))
    D = np.zeros((nv, nq))
    N = np.zeros((nq, nv))
    for i in range(single_q.shape[0]):
        T[single_v[i], single_v[i]] = 1.0
        D[single_v[i], single_q[i]] = 1.0
        N[single_q[i], single_v[i]] = 1.0
    G = np.zeros((q_starts.shape[0], 3, 4))
    for f in range(q_starts.shape[0]):
        s, t = q_starts[f], v_starts[f]
        ew, ex, ey, ez = q[s], q[s + 1], q[s + 2], q[s + 3]
        norm2 = ew * ew + ex * ex + ey * ey + ez * ez
        r = 1.0 / np.sqrt(norm2)
        w, x, y, z = ew * r, ex * r, ey * r, ez * r
        q_pin[s], q_pin[s + 1], q_pin[s + 2] = q[s + 4], q[s + 5], q[s + 6]
        q_pin[s + 3], q_pin[s + 4], q_pin[s + 5], q_pin[s + 6] = x, y, z, w
        # R^T of the unit quaternion (w, x, y, z)
        Rt = np.empty((3, 3))
        Rt[0, 0] = 1.0 - 2.0 * (y * y + z * z)
        Rt[1, 1] = 1.0 - 2.0 * (x * x + z * z)
        Rt[2, 2] = 1.0 - 2.0 * (x * x + y * y)
        Rt[0, 1] = 2.0 * (x * y + w * z)
        Rt[1, 0] = 2.0 * (x * y - w * z)
        Rt[0, 2] = 2.0 * (x * z - w * y)
        Rt[2, 0] = 2.0 * (x * z + w * y)
        Rt[1, 2] = 2.0 * (y * z + w * x)
        Rt[2, 1] = 2.0 * (y * z - w * x)
        for i in range(3):
            for j in range(3):
                T[t + i, t + 3 + j] = Rt[i, j]  # v_M = R^T v_FM
                T[t + 3 + i, t + j] = Rt[i, j]  # w_M = R^T w_FM
                D[t + i, s + 4 + j] = Rt[i, j]  # dp = R^T dp_FM
        # dtheta = (2 / |e|^2) (-vec(e) dew + (ew I - [vec(e)]x) dvec(e))
        c = 2.0 / norm2
        g = G[f]
        g[0, 0], g[1, 0], g[2, 0] = -c * ex, -c * ey, -c * ez
        g[0, 1], g[0, 2], g[0, 3] = c * ew, c * ez, -c * ey
        g[1, 1], g[1, 2], g[1, 3] = -c * ez, c * ew, c * ex
        g[2, 1], g[2, 2], g[2, 3] = c * ey, -c * ex, c * ew
        for i in range(3):
            for j in range(4):
                D[t + 3 + i, s + j] = g[i, j]
        # edot = 0.5 (0, w) (x) e (e unnormalized), pdot = v
        N[s, t], N[s, t + 1], N[s, t + 2] = -0.5 * ex, -0.5 * ey, -0.5 * ez
        N[s + 1, t], N[s + 1, t + 1], N[s + 1, t + 2] = 0.5 * ew, 0.5 * ez, -0.5 * ey
        N[s + 2, t], N[s + 2, t + 1], N[s + 2, t + 2] = -0.5 * ez, 0.5 * ew, 0.5 * ex
        N[s + 3, t], N[s + 3, t + 1], N[s + 3, t + 2] = 0.5 * ey, -0.5 * ex, 0.5 * ew
        for i in range(3):
            N[s + 4 + i, t + 3 + i] = 1.0
    return q_pin, T, D, N, G


@nb.njit(cache=True)
def _rotation_columns(x, q_starts, v_starts, G, nq):
    """(nv, nq): column k is ``S_k x`` (``dtheta_k x`` applied to each 3-vector of the block)."""
    out = np.zeros((x.shape[0], nq))
    for f in range(q_starts.shape[0]):
        s, t = q_starts[f], v_starts[f]
        for b in (t, t + 3):
            for k in range(4):
                d0, d1, d2 = G[f, 0, k], G[f, 1, k], G[f, 2, k]
                x0, x1, x2 = x[b], x[b + 1], x[b + 2]
                out[b, s + k] = d1 * x2 - d2 * x1
                out[b + 1, s + k] = d2 * x0 - d0 * x2
                out[b + 2, s + k] = d0 * x1 - d1 * x0
    return out


@nb.njit(cache=True)
def _acceleration_offset(v, v_starts):
    """c (nv,) = ``w_FM x v_FM`` in each joint's translational rows, and dc/dv (nv, nv)."""
    nv = v.shape[0]
    c = np.zeros(nv)
    dc = np.zeros((nv, nv))
    for t in v_starts:
        w0, w1, w2 = v[t], v[t + 1], v[t + 2]
        u0, u1, u2 = v[t + 3], v[t + 4], v[t + 5]
        c[t + 3], c[t + 4], c[t + 5] = w1 * u2 - w2 * u1, w2 * u0 - w0 * u2, w0 * u1 - w1 * u0
        dc[t + 3 : t + 6, t : t + 3] = -_skew(v[t + 3 : t + 6])
        dc[t + 3 : t + 6, t + 3 : t + 6] = _skew(v[t : t + 3])
    return c, dc


@nb.njit(cache=True)
def _dynamics(v, a, W, da_dq, da_dv, tau_pin, B_act, h, T, D, q_starts, v_starts, G, derivatives):
    """See :meth:`FreeJointState.dynamics`. With ``vdot = T^T a_pin + c(v)``, ``v_pin = T v``
    and ``tau_pin = T B u``: column k of q, ``d vdot = T^T (S_k a + A_d D_k - A_v S_k v_pin -
    W S_k tau_pin)`` (A_d, A_v pinocchio's da/d(increment), da/dv_pin); the v columns
    ``T^T A_v T + dc/dv``; the u columns ``W_drake B``."""
    nv, nq = D.shape
    nu = B_act.shape[1]
    Tt = np.ascontiguousarray(T.T)
    c, dc = _acceleration_offset(v, v_starts)
    v_free = v + h * (Tt @ a + c)
    W_drake = Tt @ W @ T
    if not derivatives:
        return v_free, W_drake, np.zeros((0, 0))
    P = nq + nv + nu
    dv_free = np.zeros((nv, P))
    inner = da_dq @ D + _rotation_columns(a, q_starts, v_starts, G, nq)
    inner -= da_dv @ _rotation_columns(T @ v, q_starts, v_starts, G, nq)
    if nu:
        inner -= W @ _rotation_columns(tau_pin, q_starts, v_starts, G, nq)
        dv_free[:, nq + nv :] = h * (W_drake @ B_act)
    dv_free[:, :nq] = h * (Tt @ inner)
    dv_free[:, nq : nq + nv] = h * (Tt @ da_dv @ T + dc)
    for i in range(nv):
        dv_free[i, nq + i] += 1.0
    return v_free, W_drake, dv_free


@nb.njit(cache=True)
def _inverse_mass_derivative(W, g, z, dM_z, T, D, q_starts, v_starts, G, P):
    """See :meth:`FreeJointState.inverse_mass_derivative`."""
    nv, nq = D.shape
    inner = _rotation_columns(z, q_starts, v_starts, G, nq) - W @ (dM_z @ D)
    inner -= W @ _rotation_columns(g, q_starts, v_starts, G, nq)
    out = np.zeros((nv, P))
    out[:, :nq] = np.ascontiguousarray(T.T) @ inner
    return out


@nb.njit(cache=True)
def _jacobian_derivative(J, dJ, D, T, q_starts, v_starts, G, P):
    """``(dJ D_k - J S_k) T`` (r, nv, P) per Drake coordinate k (zero beyond nq)."""
    r, nv = J.shape
    nq = D.shape[1]
    out = np.zeros((r, nv, P))
    for i in range(r):
        E = np.ascontiguousarray(dJ[i]) @ D  # (nv, nq)
        for f in range(q_starts.shape[0]):
            s, t = q_starts[f], v_starts[f]
            for b in (t, t + 3):  # (J S_k)[b:b+3] = J[b:b+3] x dtheta_k
                j0, j1, j2 = J[i, b], J[i, b + 1], J[i, b + 2]
                for k in range(4):
                    d0, d1, d2 = G[f, 0, k], G[f, 1, k], G[f, 2, k]
                    E[b, s + k] -= j1 * d2 - j2 * d1
                    E[b + 1, s + k] -= j2 * d0 - j0 * d2
                    E[b + 2, s + k] -= j0 * d1 - j1 * d0
        out[i, :, :nq] = T.T @ E
    return out
