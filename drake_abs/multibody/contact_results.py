"""A step's contacts as Drake's point-pair contact information: what
:class:`drake_abs.systems.ComplementarityPlant` reports on its ``contact_results`` port.

Drake's ``ContactResults`` cannot be filled from Python: pydrake (1.58) binds only its empty
constructor (its point-pair list is set by MultibodyPlant's C++ code alone), so Drake's
``ContactVisualizer``, which reads a ``ContactResults`` port, cannot draw a contact that Python
computed. :class:`PointContactResults` holds Drake's own ``PointPairContactInfo`` records, one
per contact the step pushed on, behind the reading interface of ``ContactResults``
(``num_point_pair_contacts()``, ``point_pair_contact_info(i)``, ``plant()``), so code that
reads a MultibodyPlant's contact results reads these unchanged;
:class:`drake_abs.systems.ContactForceVisualizer` draws them in Meshcat as ContactVisualizer
draws point contacts.

The numbers are the step's own, over the step [t, t + h] that starts at the Context's state
(the step the next update applies), as Drake's discrete MultibodyPlant reports its contacts:

- a contact is listed when its normal impulse is positive (a candidate left out of the step's
  LCP, beyond the activation distance, has none). Under the interior-point solve a separated
  candidate inside the LCP keeps a vanishing impulse (about 1e-20 N s) and is listed too, with
  its separation (``point_pair.depth < 0``) and a force far below any visualizer's threshold;
- ``contact_force()`` (``f_Bc_W``, N) is the force on body B: the step's normal and friction
  impulses divided by the time step h, the mean force over the step;
- ``contact_point()`` (``p_WC``, m) is the midpoint of the two witness points at the step's
  start configuration q;
- ``separation_speed()`` and ``slip_speed()`` (m/s) are the normal and tangential speeds of
  body B's witness point relative to body A's at q and the step's next velocity v+ (the
  velocity the complementarity conditions hold at): positive separation speed is apart;
- ``point_pair()`` is a ``PenetrationAsPointPair``: ``p_WCa``, ``p_WCb`` the witness points on
  A and B, ``nhat_BA_W`` the unit normal pointing from B into A, ``depth`` = -(signed
  distance) (m; negative while the bodies are apart), and the SceneGraph geometry ids of the
  ground and of the contact sphere where the plant registered them (the plant's
  ``geometry_pose``, from
  :func:`~drake_abs.diagrams.scene_plant.AddComplementarityPlantSceneGraph`), else Drake's
  default (invalid) id.

Body A is the world (the ground) for a point candidate, the pair's ``a`` body for a body-body
pair; body B the candidate's body, the pair's ``b`` body. Values are doubles (under AutoDiffXd
too: the derivatives are on the ``impulse`` port).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import GeometryId, PenetrationAsPointPair
from pydrake.multibody.plant import MultibodyPlant, PointPairContactInfo
from pydrake.multibody.tree import JacobianWrtVariable

from drake_abs.multibody.drake_dynamics import ContactModelBase, PointContact
from drake_abs.multibody.geometry_contacts import PairContact, pair_geometry


@dataclass(frozen=True)
class PointContactResults:
    """The contacts of one step, with the reading interface of Drake's ``ContactResults``
    (point pairs only: no hydroelastic or deformable contact). See the module docstring for
    what each record holds.

    Attributes:
        infos: one ``PointPairContactInfo`` per listed contact.
        candidates: the stepper's contact candidate index of each (``stepper.model.contacts``,
            the columns of the ``impulse`` port).
        source_plant: the MultibodyPlant whose body indices the records use, or None.
    """

    infos: tuple[PointPairContactInfo, ...] = ()
    candidates: tuple[int, ...] = ()
    source_plant: MultibodyPlant | None = None

    def num_point_pair_contacts(self) -> int:
        """The number of listed contacts."""
        return len(self.infos)

    def point_pair_contact_info(self, i: int) -> PointPairContactInfo:
        """The i-th contact's record; ``IndexError`` outside ``[0, num_point_pair_contacts())``
        (Drake raises too)."""
        n = len(self.infos)
        if not isinstance(i, int | np.integer) or not 0 <= i < n:
            raise IndexError(f"point_pair_contact_info: i must be in [0, {n}); got {i!r}")
        return self.infos[int(i)]

    def num_hydroelastic_contacts(self) -> int:
        """0: the step has point contacts only."""
        return 0

    def num_deformable_contacts(self) -> int:
        """0: the step has point contacts only."""
        return 0

    def plant(self) -> MultibodyPlant | None:
        """The plant the body indices refer to (``ContactResults.plant()``)."""
        return self.source_plant

    def candidate(self, i: int) -> int:
        """The contact candidate index of the i-th listed contact."""
        self.point_pair_contact_info(i)  # the index check
        return self.candidates[int(i)]


def _body(plant: MultibodyPlant, name: str, model: str | None):
    instance = plant.GetModelInstanceByName(model) if model else None
    return (
        plant.GetBodyByName(name, instance) if instance is not None else plant.GetBodyByName(name)
    )


def point_contact_results(
    model: ContactModelBase,
    q: np.ndarray,
    v_next: np.ndarray,
    impulse: np.ndarray,
    friction_impulse: np.ndarray | None,
    *,
    context=None,
    geometry_ids: Sequence[tuple[GeometryId | None, GeometryId | None]] | None = None,
    plant: MultibodyPlant | None = None,
) -> PointContactResults:
    """The contacts of one step of ``model`` (see the module docstring).

    Args:
        model: the step's contact model (``stepper.model``: its candidates, ground, h).
        q: the positions at the step's start (nq,).
        v_next: the step's next velocities (nv,) (m/s, rad/s).
        impulse: the normal impulse of every candidate (nc,) (N s).
        friction_impulse: the step's tangential impulse of every candidate (nc, 3) (N s, world
            frame, as ``Step.friction_impulse``), or None for none.
        context: a Context of ``model.plant`` to evaluate the kinematics in (set here; a new
            one by default).
        geometry_ids: per candidate, the SceneGraph ids ``(id_A, id_B)`` of its two geometries
            (None where not registered); default: none.
        plant: the plant reported by :meth:`PointContactResults.plant` (default
            ``model.plant``; one with the same bodies, e.g. the one registered with the
            SceneGraph).
    """
    mbp = model.plant
    nc = len(model.contacts)
    q = np.asarray(q, dtype=float)
    v_next = np.asarray(v_next, dtype=float)
    impulse = np.asarray(impulse, dtype=float)
    if q.shape != (model.nq,) or v_next.shape != (model.nv,) or impulse.shape != (nc,):
        raise ValueError(
            f"q, v_next and impulse must have shapes ({model.nq},), ({model.nv},) and ({nc},); "
            f"got {q.shape}, {v_next.shape} and {impulse.shape}"
        )
    friction = np.zeros((nc, 3)) if friction_impulse is None else np.asarray(friction_impulse)
    if friction.shape != (nc, 3):
        raise ValueError(f"friction_impulse must have shape ({nc}, 3); got {friction.shape}")
    listed = np.flatnonzero(impulse > 0.0)
    plant = mbp if plant is None else plant
    if not listed.size:
        return PointContactResults((), (), plant)
    ctx = mbp.CreateDefaultContext() if context is None else context
    mbp.SetPositions(ctx, q)
    world = mbp.world_frame()
    h = model.h

    def velocity(body, p_W):  # of the point of ``body`` at p_W (world), at v+
        p_B = mbp.EvalBodyPoseInWorld(ctx, body).inverse().multiply(p_W)
        J = mbp.CalcJacobianTranslationalVelocity(
            ctx, JacobianWrtVariable.kV, body.body_frame(), p_B, world, world
        )
        return J @ v_next

    infos = []
    for i in listed:
        contact = model.contacts[i]
        if isinstance(contact, PairContact):
            A = _body(mbp, contact.body_a, contact.model_a)
            B = _body(mbp, contact.body_b, contact.model_b)
            X_A = mbp.EvalBodyPoseInWorld(ctx, A)
            X_B = mbp.EvalBodyPoseInWorld(ctx, B)
            phi, n, p_A, p_B = pair_geometry(
                contact,
                X_A.rotation().matrix(),
                X_A.translation(),
                X_B.rotation().matrix(),
                X_B.translation(),
            )
            n, p_A, p_B = (np.asarray(a, dtype=float) for a in (n, p_A, p_B))
            # the rows are n . (v_A - v_B): the impulses act on A, their opposite on B
            on_a = impulse[i] * n + friction[i]  # the step's friction is on A, in the world
            f_B = -on_a / h
            relative = velocity(B, p_B) - velocity(A, p_A)
            nhat_BA = n
        else:
            assert isinstance(contact, PointContact)
            A = mbp.world_body()
            B = _body(mbp, contact.body, contact.model_instance)
            n = model.normal
            centre = mbp.EvalBodyPoseInWorld(ctx, B).multiply(np.asarray(contact.p_BC, float))
            phi = float(n @ centre - contact.radius - model.ground.height)
            p_B = centre - contact.radius * n  # the witness point on the body
            p_A = p_B - phi * n  # its projection on the ground
            f_B = (impulse[i] * n + friction[i]) / h
            relative = velocity(B, p_B)
            nhat_BA = -n  # from the body into the ground
        separation = float(-(nhat_BA @ relative))
        slip = float(np.linalg.norm(relative + separation * nhat_BA))
        ids = {}
        if geometry_ids is not None:
            id_a, id_b = geometry_ids[i]
            ids = {k: g for k, g in (("id_A", id_a), ("id_B", id_b)) if g is not None}
        pair = PenetrationAsPointPair(
            p_WCa=p_A, p_WCb=p_B, nhat_BA_W=nhat_BA, depth=-float(phi), **ids
        )
        infos.append(
            PointPairContactInfo(
                A.index(), B.index(), f_B, 0.5 * (p_A + p_B), separation, slip, pair
            )
        )
    return PointContactResults(tuple(infos), tuple(int(i) for i in listed), plant)
