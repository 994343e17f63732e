"""One step's dynamics quantities of a Drake MultibodyPlant with point contacts against a plane,
with their derivatives, for the complementarity step of :mod:`drake_abs.contact.contact_lcp`.

Values and derivatives come from one AutoDiffXd evaluation of the plant per state, seeded with
the identity on p = (q, v, u): M(q), the bias and gravity terms, the actuation, the contact
points' signed distances and translational Jacobians, and qdot = N(q) v. Geometry is computed
here (a point, with an optional radius, against a half-space; or a body-body pair of collision
shapes in closed form, :mod:`drake_abs.multibody.geometry_contacts`), not by SceneGraph, so only
the contacts a scene declares exist (and AutoDiffXd distance queries are not needed).
"""

from __future__ import annotations

import functools
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.multibody.plant import MultibodyPlant, MultibodyPlant_
from pydrake.multibody.tree import (
    BodyIndex,
    JacobianWrtVariable,
    SpatialInertia,
    SpatialInertia_,
    UnitInertia_,
)

from drake_abs.contact.cone import FrictionCone
from drake_abs.contact.damping import JointSprings, implicit_damping
from drake_abs.contact.step_data import StepQuantities
from drake_abs.multibody.affine_dynamics import AffineDynamics
from drake_abs.multibody.floating import quaternion_starts
from drake_abs.multibody.geometry_contacts import PairContact, pair_geometry, pair_tangents


@dataclass(frozen=True)
class PointContact:
    """A contact candidate: point ``p_BC`` (m, body frame) of ``body``, with ``radius`` (m; a
    sphere around the point, 0 for a point), against the ground plane; ``friction`` is the
    Coulomb coefficient (None: frictionless)."""

    body: str
    p_BC: tuple[float, float, float]
    radius: float = 0.0
    friction: float | None = None
    model_instance: str | None = None


@dataclass(frozen=True)
class GroundPlane:
    """The half-space ``n . p >= height`` (n normalised)."""

    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    height: float = 0.0


def tangent_directions(normal: np.ndarray, k: int) -> np.ndarray:
    """k unit directions (k, 3) spanning the plane orthogonal to ``normal``, evenly spread."""
    n = normal / np.linalg.norm(normal)
    seed = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = seed - n * (seed @ n)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    angles = 2 * np.pi * np.arange(k) / k
    return np.cos(angles)[:, None] * t1 + np.sin(angles)[:, None] * t2


def _pose(plant, ctx, body):
    """(R_WB (3, 3), p_WB (3,)) of ``body``, in the plant's scalar type."""
    X = plant.EvalBodyPoseInWorld(ctx, body)
    return X.rotation().matrix(), X.translation()


#: the entries of a unit inertia in the order of its parameters (``unit_inertia[body].xx`` ...):
#: the moments, then the products (entries of the symmetric 3 x 3 matrix, Drake's convention)
INERTIA_ENTRIES = ("xx", "yy", "zz", "xy", "xz", "yz")
#: their (row, column) in the 3 x 3 matrix
INERTIA_INDEX = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def central_unit_inertia(M) -> np.ndarray:
    """The unit rotational inertia about the centre of mass (m^2, 3 x 3, in the body frame) of a
    spatial inertia ``M`` about the body origin (Drake's ``SpatialInertia``, double)."""
    return np.asarray(M.Shift(M.get_com()).get_unit_inertia().CopyToFullMatrix3())


def spatial_inertia(mass: float, com, unit_inertia) -> SpatialInertia:
    """The spatial inertia about the body origin, in the body frame, of a body of ``mass`` (kg)
    whose centre of mass is at ``com`` (m, body frame) and whose unit rotational inertia about
    the centre of mass is ``unit_inertia`` (m^2; 3 x 3, or the six entries of
    :data:`INERTIA_ENTRIES`). Its physical validity is checked (``RuntimeError`` otherwise)."""
    G = np.asarray(unit_inertia, float)
    if G.shape == (6,):
        G = _full_matrix(G)
    c = np.asarray(com, float).reshape(3)
    G_Bo = G + (c @ c) * np.eye(3) - np.outer(c, c)  # shifted from the centre of mass to Bo
    return SpatialInertia(float(mass), c, _unit_inertia(UnitInertia_[float], G_Bo, float))


def _full_matrix(entries) -> np.ndarray:
    """The symmetric 3 x 3 matrix of six entries in :data:`INERTIA_ENTRIES` order (any type)."""
    G = np.empty((3, 3), dtype=np.asarray(entries).dtype)
    for value, (i, j) in zip(entries, INERTIA_INDEX, strict=True):
        G[i, j] = G[j, i] = value
    return G


def _unit_inertia(kind, G, scalar):
    """A UnitInertia of type ``kind`` with the entries of the symmetric matrix G (converted to
    ``scalar`` where they are not of that type already)."""
    return kind(*(
        G[i, j] if isinstance(G[i, j], scalar) else scalar(float(G[i, j])) for i, j in INERTIA_INDEX
    ))  # fmt: skip


def _to_autodiff(M) -> SpatialInertia_[AutoDiffXd]:
    """A double SpatialInertia as an AutoDiffXd one (no derivatives)."""
    G = np.asarray(M.get_unit_inertia().CopyToFullMatrix3())
    return SpatialInertia_[AutoDiffXd](
        AutoDiffXd(M.get_mass()),
        np.array([AutoDiffXd(x) for x in np.asarray(M.get_com())]),
        _unit_inertia(UnitInertia_[AutoDiffXd], G, AutoDiffXd),
        True,
    )


def _split(arr: np.ndarray, P: int) -> tuple[np.ndarray, np.ndarray]:
    """Value (shape of arr) and gradient (shape + (P,)) of an AutoDiffXd array."""
    flat = np.asarray(arr, dtype=object).ravel()
    value = ExtractValue(flat).reshape(arr.shape)
    grad = ExtractGradient(flat)
    if grad.shape[1] != P:  # entries that carry no derivatives (constants)
        grad = np.zeros((flat.size, P))
    return value, grad.reshape(arr.shape + (P,))


def apply_spatial_inertias(plant, context, inertias: Mapping[int, SpatialInertia]) -> None:
    """Set each body's spatial inertia ``{body index: SpatialInertia (double, about the body
    origin, in the body frame)}`` on ``context`` of ``plant`` (double or AutoDiffXd)."""
    autodiff = isinstance(plant, MultibodyPlant_[AutoDiffXd])
    for index, M in inertias.items():
        body = plant.get_body(BodyIndex(int(index)))
        body.SetSpatialInertiaInBodyFrame(context, _to_autodiff(M) if autodiff else M)


def _checked_inertias(plant, inertias) -> dict[int, SpatialInertia]:
    """``spatial_inertias`` checked: ``{body index: SpatialInertia}`` of the plant's bodies (not
    the world), each physically valid."""
    out: dict[int, SpatialInertia] = {}
    if inertias is None:
        return out
    if not isinstance(inertias, Mapping):
        raise ValueError(
            "spatial_inertias must be a mapping {body index: SpatialInertia}; got "
            f"{type(inertias).__name__}"
        )
    world = int(plant.world_body().index())
    for index, M in inertias.items():
        i = int(index)
        if not 0 <= i < plant.num_bodies() or i == world:
            raise ValueError(
                f"spatial_inertias: {index!r} is not the index of one of the plant's bodies "
                f"(1 to {plant.num_bodies() - 1}; 0 is the world)"
            )
        if not isinstance(M, SpatialInertia) or not M.IsPhysicallyValid():
            raise ValueError(
                f"spatial_inertias[{i}] must be a physically valid SpatialInertia (about the "
                f"body origin, in the body frame); got {M!r}"
            )
        out[i] = M
    return out


class ContactModelBase(ABC):
    """What every provider of step quantities shares: the plant's sizes and actuation matrix,
    the contact candidates, the ground, h and the friction cone.

    Args:
        plant: a finalized MultibodyPlant (time_step 0: the step is ours), double.
        contacts: the contact candidates: points against the ground (:class:`PointContact`), or
            body-body pairs (:class:`~drake_abs.multibody.geometry_contacts.PairContact`, which
            only :class:`MultibodyContactModel` evaluates).
        ground: the plane contacts act against.
        time_step: h in s.
        directions: tangent directions per frictional contact (linearised cone).
        spatial_inertias: bodies whose inertia differs from the plant's defaults (a finalized
            plant's default masses cannot be changed), ``{body index: SpatialInertia}``: each
            body's spatial inertia about its origin, expressed in its frame (Drake's
            ``M_BBo_B``, double). They are set (``SetSpatialInertiaInBodyFrame``) on every
            context the provider evaluates the plant in, and read by
            :meth:`body_spatial_inertia`; see :meth:`rebuilt`.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        contacts: list[PointContact | PairContact],
        ground: GroundPlane,
        time_step: float,
        directions: int = 4,
        *,
        spatial_inertias: Mapping[int, SpatialInertia] | None = None,
    ):
        if not plant.is_finalized():
            raise ValueError("plant must be finalized")
        if not contacts:
            raise ValueError("contacts must list at least one PointContact or PairContact")
        self.plant = plant
        #: ``{body index (int): SpatialInertia}``: the bodies' inertias that replace the plant's
        #: defaults (see the constructor)
        self.spatial_inertias = _checked_inertias(plant, spatial_inertias)
        self.contacts = list(contacts)
        self.ground = ground
        self.h = float(time_step)
        self.normal = np.asarray(ground.normal, float) / np.linalg.norm(ground.normal)
        friction = [np.nan if c.friction is None else c.friction for c in contacts]
        self.cone = FrictionCone(np.array(friction), directions)
        self.tangents = tangent_directions(self.normal, self.cone.directions)
        self._cones: dict[tuple[int, ...], FrictionCone] = {}
        self.B_act = plant.MakeActuationMatrix()
        self.nq, self.nv, self.nu = (
            plant.num_positions(),
            plant.num_velocities(),
            plant.num_actuators(),
        )
        #: where each free body's unit quaternion (qw, qx, qy, qz) starts in q; the stepper
        #: keeps these at unit norm (see :mod:`drake_abs.multibody.floating`)
        self.quaternion_starts = quaternion_starts(plant)

        def body_of(name, model):
            instance = plant.GetModelInstanceByName(model) if model else None
            return plant.GetBodyByName(name, instance) if instance else plant.GetBodyByName(name)

        self._bodies_d = []  # per candidate: its body (a pair: body A)
        self._pair_bodies_d = {}  # per pair candidate's index: (body A, body B)
        for i, c in enumerate(contacts):
            if isinstance(c, PairContact):
                self._pair_bodies_d[i] = (
                    body_of(c.body_a, c.model_a),
                    body_of(c.body_b, c.model_b),
                )
                self._bodies_d.append(self._pair_bodies_d[i][0])
            else:
                self._bodies_d.append(body_of(c.body, c.model_instance))
        self.affine = None  # set below, once the provider can evaluate its quantities
        self._setup()
        #: the affine quantities of a plant with prismatic joints only (None otherwise, or when
        #: set to None by hand to force the general path): see multibody/affine_dynamics.py.
        #: A pair's distance is not affine in q (its normal turns), so pairs rule it out.
        self.affine = None if self._pair_bodies_d else AffineDynamics.of(self)

    @abstractmethod
    def _setup(self) -> None:
        """Provider-specific set-up, after the shared attributes exist."""

    def rebuilt(
        self,
        *,
        contacts: list[PointContact | PairContact] | None = None,
        ground: GroundPlane | None = None,
        spatial_inertias: Mapping[int, SpatialInertia] | None = None,
    ) -> ContactModelBase:
        """A provider of the same kind on the same plant (no model file is read again) with
        other contact candidates, ground or body inertias (``spatial_inertias`` replaces this
        provider's overrides; None keeps them); the time step and the cone's directions are
        kept."""
        if spatial_inertias is None:
            spatial_inertias = self.spatial_inertias
        return type(self)(
            self.plant,
            self.contacts if contacts is None else contacts,
            self.ground if ground is None else ground,
            self.h,
            self.cone.directions,
            spatial_inertias=spatial_inertias,
        )

    def new_context(self, plant=None):
        """A default context of ``plant`` (this provider's double plant by default, or its
        AutoDiffXd copy) with :attr:`spatial_inertias` set on it."""
        plant = self.plant if plant is None else plant
        ctx = plant.CreateDefaultContext()
        apply_spatial_inertias(plant, ctx, self.spatial_inertias)
        return ctx

    def body_spatial_inertia(self, index) -> SpatialInertia:
        """The spatial inertia about its origin, in its frame, of the body ``index`` in this
        provider's dynamics (its override, or the plant's default)."""
        found = self.spatial_inertias.get(int(index))
        if found is not None:
            return found
        return self.plant.get_body(BodyIndex(int(index))).default_spatial_inertia()

    @functools.cached_property
    def massive_bodies(self) -> tuple[str, ...]:
        """Names of the plant's bodies with a positive mass (the mass parameters of
        :meth:`mass_derivatives`; massless helper bodies, such as a floating base's chain, are
        left out). A body name that occurs in several model instances is qualified as
        ``"instance::body"``, so that every parameter has its own name."""
        return tuple(name for name, _ in self._massive)

    @functools.cached_property
    def _massive(self) -> tuple[tuple[str, BodyIndex], ...]:
        """``(name, body index)`` of each body with a positive mass (see massive_bodies)."""
        plant = self.plant
        bodies = [
            plant.get_body(BodyIndex(i))
            for i in range(plant.num_bodies())
            if i != int(plant.world_body().index())
        ]
        bodies = [b for b in bodies if self.body_spatial_inertia(b.index()).get_mass() > 0.0]
        counts: dict[str, int] = {}
        for b in bodies:
            counts[b.name()] = counts.get(b.name(), 0) + 1
        return tuple(
            (
                b.name()
                if counts[b.name()] == 1
                else f"{plant.GetModelInstanceName(b.model_instance())}::{b.name()}",
                b.index(),
            )
            for b in bodies
        )

    @functools.cached_property
    def _inertia_seeded(self):
        """An AutoDiffXd copy of the plant and a context whose massive bodies' inertias carry
        the derivatives of :meth:`inertial_derivatives` (7 per body: its mass, then its unit
        inertia about the centre of mass, :data:`INERTIA_ENTRIES`); built once."""
        plant = getattr(self, "plant_ad", None) or self.plant.ToAutoDiffXd()  # (its own context)
        ctx = self.new_context(plant)
        nb = len(self._massive)
        seeds = np.eye(7 * nb)
        for k, (_, index) in enumerate(self._massive):
            M = self.body_spatial_inertia(index)
            c = np.asarray(M.get_com())
            mass = AutoDiffXd(M.get_mass(), seeds[k])
            G_cm = central_unit_inertia(M)
            G = _full_matrix(np.array([  # about the centre of mass, seeded
                AutoDiffXd(G_cm[i, j], seeds[nb + 6 * k + e])
                for e, (i, j) in enumerate(INERTIA_INDEX)
            ]))  # fmt: skip
            G_Bo = G + ((c @ c) * np.eye(3) - np.outer(c, c))  # shifted to Bo (c held)
            seeded = SpatialInertia_[AutoDiffXd](
                mass, np.array([AutoDiffXd(x) for x in c]),
                _unit_inertia(UnitInertia_[AutoDiffXd], G_Bo, AutoDiffXd), True,
            )  # fmt: skip
            plant.get_body(index).SetSpatialInertiaInBodyFrame(ctx, seeded)
        return plant, ctx

    def inertial_derivatives(
        self, q: np.ndarray, v: np.ndarray, u: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(dW, dv_free)``: the derivatives of W = M^-1 (B, nv, nv, T) and of the free velocity
        (B, nv, T) with respect to the inertias of :attr:`massive_bodies`, at the states q
        (B, nq), v (B, nv) and inputs u (B, nu), T = 7 nb columns: first every body's mass (kg;
        its centre of mass and unit inertia held, as ``RigidBody.SetMass`` does, so its
        rotational inertia scales with it), then per body the six entries of its unit
        rotational inertia about its centre of mass in its frame (m^2, :data:`INERTIA_ENTRIES`;
        a product entry moves both symmetric entries; mass and centre of mass held). Evaluated
        through an AutoDiffXd copy of the plant, whatever the provider; contacts do not depend
        on the inertias."""
        plant, ctx = self._inertia_seeded
        T = 7 * len(self.massive_bodies)
        B, nv = v.shape
        dW = np.zeros((B, nv, nv, T))
        dv_free = np.zeros((B, nv, T))
        for b in range(B):
            plant.SetPositions(ctx, np.array([AutoDiffXd(x) for x in q[b]]))
            plant.SetVelocities(ctx, np.array([AutoDiffXd(x) for x in v[b]]))
            M, dM = _split(plant.CalcMassMatrix(ctx), T)
            tau_ad = plant.CalcGravityGeneralizedForces(ctx) - plant.CalcBiasTerm(ctx)
            tau, dtau = _split(tau_ad, T)
            tau = tau + self.B_act @ u[b]  # the actuation does not depend on the inertias
            W = np.linalg.inv(M)
            dW[b] = -np.moveaxis(W @ np.moveaxis(dM, -1, 0) @ W, 0, -1)
            dv_free[b] = self.h * (np.einsum("ijt,j->it", dW[b], tau) + W @ dtau)
        return dW, dv_free

    def mass_derivatives(
        self, q: np.ndarray, v: np.ndarray, u: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The mass columns of :meth:`inertial_derivatives` (its first nb): ``dW`` (B, nv, nv,
        nb) and ``dv_free`` (B, nv, nb), each body's mass scaled with its centre of mass and unit
        inertia held."""
        nb = len(self.massive_bodies)
        dW, dv_free = self.inertial_derivatives(q, v, u)
        return dW[..., :nb], dv_free[..., :nb]

    @functools.cached_property
    def point_contacts(self) -> np.ndarray:
        """Indices of the candidates that are points (or spheres) against the ground
        (:class:`PointContact`), whose radius and offset ``p_BC`` are model parameters (see
        :meth:`point_parameter_derivatives`)."""
        return np.array(
            [i for i, c in enumerate(self.contacts) if isinstance(c, PointContact)], dtype=np.int64
        )

    @functools.cached_property
    def _geometry_context(self):
        """A double context of the plant of its own (for :meth:`point_parameter_derivatives`)."""
        return self.new_context()

    def point_parameter_derivatives(
        self, q: np.ndarray, active: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Derivatives of the rows of the candidates ``active`` (na indices) at the positions q
        (B, nq) with respect to each point candidate's own geometry, four columns per candidate:
        its radius r (m), then its offset ``p_BC = (x, y, z)`` (m, body frame).

        With the body's orientation R and world-frame angular-velocity Jacobian Jw (3, nv; in
        this plant's v, whatever the provider), the distance ``phi = n . (p_WB + R p_BC) - r -
        height`` and the witness point ``Q = C - r n`` (on the body) give

            dphi/dr = -1,                 d J_Q / dr = [n]x Jw            (so dJn/dr = 0),
            dphi/dp_a = n . R e_a,        d J_Q / dp_a = -[R e_a]x Jw,

        all constant in (r, p_BC): the rows are affine in a candidate's geometry. Returns
        ``dphi`` (B, na, 4) (m/m), ``dJn`` (B, na, nv, 4) and ``dJt`` (B, nt, nv, 4) (the rows'
        units per m), in the row layout of :meth:`quantities` (k tangent rows per frictional
        candidate, in ``active`` order); each row depends on its own candidate only. Pair
        candidates' rows are 0."""
        q = np.asarray(q, dtype=float)
        active = np.asarray(active, dtype=np.int64)
        B, na, nv = len(q), active.size, self.nv
        k = self.cone.directions
        frictional = ~np.isnan(self.cone.coefficients[active])
        nt = int(frictional.sum()) * k
        dphi = np.zeros((B, na, 4))
        dJn = np.zeros((B, na, nv, 4))
        dJt = np.zeros((B, nt, nv, 4))
        plant, ctx, world = self.plant, self._geometry_context, self.plant.world_frame()
        n = self.normal
        points = [
            (i, local)
            for local, i in enumerate(active)
            if isinstance(self.contacts[i], PointContact)
        ]
        first_row = np.concatenate([[0], np.cumsum(frictional * k)])  # each one's first Jt row
        for b in range(B):
            plant.SetPositions(ctx, q[b])
            for i, local in points:
                body = self._bodies_d[i]
                R = plant.EvalBodyPoseInWorld(ctx, body).rotation().matrix()
                Jw = plant.CalcJacobianAngularVelocity(
                    ctx, JacobianWrtVariable.kV, body.body_frame(), world, world
                )
                dJ = np.empty((3, nv, 4))  # d J_Q / d(r, x, y, z), J_Q (3, nv)
                dJ[..., 0] = np.cross(n, Jw, axis=0)
                for a in range(3):
                    dJ[..., a + 1] = -np.cross(R[:, a], Jw, axis=0)
                dphi[b, local, 0] = -1.0
                dphi[b, local, 1:] = n @ R
                dJn[b, local] = np.einsum("i,inc->nc", n, dJ)
                if frictional[local]:
                    start = first_row[local]
                    dJt[b, start : start + k] = np.einsum("ti,inc->tnc", self.tangents, dJ)
        return dphi, dJn, dJt

    def cone_for(self, active: np.ndarray) -> FrictionCone:
        """The friction cone of a subset of the contacts (indices)."""
        active = np.asarray(active, dtype=np.int64)
        key = active.tobytes()
        cone = self._cones.get(key)
        if cone is None:
            cone = FrictionCone(self.cone.coefficients[active], self.cone.directions)
            self._cones[key] = cone
        return cone

    def quantities(
        self,
        q: np.ndarray,
        v: np.ndarray,
        u: np.ndarray,
        active: np.ndarray | None = None,
        *,
        derivatives: bool = True,
        kinematics=None,
        damping: np.ndarray | None = None,
        springs: JointSprings | None = None,
    ) -> StepQuantities:
        """Quantities for a batch: q (B, nq), v (B, nv), u (B, nu), for the contacts ``active``
        (indices; all by default), with derivatives with respect to p = (q, v, u) unless
        ``derivatives=False``. ``kinematics``: a provider's own kinematics of a one-state batch,
        already evaluated at q (see :meth:`quantities_within`). ``damping``: joint damping per
        velocity (nv,), and ``springs``: joint springs
        (:class:`~drake_abs.contact.damping.JointSprings`), both taken implicitly
        (:mod:`drake_abs.contact.damping`): the quantities of the damped step (W = (M + h D')^-1
        with ``D' = D + h K``, and its free velocity with the springs' torques)."""
        quant = self._quantities(q, v, u, active, derivatives, kinematics)
        if (damping is not None and np.any(damping)) or (springs is not None and springs.active):
            quant = implicit_damping(quant, damping, self.h, springs=springs)[0]
        return quant

    def _quantities(self, q, v, u, active, derivatives: bool, kinematics) -> StepQuantities:
        """The undamped quantities of :meth:`quantities`."""
        active = np.arange(len(self.contacts)) if active is None else np.asarray(active, int)
        if self.affine is not None and kinematics is None:  # one evaluation serves every state
            return self.affine.quantities(q, v, u, active, derivatives=derivatives)
        if kinematics is not None and len(q) != 1:
            raise ValueError(f"kinematics belong to one state; got a batch of {len(q)}")
        per_state = [
            self._one(qb, vb, ub, active, derivatives, kinematics)
            for qb, vb, ub in zip(q, v, u, strict=True)
        ]
        products = [s.pop("dW_times", None) for s in per_state]  # per-state functions of f
        if len(per_state) == 1:
            fields = {k: np.asarray(x)[None] for k, x in per_state[0].items()}
        else:
            fields = {k: np.stack([s[k] for s in per_state]) for k in per_state[0]}
        if products[0] is not None:
            fields["dW_times"] = lambda f: np.stack(
                [fn(fb) for fn, fb in zip(products, f, strict=True)]
            )
        return StepQuantities(q=np.asarray(q, float), v=np.asarray(v, float), **fields)

    def quantities_within(
        self, q: np.ndarray, v: np.ndarray, u: np.ndarray, distance: float, *,
        derivatives: bool = True, damping: np.ndarray | None = None,
        springs: JointSprings | None = None,
    ) -> tuple[np.ndarray, StepQuantities]:  # fmt: skip
        """For one state (q (1, nq), v (1, nv), u (1, nu)): the indices of the candidates within
        ``distance`` (m) and their quantities. Providers may share the kinematics between the
        two (pinocchio does); the result equals ``distances`` then ``quantities``."""
        active = np.flatnonzero(self.distances(q)[0] <= distance)
        return active, self.quantities(
            q, v, u, active, derivatives=derivatives, damping=damping, springs=springs
        )

    @abstractmethod
    def _one(self, q, v, u, active, derivatives: bool, kinematics=None) -> dict:
        """The quantities of one state (the fields of StepQuantities but q and v)."""

    def tangent_directions(self, q: np.ndarray, index: np.ndarray) -> np.ndarray:
        """The friction directions (B, n, k, 3) in the world of the candidates ``index`` (n,)
        at positions ``q`` (B, nq): the ground's ``tangents`` for a point candidate; for a
        pair candidate, those of its own contact normal at q (the directions of its ``Jt`` rows,
        :func:`~drake_abs.multibody.geometry_contacts.pair_tangents`)."""
        q = np.asarray(q, dtype=float)
        index = np.asarray(index, dtype=int).reshape(-1)
        out = np.broadcast_to(self.tangents, (len(q), index.size, *self.tangents.shape)).copy()
        pairs = [(j, int(i)) for j, i in enumerate(index) if int(i) in self._pair_bodies_d]
        if not pairs:
            return out
        plant = self.plant
        if getattr(self, "_directions_context", None) is None:
            self._directions_context = self.new_context()
        ctx = self._directions_context
        for b, qb in enumerate(q):
            plant.SetPositions(ctx, qb)
            for j, i in pairs:
                A, B = self._pair_bodies_d[i]
                n = pair_geometry(self.contacts[i], *_pose(plant, ctx, A), *_pose(plant, ctx, B))[1]
                out[b, j] = pair_tangents(np.asarray(n, dtype=float), self.tangents.shape[0])
        return out

    def distances(self, q: np.ndarray) -> np.ndarray:
        """Signed distances (B, nc) in m of every contact candidate, in double (affine in q, and
        evaluated so, for a plant with :attr:`affine` quantities)."""
        if self.affine is not None:
            return self.affine.distances(q)
        return self._distances(q)

    @abstractmethod
    def _distances(self, q: np.ndarray) -> np.ndarray:
        """The provider's signed distances (B, nc), by its kinematics."""


class MultibodyContactModel(ContactModelBase):
    """Evaluates :class:`~drake_abs.contact.step_data.StepQuantities` for a finalized continuous
    MultibodyPlant (double) and a list of point contacts against one ground plane, through the
    plant itself (AutoDiffXd for derivatives). Any joint type. Arguments as
    :class:`ContactModelBase`.
    """

    def _setup(self) -> None:
        plant = self.plant
        self.plant_ad = plant.ToAutoDiffXd()
        self.context_ad = self.new_context(self.plant_ad)
        self._bodies = [self.plant_ad.get_body(b.index()) for b in self._bodies_d]
        self._pair_bodies_ad = {
            i: tuple(self.plant_ad.get_body(b.index()) for b in pair)
            for i, pair in self._pair_bodies_d.items()
        }
        self._context = self.new_context()
        self._qdot_is_v = bool(plant.IsVelocityEqualToQDot())
        self._unit_v_d = list(np.eye(self.nv))
        self._unit_v = [
            np.array([AutoDiffXd(float(i == j)) for i in range(self.nv)]) for j in range(self.nv)
        ]

    def _distances(self, q: np.ndarray) -> np.ndarray:
        plant, ctx = self.plant, self._context
        out = np.empty((len(q), len(self.contacts)))
        for b, qb in enumerate(q):
            plant.SetPositions(ctx, qb)
            for i, (contact, body) in enumerate(zip(self.contacts, self._bodies_d, strict=True)):
                if i in self._pair_bodies_d:
                    A, B = self._pair_bodies_d[i]
                    out[b, i] = pair_geometry(
                        contact, *_pose(plant, ctx, A), *_pose(plant, ctx, B)
                    )[0]
                    continue
                p_WC = plant.EvalBodyPoseInWorld(ctx, body).multiply(np.asarray(contact.p_BC))
                out[b, i] = self.normal @ p_WC - contact.radius - self.ground.height
        return out

    def _evaluate(self, plant, ctx, q, v, u, active, unit_v) -> dict:
        """M, tau, N, phi, Jn, Jt of one state, in the plant's scalar type (double, or
        AutoDiffXd seeded on p = (q, v, u)): one code path for values and derivatives."""
        nv = self.nv
        plant.SetPositions(ctx, q)
        plant.SetVelocities(ctx, v)
        out = {"M": plant.CalcMassMatrix(ctx)}
        out["tau"] = (
            self.B_act @ u + plant.CalcGravityGeneralizedForces(ctx) - plant.CalcBiasTerm(ctx)
        )
        if self._qdot_is_v:  # N = I (prismatic, revolute, planar chains); dN = 0
            out["N"] = np.eye(self.nq, dtype=object if plant is self.plant_ad else float)
        else:
            out["N"] = np.stack([plant.MapVelocityToQDot(ctx, e) for e in unit_v], axis=1)
        phi, Jn, Jt = [], [], []
        world = plant.world_frame()
        for i in active:
            contact = self.contacts[i]
            if i in self._pair_bodies_d:
                self._pair_rows(plant, ctx, i, phi, Jn, Jt)
                continue
            body = self._bodies[i] if plant is self.plant_ad else self._bodies_d[i]
            X_WB = plant.EvalBodyPoseInWorld(ctx, body)
            p_WC = X_WB.multiply(np.asarray(contact.p_BC, float))
            phi.append(self.normal @ p_WC - contact.radius - self.ground.height)
            # the witness point on the body: p_BC moved by the radius against the normal
            p_BQ = np.asarray(contact.p_BC, float) - contact.radius * (
                X_WB.rotation().inverse().multiply(self.normal)
            )
            J = plant.CalcJacobianTranslationalVelocity(
                ctx, JacobianWrtVariable.kV, body.body_frame(), p_BQ, world, world
            )
            Jn.append(self.normal @ J)
            if contact.friction is not None:
                Jt.extend(self.tangents @ J)
        kind = object if plant is self.plant_ad else float
        out["phi"] = np.array(phi, dtype=kind).reshape(len(active))
        out["Jn"] = np.array(Jn, dtype=kind).reshape(len(active), nv)
        out["Jt"] = np.array(Jt, dtype=kind).reshape(len(Jt), nv)
        return out

    def _pair_rows(self, plant, ctx, i, phi, Jn, Jt) -> None:
        """Append pair candidate i's phi, Jn row and (if frictional) k Jt rows: the rows map v to
        the relative velocity of the witness points, n . (v_A(p_A) - v_B(p_B)), and likewise
        along k tangents orthogonal to n."""
        contact = self.contacts[i]
        A, B = self._pair_bodies_d[i]
        if plant is self.plant_ad:
            A, B = self._pair_bodies_ad[i]
        d, n, p_A, p_B = pair_geometry(contact, *_pose(plant, ctx, A), *_pose(plant, ctx, B))
        world = plant.world_frame()
        J = []
        for body, p_W in ((A, p_A), (B, p_B)):
            p_BQ = plant.EvalBodyPoseInWorld(ctx, body).inverse().multiply(p_W)
            J.append(plant.CalcJacobianTranslationalVelocity(
                ctx, JacobianWrtVariable.kV, body.body_frame(), p_BQ, world, world
            ))  # fmt: skip
        J_rel = J[0] - J[1]
        phi.append(d)
        Jn.append(n @ J_rel)
        if contact.friction is not None:
            Jt.extend(pair_tangents(n, self.cone.directions) @ J_rel)

    def _one(self, q, v, u, active, derivatives: bool, kinematics=None) -> dict:
        nq, nv, nu = self.nq, self.nv, self.nu
        h = self.h
        if not derivatives:
            e = self._evaluate(self.plant, self._context, q, v, u, active, self._unit_v_d)
            W = np.linalg.inv(e["M"])
            v_free = np.asarray(v, float) + h * W @ e["tau"]
            return dict(W=W, v_free=v_free, phi=e["phi"], Jn=e["Jn"], Jt=e["Jt"], N=e["N"])
        P = nq + nv + nu
        q_ad = InitializeAutoDiff(np.reshape(q, (-1, 1)), P, 0).ravel()
        v_ad = InitializeAutoDiff(np.reshape(v, (-1, 1)), P, nq).ravel()
        u_ad = InitializeAutoDiff(np.reshape(u, (-1, 1)), P, nq + nv).ravel()
        e = self._evaluate(self.plant_ad, self.context_ad, q_ad, v_ad, u_ad, active, self._unit_v)
        M, dM = _split(e["M"], P)
        tau, dtau = _split(e["tau"], P)
        N, dN = _split(e["N"], P)
        phi, dphi = _split(e["phi"], P)
        Jn, dJn = _split(e["Jn"], P)
        Jt, dJt = _split(e["Jt"], P) if e["Jt"].size else (np.zeros((0, nv)), np.zeros((0, nv, P)))
        W = np.linalg.inv(M)
        dW = np.zeros((nv, nv, P))  # d(M^-1) = -W dM W; M depends on q only
        dW[..., :nq] = -np.moveaxis(W @ np.moveaxis(dM[..., :nq], -1, 0) @ W, 0, -1)
        dv_free = np.zeros((nv, P))
        dv_free[:, nq : nq + nv] = np.eye(nv)
        dv_free += h * (np.einsum("ijp,j->ip", dW, tau) + W @ dtau)
        v_free = np.asarray(v, float) + h * W @ tau
        return dict(
            W=W, v_free=v_free, phi=phi, Jn=Jn, Jt=Jt, N=N,
            dW=dW, dv_free=dv_free, dphi=dphi, dJn=dJn, dJt=dJt, dN=dN,
        )  # fmt: skip
