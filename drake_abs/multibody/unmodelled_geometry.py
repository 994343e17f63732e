"""Collision geometry that a scene's contact candidates do not cover, and the warnings that say
so (issue 33: model only what is required, and say when it is not enough).

A scene models only the contacts it declares (:mod:`drake_abs.multibody.scene`): a body whose
collision geometry has no contact candidate passes through the ground, and the step calls that
converged. :class:`UnmodelledGeometry` reads every body's collision geometry from the scene's
model files (a plant parsed for the purpose with a SceneGraph, STL meshes through OBJ copies),
keeps what the candidates do not cover, and measures how far below the ground plane it lies at
a batch of states. The stepper (:class:`~drake_abs.multibody.stepper.ComplementarityStepper`,
option ``check_unmodelled``) runs this after every step and raises
:class:`UnmodelledPenetrationWarning` naming the body, the depth and the contact entries that
would model it (:meth:`UnmodelledGeometry.suggest_contacts`, also
:meth:`drake_abs.multibody.builder.SceneModel.suggest_contacts`). An initial state with a
contact candidate below the ground raises :class:`InitialPenetrationWarning`
(:func:`warn_initial_penetration`).

What is checked, exactly (the lowest point of a convex shape against a plane):

- sphere: its centre and radius; capsule: its two end-cap centres and radius; box: its 8
  corners; cylinder: its two rim circles (closed form); ellipsoid: closed form; mesh and convex:
  the vertices of the convex hull Drake computes for them (``Shape.GetConvexHull()``; an STL
  file's through an OBJ copy, so a concave mesh counts as its hull). Half-spaces and other
  shapes are skipped, as are bodies welded to the world (they cannot move into the ground).
- covered: a shape's point whose sphere lies inside a contact candidate's sphere on the same
  body (``|p - c| + r <= r_c``, to 1 um), or inside the convex hull of the centres of the body's
  candidates (with a radius no larger than theirs), is never lower than the lowest of them,
  which the step keeps out of the ground; it is left out. A body all of whose geometry is
  covered is not checked, nor one whose geometry lies within the tolerance of its candidates
  (its ``reach``: a foot mesh around its contact sphere). Body-body pairs cover no ground
  contact.
- against the ground plane only: geometry inside another body is not measured.

Cost: one batched forward kinematics (a compiled loop over the batch and the joints, from the
plant's joint frames: revolute, prismatic, weld and quaternion floating joints; other joints
through the MultibodyPlant, state by state), then per state and checked body a bounding sphere
in the body frame; only where that sphere dips deeper than the tolerance are its points
evaluated. Measured per step (``docs/howto/own_robot.md``, "When the scene does not model
enough"): 1 to 4 % of a step on Solo12 (16 meshes), 0.5 to 1.6 % on gymnasium's Hopper, at B = 1
and B = 256; nothing for a scene without collision geometry. The geometry is read once per
process and scene, at the first check.
"""

from __future__ import annotations

import logging
import warnings
import weakref
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numba as nb
import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    BodyIndex,
    PrismaticJoint,
    QuaternionFloatingJoint,
    RevoluteJoint,
    WeldJoint,
)
from scipy.spatial import ConvexHull, QhullError

from drake_abs.multibody.drake_dynamics import PointContact

LOGGER = logging.getLogger(__name__)

#: How close (m) a shape's point sphere may stick out of a candidate's sphere and still count as
#: covered by it (rounding of points written to a scene file).
COVER_TOL = 1e-6

#: The 26 directions (unit) a mesh's, cylinder's or ellipsoid's suggested points are extreme in:
#: the shape frame's axes, the diagonals of its faces and of its corners.
_DIRECTIONS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)])
_DIRECTIONS = _DIRECTIONS[np.abs(_DIRECTIONS).sum(axis=1) > 0].astype(float)
_DIRECTIONS /= np.linalg.norm(_DIRECTIONS, axis=1, keepdims=True)


class UnmodelledPenetrationWarning(UserWarning):
    """After a step, a body's collision geometry that no contact candidate covers lies below the
    ground by more than the stepper's tolerance: the scene does not model that contact, and the
    body passes through the ground. Raised once per body and stepper, with the depth of the
    deepest state of the batch where it first fired and the contact entries that would model it
    (:meth:`UnmodelledGeometry.suggest_contacts`)."""


class InitialPenetrationWarning(UserWarning):
    """An initial state (a scene's, a plant's) has a contact candidate below the ground by more
    than the penetration tolerance: the first step pushes it out within one step, with an
    impulse no contact produces, and calls the step converged."""


# --- the geometry ----------------------------------------------------------------------------


@dataclass(frozen=True)
class SupportShape:
    """One collision shape in its body's frame, as the lowest-point test sees it: the lowest
    point against a plane of normal n (in the body frame) is at height
    ``min_i n . points[i] - radius - disc_radius sqrt(1 - (n . disc_axis)^2) - |ellipsoid^T n|``
    above the body origin's.

    Attributes:
        kind: the Drake shape (``"sphere"``, ``"capsule"``, ``"box"``, ``"cylinder"``,
            ``"ellipsoid"``, ``"mesh"``, ``"convex"``).
        name: the geometry's name in the SceneGraph.
        points: (n, 3) m: a sphere's centre, a capsule's end-cap centres, a box's corners, a
            cylinder's rim centres, an ellipsoid's centre, a mesh's hull vertices (those left
            after covered ones are removed).
        radius: m, the sphere swept over the points (sphere, capsule).
        disc_axis, disc_radius: a cylinder's axis (unit) and radius (m); radius 0 otherwise.
        ellipsoid: (3, 3) ``R_BG diag(a, b, c)`` of an ellipsoid; zeros otherwise.
        suggested: (m, 3) the points :meth:`UnmodelledGeometry.suggest_contacts` proposes for
            it, each a sphere of ``radius``: the points themselves for spheres, capsules and
            boxes; a mesh's the 8 corners of its hull's bounding box in the shape's frame
            (they hold the whole hull above the ground, a little higher than it rests where
            the mesh is rounded); a cylinder's 8 points on each rim circle; an ellipsoid's
            extreme points in 26 directions of its frame.
    """

    kind: str
    name: str
    points: np.ndarray
    radius: float = 0.0
    disc_axis: np.ndarray = field(default_factory=lambda: np.zeros(3))
    disc_radius: float = 0.0
    ellipsoid: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    suggested: np.ndarray | None = None

    def bounding_sphere(self, centre: np.ndarray) -> float:
        """The radius (m) of a sphere about ``centre`` (body frame) that holds the shape."""
        reach = np.linalg.norm(self.points - centre, axis=1).max()
        extra = self.disc_radius + float(np.linalg.norm(self.ellipsoid, axis=0).max(initial=0.0))
        return float(reach + self.radius + extra)


@dataclass(frozen=True)
class BodyGeometry:
    """A body's collision shapes (:class:`SupportShape`, in its frame) that its contact
    candidates leave uncovered; ``model`` is its model instance's name, ``unique`` whether its
    name alone names it in the plant, ``reach`` (m) how far below the lowest point of its
    candidates that geometry can lie (its farthest point from the nearest candidate sphere;
    ``inf`` for a body without candidates): while the step keeps the candidates out of the
    ground, the body is never deeper than that."""

    body: str
    model: str
    shapes: tuple[SupportShape, ...]
    unique: bool = True
    reach: float = np.inf

    @property
    def label(self) -> str:
        """How messages and :meth:`UnmodelledGeometry.suggest_contacts` name it: the body's
        name, ``"model::body"`` where the name is not unique."""
        return self.body if self.unique else f"{self.model}::{self.body}"


def _shape_support(shape, name: str, X_BG) -> SupportShape | None:
    """The :class:`SupportShape` of a SceneGraph shape posed at ``X_BG`` in its body, or None
    for a shape that is not checked (half-spaces and the like)."""
    from pydrake.geometry import Box, Capsule, Convex, Cylinder, Ellipsoid, Mesh, Sphere

    R = np.asarray(X_BG.rotation().matrix(), float)
    p = np.asarray(X_BG.translation(), float)

    def body_frame(local):
        return np.asarray(local, float).reshape(-1, 3) @ R.T + p

    def extremes(support):  # the shape's support points in the 26 directions (body frame)
        return body_frame(_unique_rows(np.array([support(d) for d in _DIRECTIONS])))

    if isinstance(shape, Sphere):
        pts = body_frame(np.zeros(3))
        return SupportShape("sphere", name, pts, float(shape.radius()), suggested=pts)
    if isinstance(shape, Capsule):
        half = shape.length() / 2
        pts = body_frame([[0, 0, -half], [0, 0, half]])
        return SupportShape("capsule", name, pts, float(shape.radius()), suggested=pts)
    if isinstance(shape, Box):
        h = np.asarray(shape.size(), float) / 2
        pts = body_frame([[i * h[0], j * h[1], k * h[2]]
                          for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])  # fmt: skip
        return SupportShape("box", name, pts, suggested=pts)
    if isinstance(shape, Cylinder):
        r, half = float(shape.radius()), shape.length() / 2
        angles = np.arange(8) * np.pi / 4
        rim = [[r * np.cos(a), r * np.sin(a), z] for z in (-half, half) for a in angles]
        return SupportShape(
            "cylinder", name, body_frame([[0, 0, -half], [0, 0, half]]), 0.0, R[:, 2].copy(), r,
            suggested=body_frame(rim),
        )  # fmt: skip
    if isinstance(shape, Ellipsoid):
        axes = np.array([shape.a(), shape.b(), shape.c()], float)
        M = np.diag(axes)

        def support(d):  # the point of x^T M^-2 x = 1 farthest along d
            return M @ M @ d / np.linalg.norm(M @ d)

        return SupportShape(
            "ellipsoid", name, body_frame(np.zeros(3)), ellipsoid=R @ M,
            suggested=extremes(support),
        )  # fmt: skip
    if isinstance(shape, Mesh | Convex):
        hull = shape.GetConvexHull()
        V = np.array([hull.vertex(i) for i in range(hull.num_vertices())], float).reshape(-1, 3)
        if not len(V):
            return None
        kind = "mesh" if isinstance(shape, Mesh) else "convex"
        lo, hi = V.min(axis=0), V.max(axis=0)  # the hull's bounding box in the shape's frame
        corners = [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                   for z in (lo[2], hi[2])]  # fmt: skip
        return SupportShape(kind, name, body_frame(V), suggested=body_frame(corners))
    return None


def _unique_rows(a: np.ndarray) -> np.ndarray:
    """The rows of ``a`` without repeats (to 1e-12 m), in their first order."""
    _, first = np.unique(np.round(a, 12), axis=0, return_index=True)
    return a[np.sort(first)]


def _uncovered(points: np.ndarray, radius: float, spheres: np.ndarray) -> np.ndarray:
    """Which of ``points`` (n, 3), each a sphere of ``radius``, the candidate spheres (rows of
    ``spheres``: centre, radius) on the same body do not cover: a point is covered inside one
    of them (``|p - c| + radius <= r_c``), or inside the convex hull of their centres with a
    radius no larger than theirs (it is then never lower than the lowest of them)."""
    if not len(spheres) or not len(points):
        return np.ones(len(points), dtype=bool)
    gap = np.linalg.norm(points[:, None, :] - spheres[None, :, :3], axis=2) + radius
    covered = (gap <= spheres[None, :, 3] + COVER_TOL).any(axis=1)
    if radius <= spheres[:, 3].min() + COVER_TOL and len(spheres) >= 4:
        try:
            faces = ConvexHull(spheres[:, :3]).equations  # inside: n . x + d <= 0, |n| = 1
        except QhullError:  # flat or degenerate: no volume to be inside
            faces = None
        if faces is not None:
            covered |= (points @ faces[:, :3].T + faces[:, 3] <= COVER_TOL).all(axis=1)
    return ~covered


def _reach(shape: SupportShape, spheres: np.ndarray) -> float:
    """How far (m) below the lowest of the candidate spheres (rows: centre, radius) the shape
    can reach: the largest over its points of the smallest ``|p - c| + r - r_c`` (a cylinder's
    or ellipsoid's from its bounding sphere); inf without candidates."""
    if not len(spheres):
        return np.inf
    if shape.disc_radius > 0 or shape.ellipsoid.any():
        centre = shape.points.mean(axis=0)
        points, radius = centre[None], shape.bounding_sphere(centre)
    else:
        points, radius = shape.points, shape.radius
    gap = np.linalg.norm(points[:, None, :] - spheres[None, :, :3], axis=2) + radius
    return float((gap - spheres[None, :, 3]).min(axis=1).max())


def _without_covered(shape: SupportShape, spheres: np.ndarray) -> SupportShape | None:
    """``shape`` with its covered points removed (None when all are), a cylinder or ellipsoid
    kept whole unless its bounding sphere is covered."""
    if shape.disc_radius > 0 or shape.ellipsoid.any():
        centre = shape.points.mean(axis=0)
        if not _uncovered(centre[None], shape.bounding_sphere(centre), spheres)[0]:
            return None
        return shape
    keep = _uncovered(shape.points, shape.radius, spheres)
    if not keep.any():
        return None
    suggested = shape.suggested
    if suggested is not None:
        suggested = suggested[_uncovered(suggested, shape.radius, spheres)]
    return SupportShape(
        shape.kind, shape.name, shape.points[keep], shape.radius, shape.disc_axis,
        shape.disc_radius, shape.ellipsoid, suggested,
    )  # fmt: skip


#: Collision geometry read per scene model list (and model file versions), in this process.
_READ: dict[tuple, list[tuple[str, str, SupportShape]]] = {}


def read_collision_geometry(models: Sequence, where: str) -> list[tuple[str, str, SupportShape]]:
    """Every collision shape of the bodies of ``models`` (a scene's
    :class:`~drake_abs.multibody.scene_entries.ModelSpec` entries) that can move:
    ``[(model instance, body, SupportShape)]`` in the body's frame, read once per process and
    model files (a plant parsed with a SceneGraph, STL meshes through OBJ copies). A scene whose
    geometry cannot be read logs why and has none (the check is then off for it)."""
    from drake_abs.multibody.parsing import resolve_model_file

    stamps = []
    for spec in models:
        try:
            path = resolve_model_file(spec)
            stat = Path(path).stat()
            stamps.append((str(path), stat.st_mtime_ns, stat.st_size))
        except (OSError, ValueError):
            stamps.append((spec.file, 0, 0))
    key = (tuple(models), tuple(stamps))
    if key not in _READ:
        try:
            _READ[key] = _read(models, where)
        except (RuntimeError, ValueError) as err:
            LOGGER.warning(
                "%s: the collision geometry of its model files could not be read (%s); the "
                "check for unmodelled geometry is off for it",
                where,
                err,
            )
            _READ[key] = []
    return _READ[key]


def _read(models: Sequence, where: str) -> list[tuple[str, str, SupportShape]]:
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.systems.framework import DiagramBuilder

    from drake_abs.multibody.parsing import add_model_specs

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    add_model_specs(plant, models, where, collisions=True, obj_meshes=True)
    plant.Finalize()
    inspector = scene_graph.model_inspector()
    fixed = {int(b.index()) for b in plant.GetBodiesWeldedTo(plant.world_body())}
    out = []
    for i in range(plant.num_bodies()):
        body = plant.get_body(BodyIndex(i))
        if i in fixed:
            continue
        model = plant.GetModelInstanceName(body.model_instance())
        for gid in plant.GetCollisionGeometriesForBody(body):
            support = _shape_support(
                inspector.GetShape(gid), inspector.GetName(gid), inspector.GetPoseInFrame(gid)
            )
            if support is not None:
                out.append((model, body.name(), support))
    return out


# --- the check -------------------------------------------------------------------------------


class UnmodelledGeometry:
    """The collision geometry of a scene's bodies that its contact candidates do not cover (see
    the module docstring), and its depth below the ground at a batch of states.

    Args:
        plant: the scene's dynamics plant (finalized; the step's q poses it).
        contacts: the scene's contact candidates (point candidates cover geometry on their body).
        models: the scene's model entries (the geometry is read from their files, once, when
            first needed).
        where: how messages name the scene (``"scene 'solo12_drop'"``).
        friction: the friction coefficient of suggested contact entries (the scene's most
            common one; None: frictionless).
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        contacts: Sequence,
        models: Sequence,
        where: str,
        friction: float | None = None,
    ):
        self.plant = plant
        self.contacts = list(contacts)
        self.models = tuple(models)
        self.where = where
        self.friction = friction

    @classmethod
    def of_scene(cls, scene, plant: MultibodyPlant, contacts: Sequence) -> UnmodelledGeometry:
        """The uncovered geometry of ``scene`` (a :class:`~drake_abs.multibody.scene.Scene`)
        on its dynamics ``plant`` with its candidates ``contacts``; suggested entries take the
        most common friction coefficient of its contact entries."""
        frictions = Counter(c.friction for c in scene.contacts if c.friction is not None)
        friction = frictions.most_common(1)[0][0] if frictions else None
        return cls(plant, contacts, scene.models, f"scene {scene.name!r}", friction)

    # the data, made when first needed

    @property
    def bodies(self) -> tuple[BodyGeometry, ...]:
        """The bodies with uncovered collision geometry, each with its uncovered shapes."""
        return self._tables[0]

    @property
    def _tables(self):
        if "_cached" not in self.__dict__:
            self.__dict__["_cached"] = self._build()
        return self.__dict__["_cached"]

    def _build(self):
        plant = self.plant
        spheres: dict[tuple[str, str], list] = {}
        for c in self.contacts:
            if isinstance(c, PointContact):
                body = _body(plant, c.body, c.model_instance)
                key = (plant.GetModelInstanceName(body.model_instance()), body.name())
                spheres.setdefault(key, []).append([*c.p_BC, c.radius])
        grouped: dict[tuple[str, str], list[SupportShape]] = {}
        for model, name, shape in read_collision_geometry(self.models, self.where):
            if not plant.HasModelInstanceNamed(model):
                continue
            instance = plant.GetModelInstanceByName(model)
            if not plant.HasBodyNamed(name, instance):
                continue
            cover = np.array(spheres.get((model, name), []), float).reshape(-1, 4)
            kept = _without_covered(shape, cover)
            if kept is not None:
                grouped.setdefault((model, name), []).append((kept, _reach(kept, cover)))
        names = Counter(plant.get_body(BodyIndex(i)).name() for i in range(plant.num_bodies()))
        bodies = tuple(
            BodyGeometry(
                name,
                model,
                tuple(s for s, _ in shapes),
                names[name] == 1,
                max(r for _, r in shapes),
            )  # fmt: skip
            for (model, name), shapes in grouped.items()
        )
        return (bodies, _tables(plant, bodies), _Kinematics(plant))

    # evaluation

    def lowest(
        self, q: np.ndarray, normal, height: float, cutoff: float = np.inf, skip=None
    ) -> np.ndarray:
        """The height (m) above the ground plane ``normal . p = height`` of each checked body's
        lowest uncovered point at the states q (B, nq): (B, len(bodies)), negative below the
        ground. Exact where it is below ``cutoff`` (default: everywhere); elsewhere a lower
        bound that is at least ``cutoff`` (the lowest point of the body's bounding sphere).
        ``skip`` (len(bodies),) bool: bodies not evaluated (``inf``)."""
        bodies, tables, kinematics = self._tables
        q = np.ascontiguousarray(np.atleast_2d(q), dtype=float)
        if not bodies:
            return np.zeros((q.shape[0], 0))
        n = np.asarray(normal, float)
        n = n / np.sqrt(n @ n)
        skip = tables["none"] if skip is None else np.asarray(skip, bool)
        plane = (n, float(height), float(cutoff), skip)
        if kinematics.compiled:  # one compiled call: the poses, then the lowest points
            return _lowest_at(q, *kinematics.arrays, *tables["arrays"], *plane)
        X = kinematics.poses(q, tables["body_index"])
        return _lowest(X, *tables["arrays"], *plane)

    def depths(self, q: np.ndarray, ground, tolerance: float = 0.0) -> np.ndarray:
        """How deep (m, >= 0) each checked body's uncovered geometry is below ``ground`` (a
        :class:`~drake_abs.multibody.drake_dynamics.GroundPlane`) at the states q (B, nq):
        (B, len(bodies)); exact where deeper than ``tolerance``, else at most ``tolerance``
        (0 for a body whose geometry cannot reach deeper than ``tolerance`` below its contact
        candidates: its ``reach``)."""
        tables = self._tables[1]
        skip = tables.get(("skip", tolerance))
        if skip is None:
            skip = tables[("skip", tolerance)] = tables.get("reach", np.zeros(0)) <= tolerance
        lowest = self.lowest(q, ground.normal, ground.height, cutoff=-tolerance, skip=skip)
        return np.maximum(0.0, -lowest)

    def check(self, q: np.ndarray, ground, tolerance: float, warned: set, stacklevel: int = 1):
        """Warn (:class:`UnmodelledPenetrationWarning`, one warning for all of them) about the
        checked bodies deeper than ``tolerance`` (m) below ``ground`` (a
        :class:`~drake_abs.multibody.drake_dynamics.GroundPlane`) at some state of q (B, nq)
        and not in ``warned`` (the labels already warned about, updated): each body's label and
        the depth of its deepest state in the batch, deepest first, and the contact entries
        that would model them (:meth:`suggest_contacts`). ``stacklevel`` as the warning's,
        counted from the caller of this method."""
        bodies, tables, kinematics = self._tables
        if not bodies:
            return
        key = ("plane", ground.normal, ground.height, tolerance)
        plane = tables.get(key)
        if plane is None:  # the arguments of this ground and tolerance, made once
            n = np.asarray(ground.normal, float)
            skip = tables["reach"] <= tolerance
            plane = tables[key] = (n / np.linalg.norm(n), float(ground.height), -tolerance, skip)
        q = np.ascontiguousarray(q, dtype=float)
        if kinematics.compiled:  # the deepest of the batch per body, in one compiled call
            depth = _deepest_at(q, *kinematics.arrays, *tables["arrays"], *plane)
        else:
            depth = _deepest(kinematics.poses(q, tables["body_index"]), *tables["arrays"], *plane)
        if not (depth > tolerance).any():
            return
        new = [k for k in np.flatnonzero(depth > tolerance) if bodies[k].label not in warned]
        if not new:
            return
        new.sort(key=lambda k: -depth[k])
        labels = [bodies[k].label for k in new]
        warned.update(labels)
        lines = [
            f"  body {bodies[k].label!r}: {depth[k]:.4g} m ("
            + ("no contact candidate" if np.isinf(bodies[k].reach)
               else "its contact candidates do not cover that geometry") + ")"
            for k in new
        ]  # fmt: skip
        warnings.warn(
            f"{self.where}: collision geometry that no contact candidate covers is below the "
            f"ground by more than {tolerance:g} m (the depth of its lowest point, the deepest "
            "state of the batch):\n" + "\n".join(lines) + "\nThe scene does not model that "
            "contact: the body passes through the ground. Add to the scene's contacts "
            f"(SceneModel.suggest_contacts({labels!r}).yaml):\n"
            + self.suggest_contacts(labels).yaml,
            UnmodelledPenetrationWarning,
            stacklevel=stacklevel + 1,
        )

    # suggestions

    def suggest_contacts(
        self, bodies: Iterable[str] | None = None, tolerance: float = 0.01
    ) -> SuggestedContacts:
        """Contact entries (the scene YAML's ``contacts`` schema) that model the uncovered
        collision geometry of ``bodies`` (labels: names, ``"model::body"`` where a name is not
        unique; default: every body whose uncovered geometry can reach deeper than
        ``tolerance`` (m) below its candidates, the ``reach`` of :class:`BodyGeometry`, e.g.
        every body without candidates): per body and radius one entry of points in the body
        frame,
        rounded to 1 um, with the scene's most common friction coefficient (see
        :attr:`SupportShape.suggested`): a sphere's centre and radius, a capsule's end-cap
        centres and radius, a box's corners, a mesh's the corners of its hull's bounding box,
        a cylinder's rim points, an ellipsoid's extreme points. Points the candidates already
        cover are left out.

        Raises:
            ValueError: for a name that is not a checked body (naming the checked ones).
        """
        by_label = {b.label: b for b in self.bodies}
        if bodies is None:
            chosen = [b.label for b in self.bodies if b.reach > tolerance]
        else:
            chosen = [bodies] if isinstance(bodies, str) else list(bodies)
        unknown = [name for name in chosen if name not in by_label]
        if unknown:
            raise ValueError(
                f"{self.where}: no uncovered collision geometry on {unknown}; the bodies with "
                f"some: {sorted(by_label) or 'none'}"
            )
        entries = []
        for label in chosen:
            body = by_label[label]
            radii: dict[float, list] = {}
            for shape in body.shapes:
                pts = shape.points if shape.suggested is None else shape.suggested
                radii.setdefault(round(shape.radius, 9), []).extend(np.round(pts, 6).tolist())
            for radius, pts in radii.items():
                entry = {"body": body.body, "points": [[float(x) for x in p] for p in
                                                       _unique_rows(np.asarray(pts))]}  # fmt: skip
                entry["radius"] = float(radius)
                entry["friction"] = self.friction
                if not body.unique:
                    entry["model"] = body.model
                entries.append(entry)
        return SuggestedContacts(tuple(entries))


@dataclass(frozen=True)
class SuggestedContacts:
    """Contact entries that model a scene's uncovered collision geometry
    (:meth:`UnmodelledGeometry.suggest_contacts`): ``entries`` as plain mappings of the scene
    YAML's ``contacts`` schema (:class:`~drake_abs.multibody.scene_entries.ContactSpec`)."""

    entries: tuple[dict, ...]

    def __len__(self) -> int:
        return len(self.entries)

    @property
    def yaml(self) -> str:
        """The entries as YAML list items, to paste under a scene file's ``contacts:``."""
        lines = []
        for e in self.entries:
            lines.append(f"  - body: {e['body']}")
            if "model" in e:
                lines.append(f"    model: {e['model']}")
            lines.append("    points:")
            lines += [f"      - [{', '.join(_number(x) for x in p)}]" for p in e["points"]]
            lines.append(f"    radius: {_number(e['radius'])}")
            friction = e["friction"]
            lines.append(f"    friction: {'null' if friction is None else _number(friction)}")
        return "\n".join(lines) + "\n"

    def added_to(self, scene):
        """``scene`` (a :class:`~drake_abs.multibody.scene.Scene`) with these entries appended
        to its contacts."""
        data = scene.to_dict()
        data["contacts"] = [*data["contacts"], *(dict(e) for e in self.entries)]
        return type(scene).from_dict(data)


def _number(x: float) -> str:
    """A number as YAML text that reads back as a float (``0.0``, ``0.016``, ``-0.2241``)."""
    text = f"{float(x):.6g}"
    return text if any(c in text for c in ".eEn") else text + ".0"


def _body(plant: MultibodyPlant, name: str, model: str | None):
    instance = plant.GetModelInstanceByName(model) if model else None
    if instance is None:
        return plant.GetBodyByName(name)
    return plant.GetBodyByName(name, instance)


def _tables(plant: MultibodyPlant, bodies: tuple[BodyGeometry, ...]) -> dict[str, np.ndarray]:
    """The flat arrays the compiled check reads: per body its index in the plant, its bounding
    sphere (centre in the body frame, radius) and its first shape; per shape its first point,
    radius, disc and ellipsoid; the points."""
    body_index, centre, bound, shape_start = [], [], [], [0]
    point_start, radius, disc_axis, disc_radius, ellipsoid, points = [0], [], [], [], [], []
    for b in bodies:
        body_index.append(int(_body(plant, b.body, b.model).index()))
        pts = np.concatenate([s.points for s in b.shapes])
        c = (pts.min(axis=0) + pts.max(axis=0)) / 2
        centre.append(c)
        bound.append(max(s.bounding_sphere(c) for s in b.shapes))
        for s in b.shapes:
            points.append(s.points)
            point_start.append(point_start[-1] + len(s.points))
            radius.append(s.radius)
            disc_axis.append(s.disc_axis)
            disc_radius.append(s.disc_radius)
            ellipsoid.append(s.ellipsoid)
        shape_start.append(shape_start[-1] + len(b.shapes))
    if not bodies:
        return {"body_index": np.zeros(0, np.int64)}
    out = {
        "body_index": np.array(body_index, np.int64),
        "reach": np.array([b.reach for b in bodies], float),
        "none": np.zeros(len(bodies), bool),
    }
    out["arrays"] = (  # the arguments of _lowest after the poses, in its order
        out["body_index"],
        np.array(centre, float).reshape(-1, 3),
        np.array(bound, float),
        np.array(shape_start, np.int64),
        np.array(point_start, np.int64),
        np.array(radius, float),
        np.array(disc_axis, float).reshape(-1, 3),
        np.array(disc_radius, float),
        np.array(ellipsoid, float).reshape(-1, 3, 3),
        np.ascontiguousarray(np.concatenate(points), float),
    )
    return out


@nb.njit(cache=True)
def _lowest(X, body_index, centre, bound, shape_start, point_start, radius, disc_axis,
            disc_radius, ellipsoid, points, n, height, cutoff, skip):  # fmt: skip
    """Per state and body the height of its lowest uncovered point above the plane ``n . p =
    height`` (see :meth:`UnmodelledGeometry.lowest`), from the bodies' poses X (B, nb, 3, 4)."""
    B, K = X.shape[0], body_index.size
    out = np.empty((B, K))
    nB = np.empty(3)
    for b in range(B):
        for k in range(K):
            if skip[k]:
                out[b, k] = np.inf
                continue
            T = X[b, body_index[k]]
            for i in range(3):  # the normal in the body frame: R^T n
                nB[i] = T[0, i] * n[0] + T[1, i] * n[1] + T[2, i] * n[2]
            h0 = T[0, 3] * n[0] + T[1, 3] * n[1] + T[2, 3] * n[2] - height
            low = h0 + nB[0] * centre[k, 0] + nB[1] * centre[k, 1] + nB[2] * centre[k, 2]
            low -= bound[k]
            if low >= cutoff:  # the bounding sphere is above the cutoff: a lower bound will do
                out[b, k] = low
                continue
            best = np.inf
            for s in range(shape_start[k], shape_start[k + 1]):
                m = np.inf
                for p in range(point_start[s], point_start[s + 1]):
                    d = nB[0] * points[p, 0] + nB[1] * points[p, 1] + nB[2] * points[p, 2]
                    m = min(m, d)
                m -= radius[s]
                if disc_radius[s] > 0.0:
                    c = nB[0] * disc_axis[s, 0] + nB[1] * disc_axis[s, 1] + nB[2] * disc_axis[s, 2]
                    m -= disc_radius[s] * np.sqrt(max(0.0, 1.0 - c * c))
                e = 0.0
                for j in range(3):
                    t = ellipsoid[s, 0, j] * nB[0] + ellipsoid[s, 1, j] * nB[1]
                    t += ellipsoid[s, 2, j] * nB[2]
                    e += t * t
                m -= np.sqrt(e)
                best = min(best, m)
            out[b, k] = h0 + best
    return out


@nb.njit(cache=True)
def _lowest_at(q, kind, q_start, axis, X_PF, X_MC, parent, child, n_bodies, body_index, centre,
               bound, shape_start, point_start, radius, disc_axis, disc_radius, ellipsoid,
               points, n, height, cutoff, skip):  # fmt: skip
    """:func:`_lowest` at the states q (B, nq), their poses from :func:`_body_poses`."""
    X = _body_poses(q, kind, q_start, axis, X_PF, X_MC, parent, child, n_bodies)
    return _lowest(X, body_index, centre, bound, shape_start, point_start, radius, disc_axis,
                   disc_radius, ellipsoid, points, n, height, cutoff, skip)  # fmt: skip


@nb.njit(cache=True)
def _deepest(X, body_index, centre, bound, shape_start, point_start, radius, disc_axis,
             disc_radius, ellipsoid, points, n, height, cutoff, skip):  # fmt: skip
    """Per body the largest depth (m, >= 0) of :func:`_lowest` over the batch (non-finite
    states left out)."""
    low = _lowest(X, body_index, centre, bound, shape_start, point_start, radius, disc_axis,
                  disc_radius, ellipsoid, points, n, height, cutoff, skip)  # fmt: skip
    out = np.zeros(low.shape[1])
    for b in range(low.shape[0]):
        for k in range(low.shape[1]):
            if -low[b, k] > out[k]:  # NaN compares False
                out[k] = -low[b, k]
    return out


@nb.njit(cache=True)
def _deepest_at(q, kind, q_start, axis, X_PF, X_MC, parent, child, n_bodies, body_index,
                centre, bound, shape_start, point_start, radius, disc_axis, disc_radius,
                ellipsoid, points, n, height, cutoff, skip):  # fmt: skip
    """:func:`_deepest` at the states q (B, nq), their poses from :func:`_body_poses`."""
    X = _body_poses(q, kind, q_start, axis, X_PF, X_MC, parent, child, n_bodies)
    return _deepest(X, body_index, centre, bound, shape_start, point_start, radius, disc_axis,
                    disc_radius, ellipsoid, points, n, height, cutoff, skip)  # fmt: skip


# --- batched forward kinematics --------------------------------------------------------------

_WELD, _REVOLUTE, _PRISMATIC, _QUATERNION = 0, 1, 2, 3


class _Kinematics:
    """The world poses of a plant's bodies at a batch of q: compiled from the joints' frames
    (revolute, prismatic, weld and quaternion floating joints), else through the plant."""

    def __init__(self, plant: MultibodyPlant):
        self.plant = plant
        self.n_bodies = plant.num_bodies()
        joints = [plant.get_joint(i) for i in plant.GetJointIndices()]
        placed, order = {int(plant.world_body().index())}, []
        pending = list(joints)
        self.compiled = all(
            isinstance(j, RevoluteJoint | PrismaticJoint | WeldJoint | QuaternionFloatingJoint)
            for j in joints
        )
        while pending and self.compiled:
            ready = [j for j in pending if int(j.parent_body().index()) in placed]
            if not ready:  # a joint whose child is inboard (reversed): through the plant
                self.compiled = False
                break
            for j in ready:
                order.append(j)
                placed.add(int(j.child_body().index()))
                pending.remove(j)
        if not self.compiled:
            self._context = plant.CreateDefaultContext()
            return
        m = len(order)
        self.kind = np.zeros(m, np.int64)
        self.q_start = np.zeros(m, np.int64)
        self.axis = np.zeros((m, 3))
        self.X_PF = np.zeros((m, 3, 4))
        self.X_MC = np.zeros((m, 3, 4))
        self.parent = np.zeros(m, np.int64)
        self.child = np.zeros(m, np.int64)
        for i, j in enumerate(order):
            X_PF = j.frame_on_parent().GetFixedPoseInBodyFrame().GetAsMatrix4()
            X_MC = j.frame_on_child().GetFixedPoseInBodyFrame().inverse().GetAsMatrix4()
            if isinstance(j, WeldJoint):
                self.kind[i] = _WELD
                X_PF = X_PF @ j.X_FM().GetAsMatrix4() @ X_MC
            elif isinstance(j, RevoluteJoint):
                self.kind[i], self.axis[i] = _REVOLUTE, j.revolute_axis()
            elif isinstance(j, PrismaticJoint):
                self.kind[i], self.axis[i] = _PRISMATIC, j.translation_axis()
            else:
                self.kind[i] = _QUATERNION
            self.q_start[i] = j.position_start()
            self.X_PF[i] = X_PF[:3]
            self.X_MC[i] = X_MC[:3]
            self.parent[i] = int(j.parent_body().index())
            self.child[i] = int(j.child_body().index())
        #: the arguments of _body_poses after q, in its order
        self.arrays = (
            self.kind, self.q_start, self.axis, self.X_PF, self.X_MC, self.parent, self.child,
            self.n_bodies,
        )  # fmt: skip

    def poses(self, q: np.ndarray, needed: np.ndarray) -> np.ndarray:
        """X_WB (B, num_bodies, 3, 4) ([R | p]) at q (B, nq): every body's when compiled, else
        those of the body indices ``needed`` (the others identity)."""
        q = np.ascontiguousarray(q, dtype=float)
        if self.compiled:
            return _body_poses(q, *self.arrays)
        plant, ctx = self.plant, self._context
        X = np.broadcast_to(np.eye(4)[:3], (q.shape[0], self.n_bodies, 3, 4)).copy()
        bodies = [plant.get_body(BodyIndex(int(i))) for i in needed]
        for b, qb in enumerate(q):
            plant.SetPositions(ctx, qb)
            for i, body in zip(needed, bodies, strict=True):
                X[b, i] = plant.EvalBodyPoseInWorld(ctx, body).GetAsMatrix4()[:3]
        return X


@nb.njit(cache=True)
def _affine(A, B, out):
    """out = A B for affine transforms stored as 3 x 4 arrays [R | p]."""
    for i in range(3):
        a0, a1, a2 = A[i, 0], A[i, 1], A[i, 2]
        for j in range(4):
            out[i, j] = a0 * B[0, j] + a1 * B[1, j] + a2 * B[2, j]
        out[i, 3] += A[i, 3]


@nb.njit(cache=True)
def _body_poses(q, kind, q_start, axis, X_PF, X_MC, parent, child, n_bodies):
    """X_WB (B, n_bodies, 3, 4) ([R | p]) of every body at q (B, nq), joint by joint from the
    world out: X_WC = X_WP X_PF X_FM(q) X_MC (a weld's X_PF holds X_FM X_MC, its X_MC unused)."""
    B = q.shape[0]
    X = np.empty((B, n_bodies, 3, 4))
    T = np.zeros((3, 4))
    A = np.empty((3, 4))
    C = np.empty((3, 4))
    for b in range(B):
        X[b, 0] = 0.0  # the world body (index 0)
        X[b, 0, 0, 0] = X[b, 0, 1, 1] = X[b, 0, 2, 2] = 1.0
        for j in range(kind.size):
            Xp, Xc = X[b, parent[j]], X[b, child[j]]
            if kind[j] == 0:  # weld
                _affine(Xp, X_PF[j], Xc)
                continue
            s = q_start[j]
            T[:, :] = 0.0
            if kind[j] == 1:  # revolute: R(axis, theta) (Rodrigues)
                c, sn = np.cos(q[b, s]), np.sin(q[b, s])
                u = axis[j]
                for i in range(3):
                    for k in range(3):
                        T[i, k] = (1.0 - c) * u[i] * u[k]
                    T[i, i] += c
                T[0, 1] -= sn * u[2]
                T[1, 0] += sn * u[2]
                T[0, 2] += sn * u[1]
                T[2, 0] -= sn * u[1]
                T[1, 2] -= sn * u[0]
                T[2, 1] += sn * u[0]
            elif kind[j] == 2:  # prismatic: a translation along the axis
                T[0, 0] = T[1, 1] = T[2, 2] = 1.0
                for i in range(3):
                    T[i, 3] = axis[j, i] * q[b, s]
            else:  # quaternion floating: (qw, qx, qy, qz, x, y, z), the quaternion normalized
                w, x, y, z = q[b, s], q[b, s + 1], q[b, s + 2], q[b, s + 3]
                norm = np.sqrt(w * w + x * x + y * y + z * z)
                w, x, y, z = w / norm, x / norm, y / norm, z / norm
                T[0, 0] = 1.0 - 2.0 * (y * y + z * z)
                T[0, 1] = 2.0 * (x * y - w * z)
                T[0, 2] = 2.0 * (x * z + w * y)
                T[1, 0] = 2.0 * (x * y + w * z)
                T[1, 1] = 1.0 - 2.0 * (x * x + z * z)
                T[1, 2] = 2.0 * (y * z - w * x)
                T[2, 0] = 2.0 * (x * z - w * y)
                T[2, 1] = 2.0 * (y * z + w * x)
                T[2, 2] = 1.0 - 2.0 * (x * x + y * y)
                T[0, 3], T[1, 3], T[2, 3] = q[b, s + 4], q[b, s + 5], q[b, s + 6]
            _affine(Xp, X_PF[j], A)
            _affine(A, T, C)
            _affine(C, X_MC[j], Xc)
    return X


# --- initial states --------------------------------------------------------------------------

#: The initial states already warned about, per contact model (no warning twice for one state).
_WARNED_INITIAL: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def candidate_labels(scene) -> list[str]:
    """Where each contact candidate of ``scene`` (a :class:`~drake_abs.multibody.scene.Scene`)
    comes from, in the candidates' order: ``"contacts[j].points[i]"``, ``"contacts[j]
    (geometry)"`` or ``"pairs[j]"``."""
    from drake_abs.multibody.contacts import contact_candidates

    labels = []
    where = f"scene {scene.name!r}"
    for j, c in enumerate(scene.contacts):
        if c.geometry is None:
            labels += [f"contacts[{j}].points[{i}]" for i in range(len(c.points))]
        else:
            count = len(contact_candidates(where, scene.models, [c]))
            labels += [f"contacts[{j}] (geometry, candidate {i})" for i in range(count)]
    for j, pair in enumerate(scene.pairs):
        count = len(contact_candidates(where, scene.models, [], [pair]))
        labels += [f"pairs[{j}]"] * count
    return labels


def warn_initial_penetration(
    model, q0: np.ndarray, tolerance: float, where: str, scene=None, stacklevel: int = 1
) -> bool:
    """Warn (:class:`InitialPenetrationWarning`) when a contact candidate of ``model`` (a
    contact model: :class:`~drake_abs.multibody.drake_dynamics.ContactModelBase`) is below its
    surface (the ground; a pair's other body) by more than ``tolerance`` (m) at the initial
    positions q0 (nq,), naming each such candidate (its index, body, point and radius, and
    with the ``scene`` it was built from its entry, ``contacts[j].points[i]``) and its depth,
    deepest first. Once per model and state; ``stacklevel`` as the warning's, counted from the
    caller. Returns whether it warned."""
    q0 = np.asarray(q0, float)
    if not len(model.contacts) or q0.shape != (model.nq,) or not np.all(np.isfinite(q0)):
        return False
    depth = -np.asarray(model.distances(q0[None]), float)[0]
    deep = np.flatnonzero(depth > tolerance)
    if not deep.size:
        return False
    seen = _WARNED_INITIAL.setdefault(model, set())
    key = q0.tobytes()
    if key in seen:
        return False
    seen.add(key)
    labels = None
    if scene is not None:
        try:
            labels = candidate_labels(scene)
        except (RuntimeError, ValueError):
            labels = None
        if labels is not None and len(labels) != len(model.contacts):
            labels = None
    lines = []
    for i in deep[np.argsort(-depth[deep])]:
        c = model.contacts[i]
        entry = "" if labels is None else f"{labels[i]}: "
        if isinstance(c, PointContact):
            point = ", ".join(f"{x:g}" for x in c.p_BC)
            what = f"candidate {i} ({entry}body {c.body!r}, point [{point}], radius {c.radius:g} m)"
        else:
            what = f"candidate {i} ({entry}pair {c.body_a!r}-{c.body_b!r})"
        lines.append(f"  {what}: {depth[i]:.4g} m deep")
    warnings.warn(
        f"{where}: the initial state has {deep.size} contact candidate(s) below their surface "
        f"by more than {tolerance:g} m:\n" + "\n".join(lines) + "\nThe first step pushes them "
        "out within one step, with an impulse no contact produces (and calls the step "
        "converged): start from a state above the ground (the scene's initial_state).",
        InitialPenetrationWarning,
        stacklevel=stacklevel + 1,
    )
    return True
