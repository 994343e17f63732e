"""A scene's contact candidates: its ``contacts`` and ``pairs`` entries expanded into the
candidates the step evaluates
(:func:`~drake_abs.multibody.contacts.contact_candidates`).

Listed points stay as they are; a ``geometry: collision`` entry and a pair are expanded from the
bodies' collision shapes, read from a plant built with a SceneGraph for the purpose (the step's
own plant has none); see :mod:`drake_abs.multibody.geometry_contacts` for the closed forms.
"""

from __future__ import annotations

from collections.abc import Sequence

from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from drake_abs.multibody.drake_dynamics import PointContact
from drake_abs.multibody.geometry_contacts import PairContact, Shape, ground_points, shape_of
from drake_abs.multibody.parsing import add_model_specs
from drake_abs.multibody.scene_entries import ContactSpec, ModelSpec, PairSpec


def contact_candidates(
    where: str,
    models: Sequence[ModelSpec],
    contacts: Sequence[ContactSpec],
    pairs: Sequence[PairSpec] = (),
) -> list[PointContact | PairContact]:
    """The contact candidates of a scene's ``contacts`` and ``pairs`` (its ``models`` hold the
    bodies), in its order: each ``contacts`` entry's listed points, or its body's collision
    shapes as exact point candidates against the ground (``geometry: collision``), then each
    ``pairs`` entry's unfiltered pairs of collision shapes. ``where`` (``"scene 'box_push'"``)
    starts every error message."""
    needs_geometry = pairs or any(c.geometry is not None for c in contacts)
    shapes = _CollisionShapes(where, models) if needs_geometry else None
    out: list[PointContact | PairContact] = []
    for c in contacts:
        if c.geometry is None:
            out.extend(PointContact(c.body, tuple(p), c.radius, c.friction, c.model)
                       for p in c.points)  # fmt: skip
            continue
        for _, shape in shapes.of(c.body, c.model):
            out.extend(PointContact(c.body, p, radius, c.friction, c.model)
                       for p, radius in ground_points(shape))  # fmt: skip
    for pair in pairs:
        found = [
            PairContact(
                pair.a, shape_a, pair.b, shape_b, pair.friction, pair.model_a, pair.model_b
            )  # fmt: skip
            for id_a, shape_a in shapes.of(pair.a, pair.model_a)
            for id_b, shape_b in shapes.of(pair.b, pair.model_b)
            if not shapes.inspector.CollisionFiltered(id_a, id_b)
        ]
        if not found:
            raise ValueError(
                f"{where}: pair {pair.a!r}-{pair.b!r}: the model's collision filters exclude "
                "every pair of their collision shapes"
            )
        out.extend(found)
    return out


class _CollisionShapes:
    """The collision shapes of a scene's bodies (a plant and SceneGraph parsed for them)."""

    def __init__(self, where: str, models: Sequence[ModelSpec]):
        self.where = where
        self._builder = DiagramBuilder()
        self.plant, scene_graph = AddMultibodyPlantSceneGraph(self._builder, 0.0)
        add_model_specs(self.plant, models, where, collisions=True)
        self.plant.Finalize()
        self.inspector = scene_graph.model_inspector()

    def of(self, body_name: str, model: str | None) -> list[tuple[object, Shape]]:
        """``[(geometry id, Shape)]`` of a body's collision geometry; ``ValueError`` for a body
        without any, or with a shape other than a sphere, capsule or box."""
        plant, where = self.plant, f"{self.where}: body {body_name!r}"
        instance = plant.GetModelInstanceByName(model) if model else None
        body = (plant.GetBodyByName(body_name, instance) if instance is not None
                else plant.GetBodyByName(body_name))  # fmt: skip
        out = []
        for gid in plant.GetCollisionGeometriesForBody(body):
            found = shape_of(self.inspector, gid)
            if found is None:
                raise ValueError(
                    f"{where}: collision shape {type(self.inspector.GetShape(gid)).__name__} "
                    f"({self.inspector.GetName(gid)!r}) is not supported; spheres, capsules and "
                    "boxes are (or list the body's contact points)"
                )
            X_BG = self.inspector.GetPoseInFrame(gid)
            R = tuple(tuple(float(x) for x in row) for row in X_BG.rotation().matrix())
            out.append((gid, Shape(found[0], found[1], tuple(X_BG.translation()), R)))
        if not out:
            raise ValueError(f"{where} has no collision geometry in its model file")
        return out
