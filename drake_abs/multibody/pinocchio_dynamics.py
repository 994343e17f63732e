"""A Drake MultibodyPlant's rigid-body dynamics evaluated by pinocchio, with analytic derivatives:
the fast provider of :class:`~drake_abs.contact.contact_lcp.StepQuantities` for the complementarity
step.

:func:`pinocchio_model_from_plant` copies a finalized MultibodyPlant (masses, inertias, joint
frames, gravity) into a ``pinocchio.Model`` at the same coordinate offsets: every Drake joint with
degrees of freedom must be a RevoluteJoint, a PrismaticJoint or a QuaternionFloatingJoint (welds
are merged into their parent). Revolute and prismatic joints have the same coordinates in both,
``qdot = v``. A quaternion floating joint (a URDF ``floating`` joint, such as the shipped ball's;
any number of them, anywhere in the tree) becomes pinocchio's free flyer, whose coordinates
differ from Drake's: every quantity and derivative is mapped back to Drake's q = (qw, qx, qy, qz,
x, y, z) and v = (w, v) (in the parent frame), N(q) and dN included, so the state does not depend
on the provider (:mod:`drake_abs.multibody.pinocchio_free_joints`; the quaternion is extended off
the unit sphere as Drake's AutoDiffXd derivatives extend it). Other free bodies get a floating
base made of joints (see :func:`drake_abs.multibody.builder.add_floating_base_chains`).

:class:`PinocchioContactModel` has the interface of
:class:`~drake_abs.multibody.drake_dynamics.MultibodyContactModel` and gives the same numbers
(tests check every quantity and derivative against it), in a fraction of the time:

- values: ``computeMinverse`` (W), ``aba`` (v_free = v + h aba(q, v, B u), gravity and bias
  included), ``computeJointJacobians`` (points and their Jacobians);
- derivatives: ``computeABADerivatives`` (dv_free); dW only as applied to the step's impulse f
  (``StepQuantities.dW_times``): ``d(W f) = -W dM(q) (W f)``, one ``computeRNEADerivatives`` at
  zero velocity and gravity with acceleration ``W f``; and dJ/dq in closed form from the joint
  Jacobians (see ``_contact_rows``). Pinocchio differentiates with respect to tangent increments
  of its configuration (for revolute and prismatic joints: q itself); with free flyers these are
  chained to Drake's q.
"""

from __future__ import annotations

import numba as nb
import numpy as np
import pinocchio as pin
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    PrismaticJoint,
    QuaternionFloatingJoint,
    RevoluteJoint,
    WeldJoint,
)

from drake_abs.multibody.drake_dynamics import ContactModelBase, PointContact
from drake_abs.multibody.pinocchio_free_joints import FreeJointCoordinates


def _se3(X) -> pin.SE3:
    """A Drake RigidTransform as a pinocchio SE3."""
    return pin.SE3(np.asarray(X.rotation().matrix()), np.asarray(X.translation()))


_SUPPORTED = RevoluteJoint | PrismaticJoint | WeldJoint | QuaternionFloatingJoint


def pinocchio_model_from_plant(plant: MultibodyPlant) -> tuple[pin.Model, dict]:
    """The pinocchio model of a finalized (continuous or discrete) MultibodyPlant, and a map from
    each Drake body index to ``(pinocchio joint id, X_JB)``: the body frame's pose in the frame of
    the pinocchio joint that carries it (world: joint 0).

    A QuaternionFloatingJoint becomes a free-flyer joint at the same coordinate offsets, whose
    coordinates differ from Drake's (see :class:`FreeJointCoordinates`).

    Raises:
        NotImplementedError: for a joint type other than revolute, prismatic, weld or
            quaternion floating.
    """
    if not plant.is_finalized():
        raise ValueError("plant must be finalized")
    context = plant.CreateDefaultContext()
    model = pin.Model()
    model.gravity = pin.Motion(
        np.concatenate([plant.gravity_field().gravity_vector(), np.zeros(3)])
    )
    carried = {int(plant.world_body().index()): (0, pin.SE3.Identity())}
    joints = [plant.get_joint(i) for i in plant.GetJointIndices()]
    for joint in joints:
        if not isinstance(joint, _SUPPORTED):
            raise NotImplementedError(
                f"joint {joint.name()!r} is a {type(joint).__name__}; the pinocchio dynamics "
                "support revolute, prismatic, weld and quaternion floating joints (use the "
                "Drake dynamics)"
            )
    pending = sorted(joints, key=lambda j: (j.num_velocities() > 0, j.velocity_start()))
    ids = {}  # Drake joint index -> pinocchio joint id

    def unique_name(joint) -> str:  # joint names are unique within a model instance only
        return f"{plant.GetModelInstanceName(joint.model_instance())}/{joint.name()}"

    def attach(joint) -> None:
        parent_id, X_JP = carried[int(joint.parent_body().index())]
        X_PF = _se3(joint.frame_on_parent().GetFixedPoseInBodyFrame())
        X_CM = _se3(joint.frame_on_child().GetFixedPoseInBodyFrame())
        X_JF = X_JP * X_PF
        child = joint.child_body()
        if isinstance(joint, WeldJoint):
            carried[int(child.index())] = (parent_id, X_JF * _se3(joint.X_FM()) * X_CM.inverse())
            jid, X_JC = carried[int(child.index())]
        elif isinstance(joint, QuaternionFloatingJoint):
            jid = model.addJoint(parent_id, pin.JointModelFreeFlyer(), X_JF, unique_name(joint))
            ids[int(joint.index())] = jid
            X_JC = X_CM.inverse()
            carried[int(child.index())] = (jid, X_JC)
        else:
            axis = np.asarray(
                joint.revolute_axis()
                if isinstance(joint, RevoluteJoint)
                else joint.translation_axis(),
                float,
            )
            kind = (
                pin.JointModelRevoluteUnaligned
                if isinstance(joint, RevoluteJoint)
                else pin.JointModelPrismaticUnaligned
            )
            jid = model.addJoint(parent_id, kind(axis), X_JF, unique_name(joint))
            ids[int(joint.index())] = jid
            X_JC = X_CM.inverse()
            carried[int(child.index())] = (jid, X_JC)
        M = child.CalcSpatialInertiaInBodyFrame(context)
        mass = float(M.get_mass())
        if mass > 0:
            com = np.asarray(M.get_com())
            I_com = M.Shift(com).CalcRotationalInertia().CopyToFullMatrix3()
            model.appendBodyToJoint(jid, pin.Inertia(mass, com, I_com), X_JC)

    while pending:  # parents first; welds as soon as their parent is placed
        ready = [j for j in pending if int(j.parent_body().index()) in carried]
        if not ready:
            raise ValueError("the plant's joints do not form a tree rooted at the world")
        joint = ready[0]
        if joint.num_velocities() and any(w.num_velocities() == 0 for w in ready):
            joint = next(w for w in ready if w.num_velocities() == 0)
        attach(joint)
        pending.remove(joint)
    for joint in joints:
        if joint.num_velocities():
            pj = model.joints[ids[int(joint.index())]]
            if (pj.idx_q, pj.idx_v) != (joint.position_start(), joint.velocity_start()):
                raise ValueError(
                    f"joint {joint.name()!r}: pinocchio coordinates ({pj.idx_q}, {pj.idx_v}) "
                    f"differ from Drake's ({joint.position_start()}, {joint.velocity_start()})"
                )
    # the actuators' reflected inertia (MJCF armature: rotor inertia x gear^2), which Drake's
    # mass matrix includes, as pinocchio's joint armature (its CRBA and ABA include it)
    armature = np.zeros(model.nv)
    for a in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(a)
        armature[actuator.joint().velocity_start()] += actuator.default_reflected_inertia()
    model.armature = armature
    return model, carried


class PinocchioContactModel(ContactModelBase):
    """Step quantities of a MultibodyPlant (revolute, prismatic, weld and quaternion floating
    joints) with point contacts against one ground plane, evaluated by pinocchio, in Drake's
    coordinates. Arguments as :class:`~drake_abs.multibody.drake_dynamics.MultibodyContactModel`.
    """

    def _setup(self) -> None:
        pairs = [c for c in self.contacts if not isinstance(c, PointContact)]
        if pairs:
            raise NotImplementedError(
                f"pinocchio evaluates point contacts against the ground only; {len(pairs)} "
                "candidates are body-body pairs (e.g. "
                f"{pairs[0].body_a!r}-{pairs[0].body_b!r}); use dynamics: drake"
            )
        plant = self.plant
        self._eye = np.eye(self.nq)
        self._lower = np.tril_indices(self.nv, -1)
        self.pin_model, carried = pinocchio_model_from_plant(plant)
        self.pin_data = self.pin_model.createData()
        free = self.pin_model.copy()
        free.gravity = pin.Motion.Zero()
        self._free_model, self._free_data = free, free.createData()
        #: the quaternion floating joints' coordinate maps (None without any: then pinocchio's
        #: coordinates are Drake's, qdot = v)
        self._coords = FreeJointCoordinates(plant) if self.quaternion_starts else None
        if self._coords is not None:  # dN/dp: constant (N is linear in the quaternions)
            self._dN = np.zeros((self.nq, self.nv, self.nq + self.nv + self.nu))
            self._dN[..., : self.nq] = self._coords.dN
        self._points = []  # (pinocchio joint id, p_J: the contact point in that joint's frame)
        for body in self._bodies_d:
            jid, X_JB = carried[int(body.index())]
            self._points.append((jid, X_JB))
        self._points = [
            (jid, X_JB.act(np.asarray(c.p_BC, float)))
            for (jid, X_JB), c in zip(self._points, self.contacts, strict=True)
        ]
        m = self.pin_model
        # per contact, which velocities lie on its body's path from the world (root first), and
        # the rank on that path of the joint each belongs to
        self._on_path = np.full((len(self._points), self.nv), -1, dtype=np.int64)
        self._rank = np.full((len(self._points), self.nv), -1, dtype=np.int64)
        for i, (jid, _) in enumerate(self._points):
            path, rank = [], []
            for r, j in enumerate(j for j in m.supports[jid] if j > 0):
                path.extend(range(m.joints[j].idx_v, m.joints[j].idx_v + m.joints[j].nv))
                rank.extend([r] * m.joints[j].nv)
            self._on_path[i, : len(path)] = path
            self._rank[i, : len(rank)] = rank
        self._radius = np.array([c.radius for c in self.contacts], dtype=float)
        joints = sorted({jid for jid, _ in self._points})
        self._by_joint = []  # (joint id, its contacts' indices, their points in its frame)
        for jid in joints:
            idx = np.array([i for i, (j, _) in enumerate(self._points) if j == jid])
            self._by_joint.append((jid, idx, np.array([self._points[i][1] for i in idx])))
        self._has_friction = np.array([c.friction is not None for c in self.contacts])

    def _pin_q(self, q: np.ndarray) -> np.ndarray:
        """Pinocchio's configuration at Drake's q (the same vector without free joints)."""
        return q if self._coords is None else self._coords.at(q).q_pin

    def _centres(self) -> np.ndarray:
        """World positions (nc, 3) of every contact centre after the last forward kinematics:
        one placement read per joint that carries contacts."""
        data = self.pin_data
        if len(self._by_joint) == 1:  # every contact on one body (a box, a ball)
            jid, _, p_J = self._by_joint[0]
            X = data.oMi[jid]
            return p_J @ X.rotation.T + X.translation
        out = np.empty((len(self.contacts), 3))
        for jid, idx, p_J in self._by_joint:
            X = data.oMi[jid]
            out[idx] = p_J @ X.rotation.T + X.translation
        return out

    def _distances(self, q: np.ndarray) -> np.ndarray:
        model, data = self.pin_model, self.pin_data
        out = np.empty((len(q), len(self.contacts)))
        for b, qb in enumerate(q):
            pin.forwardKinematics(model, data, self._pin_q(np.asarray(qb, float)))
            out[b] = self._centres() @ self.normal - self._radius - self.ground.height
        return out

    def _kinematics(self, q: np.ndarray) -> tuple:
        """``(centres (nc, 3), J (6, nv), maps)`` at Drake's q: every contact centre in the
        world, pinocchio's world-frame joint Jacobians (one ``computeJointJacobians``) and the
        free joints' :class:`FreeJointState` (None without free joints)."""
        maps = None if self._coords is None else self._coords.at(q)
        pin.computeJointJacobians(self.pin_model, self.pin_data, q if maps is None else maps.q_pin)
        # (6, nv) even for nv = 1, where the binding hands back a vector
        return self._centres(), np.array(self.pin_data.J).reshape(6, self.nv), maps

    def quantities_within(self, q, v, u, distance, *, derivatives=True):
        """As the base class, with one kinematics pass for the distances and the quantities
        (the base class's, for a plant with affine quantities)."""
        if self.affine is not None:
            return super().quantities_within(q, v, u, distance, derivatives=derivatives)
        kinematics = self._kinematics(np.asarray(q[0], float))
        phi = kinematics[0] @ self.normal - self._radius - self.ground.height
        active = np.flatnonzero(phi <= distance)
        quant = self.quantities(q, v, u, active, derivatives=derivatives, kinematics=kinematics)
        return active, quant

    def _contacts(self, kinematics, active, derivatives: bool, P: int = 0):
        """phi (na,), Jn (na, nv), Jt (nt, nv) and, with derivatives, dphi/dq (na, nq) and
        dJn/dq, dJt/dq (rows, nv, nq) for the active contacts, in Drake's coordinates, from the
        contact centres and the world-frame joint Jacobians (see :meth:`_kinematics` and
        :func:`_contact_rows`). With quaternion floating joints the derivatives are d/dp, P
        columns (zero beyond q's).
        """
        centres, J, maps = kinematics
        phi, Jn, Jt, dphi, dJn, dJt = _contact_rows(
            centres, np.asarray(active, dtype=np.int64), self._radius, self.normal,
            float(self.ground.height), self.tangents, self._has_friction, J, self._on_path,
            self._rank, derivatives,
        )  # fmt: skip
        if maps is not None:  # pinocchio's velocities and tangent increments -> Drake's v, q
            if derivatives:
                wide = np.zeros((len(dphi), P))
                wide[:, : self.nq] = dphi @ maps.D
                dphi = wide
                dJn = maps.jacobian_derivative(Jn, dJn, P)
                dJt = maps.jacobian_derivative(Jt, dJt, P)
            Jn, Jt = Jn @ maps.T, Jt @ maps.T
        out = {"phi": phi, "Jn": Jn, "Jt": Jt}
        if derivatives:
            out.update(dphi=dphi, dJn=dJn, dJt=dJt)
        return out

    def _one(self, q, v, u, active, derivatives: bool, kinematics=None) -> dict:
        q = np.asarray(q, float)
        if kinematics is None:
            kinematics = self._kinematics(q)
        if kinematics[2] is not None:
            return self._one_free(q, v, u, active, derivatives, kinematics)
        model, data = self.pin_model, self.pin_data
        nq, nv, nu = self.nq, self.nv, self.nu
        h = self.h
        v = np.asarray(v, float)
        tau = self.B_act @ np.asarray(u, float)
        if not derivatives:
            a = pin.aba(model, data, q, v, tau)
            W = pin.computeMinverse(model, data, q)  # upper triangle
            W[self._lower] = W.T[self._lower]
            out = self._contacts(kinematics, active, False)
            return dict(W=W, v_free=v + h * a, N=self._eye, **out)
        da_dq, da_dv, W = pin.computeABADerivatives(model, data, q, v, tau)
        W = W.copy()  # data.Minv, upper triangle
        W[self._lower] = W.T[self._lower]
        a = data.ddq.copy()
        P = nq + nv + nu
        dv_free = np.zeros((nv, P))
        dv_free[:, :nq] = h * da_dq
        dv_free[:, nq : nq + nv] = np.eye(nv) + h * da_dv
        dv_free[:, nq + nv :] = h * W @ self.B_act
        fm, fd = self._free_model, self._free_data
        zero = np.zeros(nv)
        q = q.copy()  # held by dW_times, evaluated after the LCP solve

        def dW_times(f: np.ndarray) -> np.ndarray:  # (nv,) -> (nv, P): d(W f) = -W dM (W f)
            dW_f = np.zeros((nv, P))
            dM_a = pin.computeRNEADerivatives(fm, fd, q, zero, W @ f)[0]  # at zero v, gravity
            dW_f[:, :nq] = -W @ dM_a
            return dW_f

        c = self._contacts(kinematics, active, True)

        def widen(d):  # (..., nq) -> (..., P): only q-columns are non-zero
            out = np.zeros(d.shape[:-1] + (P,))
            out[..., :nq] = d
            return out

        return dict(
            W=W, v_free=v + h * a, N=self._eye, phi=c["phi"], Jn=c["Jn"], Jt=c["Jt"],
            dW_times=dW_times, dv_free=dv_free, dphi=widen(c["dphi"]), dJn=widen(c["dJn"]),
            dJt=widen(c["dJt"]), dN=np.zeros((nq, nv, P)),
        )  # fmt: skip

    def _one_free(self, q, v, u, active, derivatives: bool, kinematics) -> dict:
        """:meth:`_one` for a plant with quaternion floating joints: pinocchio evaluated at
        ``(q_pin, T v, T B u)`` and everything mapped back to Drake's coordinates (see
        :mod:`~drake_abs.multibody.pinocchio_free_joints`)."""
        model, data = self.pin_model, self.pin_data
        nq, nv, nu = self.nq, self.nv, self.nu
        maps = kinematics[2]
        T, q_pin = maps.T, maps.q_pin
        v = np.asarray(v, float)
        v_pin = T @ v
        tau_pin = T @ (self.B_act @ np.asarray(u, float))
        if not derivatives:
            a = pin.aba(model, data, q_pin, v_pin, tau_pin)
            W = pin.computeMinverse(model, data, q_pin)  # upper triangle
            W[self._lower] = W.T[self._lower]
            v_free, W_drake, _ = maps.dynamics(v, a, W, W, W, tau_pin, self.B_act, self.h, False)
            out = self._contacts(kinematics, active, False)
            return dict(W=W_drake, v_free=v_free, N=maps.N, **out)
        da_dq, da_dv, W = pin.computeABADerivatives(model, data, q_pin, v_pin, tau_pin)
        W = W.copy()  # data.Minv, upper triangle
        W[self._lower] = W.T[self._lower]
        v_free, W_drake, dv_free = maps.dynamics(
            v, data.ddq, W, da_dq, da_dv, tau_pin, self.B_act, self.h, True
        )
        P = nq + nv + nu
        fm, fd = self._free_model, self._free_data
        zero = np.zeros(nv)
        q_pin = q_pin.copy()  # held by dW_times, evaluated after the LCP solve

        def dW_times(f: np.ndarray) -> np.ndarray:  # (nv,) -> (nv, P)
            g = T @ f
            z = W @ g
            dM_z = pin.computeRNEADerivatives(fm, fd, q_pin, zero, z)[0]  # at zero v, gravity
            return maps.inverse_mass_derivative(W, g, z, dM_z, P)

        c = self._contacts(kinematics, active, True, P)
        return dict(
            W=W_drake, v_free=v_free, N=maps.N, phi=c["phi"], Jn=c["Jn"], Jt=c["Jt"],
            dW_times=dW_times, dv_free=dv_free, dphi=c["dphi"], dJn=c["dJn"], dJt=c["dJt"],
            dN=self._dN.copy(),
        )  # fmt: skip


@nb.njit(cache=True)
def _contact_rows(
    centres, active, radius, n, height, tangents, friction, J, paths, ranks, derivatives
):  # fmt: skip
    """Rows of the active contacts (indices ``active``, na of them): ``phi`` (na,), ``Jn`` (na,
    nv), ``Jt`` (nt, nv) and, with ``derivatives``, ``dphi`` (na, nv), ``dJn`` (na, nv, nv),
    ``dJt`` (nt, nv, nv), in pinocchio's velocities, derivatives with respect to its tangent
    increments (Drake's q and v for 1-dof joints).

    Per candidate: centres (nc, 3) in the world (the witness point is ``Q = C - radius n``),
    radius (nc,), friction (nc,) whether it has friction, paths (nc, nv) the velocity indices on
    its body's path from the world (root first, -1 padded), ranks (nc, nv) the rank on that path
    of the joint each index belongs to. J (6, nv): the world-frame joint Jacobians (linear rows
    first) of all joints. The body joint's Jacobian is J restricted to its path's columns, so a
    point p fixed on the body moves with ``J_p = Jv - [p]x Jw``.
    """
    na = active.shape[0]
    nv = J.shape[1]
    k = tangents.shape[0]
    nt = 0
    for a in active:
        if friction[a]:
            nt += k
    phi = np.empty(na)
    Jn = np.zeros((na, nv))
    Jt = np.zeros((nt, nv))
    m = nv if derivatives else 0
    dphi = np.zeros((na, m))
    dJn = np.zeros((na, m, m))
    dJt = np.zeros((nt, m, m))
    row_t = 0
    for i in range(na):
        c = active[i]
        C = centres[c]
        Q = C - radius[c] * n
        phi[i] = n[0] * C[0] + n[1] * C[1] + n[2] * C[2] - radius[c] - height
        count = 0
        while count < nv and paths[c, count] >= 0:
            count += 1
        path = paths[c, :count]
        rank = ranks[c, :count]
        Jv = np.zeros((3, nv))
        Jw = np.zeros((3, nv))
        for j in path:
            Jv[:, j] = J[:3, j]
            Jw[:, j] = J[3:, j]
        J_Q = np.zeros((3, nv))
        J_C = np.zeros((3, nv))
        for j in path:
            J_Q[:, j] = Jv[:, j] - np.cross(Q, Jw[:, j])
            J_C[:, j] = Jv[:, j] - np.cross(C, Jw[:, j])
        Jn[i] = n @ J_Q
        if friction[c]:
            Jt[row_t : row_t + k] = tangents @ J_Q
        if derivatives:
            dphi[i] = n @ J_C
            dJ_Q = _point_jacobian_derivative(Jv, Jw, path, rank, J_C, Q)
            for a in range(nv):
                for b in range(nv):
                    d = dJ_Q[:, a, b]
                    dJn[i, a, b] = n[0] * d[0] + n[1] * d[1] + n[2] * d[2]
                    if friction[c]:
                        for t in range(k):
                            tt = tangents[t]
                            dJt[row_t + t, a, b] = tt[0] * d[0] + tt[1] * d[1] + tt[2] * d[2]
        if friction[c]:
            row_t += k
    return phi, Jn, Jt, dphi, dJn, dJt


@nb.njit(cache=True)
def _point_jacobian_derivative(Jv, Jw, path, rank, J_C, Q):
    """d J_Q / d(tangent increment) (3, nv, nv) of ``J_Q = Jv - [Q]x Jw`` for the point
    Q = C - r n, from the body joint's world-frame Jacobian (Jv, Jw (3, nv)), the velocity
    indices on its path from the world (root first) and their joints' ranks on the path, the
    Jacobian J_C of the body-fixed point C and Q's world position.

    A column S_j moves with an increment along column S_k of its own joint or of a joint before
    it on the path (pinocchio moves a joint's frame by ``X exp(d)``: every motion after it is
    carried along): ``dS_j/dk = S_k x S_j`` (spatial cross product), so ``dJv_j/dk = w_k x v_j
    + v_k x w_j`` and ``dJw_j/dk = w_k x w_j``; then ``dJ_Q[:, j, k] = dJv_j/dk - Q x dJw_j/dk
    - (J_C[:, k]) x Jw[:, j]``.
    """
    nv = Jv.shape[1]
    out = np.zeros((3, nv, nv))
    for a in range(path.shape[0]):
        k = path[a]
        for b in range(path.shape[0]):
            j = path[b]
            dv = np.zeros(3)
            if rank[b] >= rank[a]:
                wk, vk, vj, wj = Jw[:, k], Jv[:, k], Jv[:, j], Jw[:, j]
                dv = np.cross(wk, vj) + np.cross(vk, wj) - np.cross(Q, np.cross(wk, wj))
            out[:, j, k] = dv - np.cross(J_C[:, k], Jw[:, j])
    return out
