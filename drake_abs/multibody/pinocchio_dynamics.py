"""A Drake MultibodyPlant's rigid-body dynamics evaluated by pinocchio, with analytic derivatives:
the fast provider of :class:`~drake_abs.contact.step_data.StepQuantities` for the complementarity
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
base made of joints (see :func:`drake_abs.multibody.parsing.add_floating_base_chains`).

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

from collections.abc import Mapping

import numba as nb
import numpy as np
import pinocchio as pin
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    PrismaticJoint,
    QuaternionFloatingJoint,
    RevoluteJoint,
    SpatialInertia,
    WeldJoint,
)

from drake_abs.contact.damping import JointSprings, check_springs, effective_damping
from drake_abs.contact.step_data import StepQuantities
from drake_abs.multibody.drake_dynamics import (
    ContactModelBase,
    PointContact,
    apply_spatial_inertias,
)
from drake_abs.multibody.pinocchio_free_joints import FreeJointCoordinates
from drake_abs.multibody.tree_kinematics import TreeKinematics


def _se3(X) -> pin.SE3:
    """A Drake RigidTransform as a pinocchio SE3."""
    return pin.SE3(np.asarray(X.rotation().matrix()), np.asarray(X.translation()))


_SUPPORTED = RevoluteJoint | PrismaticJoint | WeldJoint | QuaternionFloatingJoint


def pinocchio_model_from_plant(
    plant: MultibodyPlant, spatial_inertias: Mapping[int, SpatialInertia] | None = None
) -> tuple[pin.Model, dict]:
    """The pinocchio model of a finalized (continuous or discrete) MultibodyPlant, and a map from
    each Drake body index to ``(pinocchio joint id, X_JB)``: the body frame's pose in the frame of
    the pinocchio joint that carries it (world: joint 0). The bodies' inertias are the plant's
    defaults, but for those ``spatial_inertias`` gives (``{body index: SpatialInertia}``, about
    the body origin, in the body frame; see
    :class:`~drake_abs.multibody.drake_dynamics.ContactModelBase`).

    A QuaternionFloatingJoint becomes a free-flyer joint at the same coordinate offsets, whose
    coordinates differ from Drake's (see :class:`FreeJointCoordinates`).

    Raises:
        NotImplementedError: for a joint type other than revolute, prismatic, weld or
            quaternion floating.
    """
    if not plant.is_finalized():
        raise ValueError("plant must be finalized")
    context = plant.CreateDefaultContext()
    apply_spatial_inertias(plant, context, spatial_inertias or {})
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
        self.pin_model, carried = pinocchio_model_from_plant(plant, self.spatial_inertias)
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
        self._has_friction = np.array([c.friction is not None for c in self.contacts])
        #: the joints that carry contacts, and each contact's slot among them
        self._carriers = [int(j) for j in joints]
        self._slot = np.array([joints.index(jid) for jid, _ in self._points], dtype=np.int64)
        self._p_J = np.array([p for _, p in self._points], dtype=float).reshape(-1, 3)
        #: compiled batched placements of the carrying joints (None with a free flyer: then
        #: they are read from pinocchio's data after its kinematics)
        self._tree = TreeKinematics.of(self.pin_model) if self._coords is None else None
        self._carrier_ids = np.array(self._carriers, dtype=np.int64)

    def _pin_q(self, q: np.ndarray) -> np.ndarray:
        """Pinocchio's configuration at Drake's q (the same vector without free joints)."""
        return q if self._coords is None else self._coords.at(q).q_pin

    def _read_placements(self, H: np.ndarray, b: int, data) -> None:
        """Copy the placements (4 x 4) of the joints that carry contacts, after the last forward
        kinematics on ``data``, into ``H[b]`` (nj, 4, 4). ``data`` is named at every call: it
        must be the data the kinematics ran on (a damped model has data of its own, and reading
        another's gives a stale state's contacts)."""
        oMi = data.oMi
        for k, jid in enumerate(self._carriers):
            H[b, k] = oMi[jid].homogeneous

    def _batch_centres(self, H: np.ndarray) -> np.ndarray:
        """Every contact centre in the world (B, nc, 3) from the carrying joints' placements
        H (B, nj, 4, 4)."""
        return _points_in_world(np.ascontiguousarray(H), self._slot, self._p_J)

    def _placements(self, q: np.ndarray) -> np.ndarray:
        """The carrying joints' world placements H (B, nj, 4, 4) at Drake's q (B, nq)."""
        q = np.asarray(q, float)
        if self._tree is not None:
            return self._tree.placements(q, self._carrier_ids)
        model, data = self.pin_model, self.pin_data
        H = np.empty((len(q), len(self._carriers), 4, 4))
        for b, qb in enumerate(q):
            pin.forwardKinematics(model, data, self._pin_q(qb))
            self._read_placements(H, b, data)
        return H

    def _distances(self, q: np.ndarray) -> np.ndarray:
        H = self._placements(q)
        return self._batch_centres(H) @ self.normal - self._radius - self.ground.height

    def quantities(
        self, q, v, u, active=None, *, derivatives=True, kinematics=None, damping=None,
        springs: JointSprings | None = None,
    ) -> StepQuantities:  # fmt: skip
        """As the base class; a batch without quaternion floating joints (any B) is evaluated in
        one pass: one pinocchio call per state (``computeABADerivatives``, which
        also places the joints and fills their Jacobians; or ``computeJointJacobians``, ``aba``
        and ``computeMinverse`` without derivatives), then every contact row of the batch in
        one compiled kernel (:func:`_contact_rows_batch`). Joint damping and springs are then
        taken in the same call: with the effective damping ``D' = D + h K`` the model's
        armature plus ``h D'`` gives ``M + h D'`` and the torque ``tau - D' v - K (q - q_ref)``,
        so ``W = (M + h D')^-1`` and the damped free velocity come out of the one ABA (equal to
        :func:`~drake_abs.contact.damping.implicit_damping` of the undamped ones)."""
        if self._coords is not None or self.affine is not None:
            return super().quantities(
                q, v, u, active, derivatives=derivatives, kinematics=kinematics, damping=damping,
                springs=springs,
            )  # fmt: skip
        active = np.arange(len(self.contacts)) if active is None else np.asarray(active, int)
        springs = check_springs(springs, self.nv)
        D = effective_damping(damping, springs, self.nv, self.h)
        D = D if D.any() else None
        return self._batch_quantities(q, v, u, active, derivatives, D, springs)

    def _damped_model(self, D: np.ndarray | None) -> tuple:
        """``(model, data)`` whose mass matrix is M + h D (armature plus h D; the model itself
        for D None), built once per D."""
        if D is None:
            return self.pin_model, self.pin_data
        cache = self.__dict__.setdefault("_damped_models", {})
        key = D.tobytes()
        if key not in cache:
            model = self.pin_model.copy()
            model.armature = self.pin_model.armature + self.h * D
            cache[key] = (model, model.createData())
        return cache[key]

    def _batch_quantities(
        self, q, v, u, active, derivatives: bool, D, springs: JointSprings | None = None
    ) -> StepQuantities:
        """The batched pass of :meth:`quantities` with the effective damping D (nv,) or None
        and the springs (their stiffness included in D) or None."""
        model, data = self._damped_model(D)
        q, v = np.array(q, float), np.array(v, float)  # copies: dW_times holds q
        B, nq, nv, nu, h = len(q), self.nq, self.nv, self.nu, self.h
        tau = np.asarray(u, float) @ self.B_act.T
        if D is not None:
            tau = tau - D * v  # the damping force at the step's end: h D v+ moved into M
        if springs is not None:
            tau = tau + springs.torque(q)  # the spring's torque at q (its h K v+ is in D)
        W = np.empty((B, nv, nv))
        a = np.empty((B, nv))
        J = np.empty((B, 6, nv))
        H = self._placements(q)  # no free flyer on this path: the compiled kinematics
        if derivatives:
            da_dq = np.empty((B, nv, nv))
            da_dv = np.empty((B, nv, nv))
            for b in range(B):
                da_dq[b], da_dv[b], W[b] = pin.computeABADerivatives(
                    model, data, q[b], v[b], tau[b]
                )
                a[b] = data.ddq
                J[b] = np.reshape(data.J, (6, nv))
        else:
            for b in range(B):
                pin.computeJointJacobians(model, data, q[b])
                J[b] = np.reshape(data.J, (6, nv))
                a[b] = pin.aba(model, data, q[b], v[b], tau[b])
                W[b] = pin.computeMinverse(model, data, q[b])
        upper = np.triu(W)  # pinocchio fills the upper triangle of M^-1
        W = upper + np.swapaxes(np.triu(W, 1), 1, 2)
        phi, Jn, Jt, dphi, dJn, dJt = _contact_rows_batch(
            self._batch_centres(H), np.asarray(active, dtype=np.int64), self._radius,
            self.normal, float(self.ground.height), self.tangents, self._has_friction, J,
            self._on_path, self._rank, derivatives, nq,
        )  # fmt: skip
        N = np.broadcast_to(self._eye, (B, nq, nv))
        if not derivatives:
            return StepQuantities(q=q, v=v, W=W, v_free=v + h * a, phi=phi, Jn=Jn, Jt=Jt, N=N)
        P = nq + nv + nu
        dv_free = np.zeros((B, nv, P))
        dv_free[:, :, :nq] = h * da_dq
        dv_free[:, :, nq : nq + nv] = np.eye(nv) + h * da_dv
        if D is not None:  # tau - D v depends on v
            dv_free[:, :, nq : nq + nv] -= h * W * D
        if springs is not None:  # and the springs' torque on q
            dv_free[:, :, :nq] += h * W @ springs.torque_jacobian(nq)
        dv_free[:, :, nq + nv :] = h * W @ self.B_act

        fm, fd = self._free_model, self._free_data
        zero = np.zeros(nv)

        def dW_times(f: np.ndarray) -> np.ndarray:  # (B, nv) -> (B, nv, P): -W dM (W f)
            Wf = np.einsum("bij,bj->bi", W, f)
            dM_a = np.empty((B, nv, nv))
            for b in range(B):  # at zero velocity and gravity
                dM_a[b] = pin.computeRNEADerivatives(fm, fd, q[b], zero, Wf[b])[0]
            out = np.zeros((B, nv, P))
            out[:, :, :nq] = -W @ dM_a
            return out

        return StepQuantities(
            q=q, v=v, W=W, v_free=v + h * a, phi=phi, Jn=Jn, Jt=Jt, N=N, dv_free=dv_free,
            dphi=dphi, dJn=dJn, dJt=dJt, dN=np.zeros((B, nq, nv, 0)),  # narrow: q columns; N = I
            dW_times=dW_times,
        )  # fmt: skip

    def _kinematics(self, q: np.ndarray) -> tuple:
        """``(centres (nc, 3), J (6, nv), maps)`` at Drake's q: every contact centre in the
        world, pinocchio's world-frame joint Jacobians (one ``computeJointJacobians``) and the
        free joints' :class:`FreeJointState` (None without free joints)."""
        maps = None if self._coords is None else self._coords.at(q)
        pin.computeJointJacobians(self.pin_model, self.pin_data, q if maps is None else maps.q_pin)
        # (6, nv) even for nv = 1, where the binding hands back a vector
        H = np.empty((1, len(self._carriers), 4, 4))
        self._read_placements(H, 0, self.pin_data)
        return self._batch_centres(H)[0], np.array(self.pin_data.J).reshape(6, self.nv), maps

    def quantities_within(self, q, v, u, distance, *, derivatives=True, damping=None, springs=None):
        """As the base class; with quaternion floating joints, one kinematics pass serves the
        distances and the quantities."""
        if self.affine is not None or self._coords is None:  # distances, then the batched pass
            return super().quantities_within(
                q, v, u, distance, derivatives=derivatives, damping=damping, springs=springs
            )
        kinematics = self._kinematics(np.asarray(q[0], float))
        phi = kinematics[0] @ self.normal - self._radius - self.ground.height
        active = np.flatnonzero(phi <= distance)
        quant = self.quantities(
            q, v, u, active, derivatives=derivatives, kinematics=kinematics, damping=damping,
            springs=springs,
        )  # fmt: skip
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
        if self._coords is not None:
            return self._one_free(q, v, u, active, derivatives, kinematics or self._kinematics(q))
        # revolute, prismatic and weld joints: the batched pass, for one state
        v, u = np.asarray(v, float)[None], np.asarray(u, float)[None]
        quant = self._batch_quantities(q[None], v, u, active, derivatives, None)
        out = {k: getattr(quant, k)[0] for k in ("W", "v_free", "N", "phi", "Jn", "Jt")}
        if derivatives:
            out.update({k: getattr(quant, k)[0] for k in ("dv_free", "dphi", "dJn", "dJt", "dN")})
            out["dW_times"] = lambda f: quant.dW_times(np.asarray(f, float)[None])[0]
        return out

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


def _contact_rows(
    centres, active, radius, n, height, tangents, friction, J, paths, ranks, derivatives
):  # fmt: skip
    """Rows of the active contacts (indices ``active``, na of them) of one state: ``phi`` (na,),
    ``Jn`` (na, nv), ``Jt`` (nt, nv) and, with ``derivatives``, ``dphi`` (na, nv), ``dJn`` (na,
    nv, nv), ``dJt`` (nt, nv, nv); centres (nc, 3), J (6, nv). :func:`_contact_rows_batch` with
    a batch of one."""
    out = _contact_rows_batch(
        centres[None], active, radius, n, height, tangents, friction,
        np.ascontiguousarray(J)[None], paths, ranks, derivatives, J.shape[1],
    )  # fmt: skip
    return tuple(x[0] for x in out)


@nb.njit(cache=True)
def _points_in_world(H, slot, p_J):
    """X (B, nc, 3): X[b, c] = R p_J[c] + p with (R, p) = H[b, slot[c]] (B, nj, 4, 4)."""
    B, nc = H.shape[0], slot.size
    X = np.empty((B, nc, 3))
    for b in range(B):
        for c in range(nc):
            k = slot[c]
            for i in range(3):
                X[b, c, i] = (
                    H[b, k, i, 0] * p_J[c, 0] + H[b, k, i, 1] * p_J[c, 1]
                    + H[b, k, i, 2] * p_J[c, 2] + H[b, k, i, 3]
                )  # fmt: skip
    return X


@nb.njit(cache=True)
def _contact_rows_batch(
    centres, active, radius, n, height, tangents, friction, J, paths, ranks, derivatives, width
):  # fmt: skip
    """Rows of the active contacts (indices ``active``, na of them) for B states: ``phi`` (B,
    na), ``Jn`` (B, na, nv), ``Jt`` (B, nt, nv) and, with ``derivatives``, ``dphi`` (B, na,
    width), ``dJn`` (B, na, nv, width), ``dJt`` (B, nt, nv, width), in pinocchio's velocities,
    derivatives with respect to its tangent increments (Drake's q and v for 1-dof joints):
    ``width`` >= nv columns, zero past the first nv (the batched pass asks for nq = nv, the q
    columns of a model with qdot = v).

    Per state: centres (B, nc, 3) every candidate's centre in the world (the witness point is
    ``Q = C - radius n``) and J (B, 6, nv) the world-frame joint Jacobians (linear rows first)
    of all joints. Per candidate: radius (nc,), friction (nc,) whether it has friction, paths
    (nc, nv) the velocity indices on its body's path from the world (root first, -1 padded),
    ranks (nc, nv) the rank on that path of the joint each index belongs to. The body joint's
    Jacobian is J restricted to its path's columns, so a point p fixed on the body moves with
    ``J_p = Jv - [p]x Jw``.

    Derivative of J_Q = Jv - [Q]x Jw: a column S_j moves with an increment along column S_k of
    its own joint or of a joint before it on the path (pinocchio moves a joint's frame by
    ``X exp(d)``: every motion after it is carried along): ``dS_j/dk = S_k x S_j`` (spatial
    cross product), so ``dJv_j/dk = w_k x v_j + v_k x w_j`` and ``dJw_j/dk = w_k x w_j``; then
    ``dJ_Q[:, j, k] = dJv_j/dk - Q x dJw_j/dk - (J_C[:, k]) x Jw[:, j]``, with J_C the
    Jacobian of the body-fixed point C. No array is allocated per state or contact.
    """
    B = centres.shape[0]
    na = active.shape[0]
    nv = J.shape[2]
    k = tangents.shape[0]
    nt = 0
    for a in active:
        if friction[a]:
            nt += k
    phi = np.empty((B, na))
    Jn = np.zeros((B, na, nv))
    Jt = np.zeros((B, nt, nv))
    m = nv if derivatives else 0
    w = width if derivatives else 0
    dphi = np.zeros((B, na, w))
    dJn = np.zeros((B, na, m, w))
    dJt = np.zeros((B, nt, m, w))
    J_Q = np.empty((3, nv))
    J_C = np.empty((3, nv))
    d = np.empty(3)
    for s in range(B):
        row_t = 0
        for i in range(na):
            c = active[i]
            C0, C1, C2 = centres[s, c, 0], centres[s, c, 1], centres[s, c, 2]
            r = radius[c]
            Q0, Q1, Q2 = C0 - r * n[0], C1 - r * n[1], C2 - r * n[2]
            phi[s, i] = n[0] * C0 + n[1] * C1 + n[2] * C2 - r - height
            count = 0
            while count < nv and paths[c, count] >= 0:
                count += 1
            J_Q[:] = 0.0
            J_C[:] = 0.0
            for p in range(count):
                j = paths[c, p]
                v0, v1, v2 = J[s, 0, j], J[s, 1, j], J[s, 2, j]
                w0, w1, w2 = J[s, 3, j], J[s, 4, j], J[s, 5, j]
                J_Q[0, j] = v0 - (Q1 * w2 - Q2 * w1)
                J_Q[1, j] = v1 - (Q2 * w0 - Q0 * w2)
                J_Q[2, j] = v2 - (Q0 * w1 - Q1 * w0)
                J_C[0, j] = v0 - (C1 * w2 - C2 * w1)
                J_C[1, j] = v1 - (C2 * w0 - C0 * w2)
                J_C[2, j] = v2 - (C0 * w1 - C1 * w0)
            for j in range(nv):
                Jn[s, i, j] = n[0] * J_Q[0, j] + n[1] * J_Q[1, j] + n[2] * J_Q[2, j]
                if derivatives:
                    dphi[s, i, j] = n[0] * J_C[0, j] + n[1] * J_C[1, j] + n[2] * J_C[2, j]
            if friction[c]:
                for t in range(k):
                    for j in range(nv):
                        Jt[s, row_t + t, j] = (
                            tangents[t, 0] * J_Q[0, j]
                            + tangents[t, 1] * J_Q[1, j]
                            + tangents[t, 2] * J_Q[2, j]
                        )
            if derivatives:
                for a in range(count):
                    kk = paths[c, a]
                    wk0, wk1, wk2 = J[s, 3, kk], J[s, 4, kk], J[s, 5, kk]
                    vk0, vk1, vk2 = J[s, 0, kk], J[s, 1, kk], J[s, 2, kk]
                    for b in range(count):
                        j = paths[c, b]
                        vj0, vj1, vj2 = J[s, 0, j], J[s, 1, j], J[s, 2, j]
                        wj0, wj1, wj2 = J[s, 3, j], J[s, 4, j], J[s, 5, j]
                        d[:] = 0.0
                        if ranks[c, b] >= ranks[c, a]:
                            # w_k x v_j + v_k x w_j - Q x (w_k x w_j)
                            x0 = wk1 * wj2 - wk2 * wj1
                            x1 = wk2 * wj0 - wk0 * wj2
                            x2 = wk0 * wj1 - wk1 * wj0
                            d[0] = (
                                (wk1 * vj2 - wk2 * vj1)
                                + (vk1 * wj2 - vk2 * wj1)
                                - (Q1 * x2 - Q2 * x1)
                            )
                            d[1] = (
                                (wk2 * vj0 - wk0 * vj2)
                                + (vk2 * wj0 - vk0 * wj2)
                                - (Q2 * x0 - Q0 * x2)
                            )
                            d[2] = (
                                (wk0 * vj1 - wk1 * vj0)
                                + (vk0 * wj1 - vk1 * wj0)
                                - (Q0 * x1 - Q1 * x0)
                            )
                        # - J_C[:, k] x Jw[:, j]
                        c0, c1, c2 = J_C[0, kk], J_C[1, kk], J_C[2, kk]
                        d[0] -= c1 * wj2 - c2 * wj1
                        d[1] -= c2 * wj0 - c0 * wj2
                        d[2] -= c0 * wj1 - c1 * wj0
                        dJn[s, i, j, kk] = n[0] * d[0] + n[1] * d[1] + n[2] * d[2]
                        if friction[c]:
                            for t in range(k):
                                dJt[s, row_t + t, j, kk] = (
                                    tangents[t, 0] * d[0]
                                    + tangents[t, 1] * d[1]
                                    + tangents[t, 2] * d[2]
                                )
            if friction[c]:
                row_t += k
    return phi, Jn, Jt, dphi, dJn, dJt
