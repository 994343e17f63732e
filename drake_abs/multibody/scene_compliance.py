"""A scene's soft contact: the :class:`~drake_abs.contact.compliance.ContactCompliance` of its
contact candidates, from the scene's ``compliance`` entry (``{kind: mujoco, ...}``) and, with
``from_model``, the MJCF files' geoms (:mod:`drake_abs.multibody.mjcf_contact_parameters`).

Each candidate needs, besides solref, solimp and margin, MuJoCo's approximation ``A_hat`` of
its row's diagonal of ``J M^-1 J^T`` (1/kg): the sum of its two bodies' translational inverse
weights (the ground's is 0). A body's is computed as MuJoCo's compiler does, at the model's
reference pose (the plant's default positions, which for an MJCF file are MuJoCo's qpos0): with
``J`` the translational Jacobian (3, nv) of the body's centre of mass in the world and ``M`` the
mass matrix, the mean of the diagonal of ``J M^-1 J^T`` (a body whose value is 0 but which can
rotate takes the rotational one instead; a body welded to the world has 0).
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable

from drake_abs.contact.compliance import (
    DEFAULT_SOLIMP,
    DEFAULT_SOLREF,
    MIN_VALUE,
    ContactCompliance,
)
from drake_abs.multibody.drake_dynamics import ContactModelBase
from drake_abs.multibody.geometry_contacts import PairContact
from drake_abs.multibody.mjcf_contact_parameters import (
    ContactParameters,
    MjcfContactInfo,
    mixed,
    read_geom_contacts,
)
from drake_abs.multibody.parsing import resolve_model_file
from drake_abs.multibody.scene import MujocoCompliance, Scene


def body_inverse_weights(plant, bodies) -> np.ndarray:
    """The translational inverse weight (1/kg) of each body of ``bodies`` (Drake bodies of
    ``plant``) at the plant's default positions (the module docstring)."""
    context = plant.CreateDefaultContext()
    W = np.linalg.inv(plant.CalcMassMatrix(context))
    world = plant.world_frame()
    out = np.zeros(len(bodies))
    for i, body in enumerate(bodies):
        if body.index() == plant.world_body().index():
            continue
        com = body.CalcCenterOfMassInBodyFrame(context) if body.default_mass() > 0 else np.zeros(3)
        Jt = plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kV, body.body_frame(), com, world, world
        )
        Jr = plant.CalcJacobianAngularVelocity(
            context, JacobianWrtVariable.kV, body.body_frame(), world, world
        )
        tran = np.trace(Jt @ W @ Jt.T) / 3
        rot = np.trace(Jr @ W @ Jr.T) / 3
        out[i] = rot if (tran < MIN_VALUE and rot > MIN_VALUE) else tran
    return out


def _bodies(plant, contact) -> list:
    """The Drake bodies of a candidate (one for a point against the ground, two for a pair)."""

    def body(name, model):
        if model:
            return plant.GetBodyByName(name, plant.GetModelInstanceByName(model))
        return plant.GetBodyByName(name)

    if isinstance(contact, PairContact):
        return [body(contact.body_a, contact.model_a), body(contact.body_b, contact.model_b)]
    return [body(contact.body, contact.model_instance)]


def _file_parameters(scene: Scene, contacts) -> tuple[list[ContactParameters], float]:
    """Each candidate's contact parameters from the scene's MJCF files, and their impratio."""
    infos: list[MjcfContactInfo] = []
    for i, spec in enumerate(scene.models):
        key = f"models[{i}].file"
        path = resolve_model_file(spec, f"{scene.locate(key)}: {key}")
        if path.suffix == ".xml":
            infos.append(read_geom_contacts(path))
    if not infos:
        raise ValueError(
            f"scene {scene.name!r}: compliance.from_model reads MuJoCo (MJCF, .xml) model files; "
            "the scene has none: state solref, solimp and margin instead"
        )

    def info_of(body: str) -> MjcfContactInfo:
        holders = [info for info in infos if body in info.bodies]
        if len(holders) != 1:
            raise ValueError(
                f"scene {scene.name!r}: compliance.from_model needs body {body!r} in exactly "
                f"one MJCF file's collision geoms; found it in {len(holders)}"
            )
        return holders[0]

    params = []
    for c in contacts:
        if isinstance(c, PairContact):
            a, b = info_of(c.body_a), info_of(c.body_b)
            params.append(mixed(a.body_geom(c.body_a), b.body_geom(c.body_b)))
        else:
            info = info_of(c.body)
            params.append(mixed(info.body_geom(c.body), info.ground()))
    impratios = {info.impratio for info in infos}
    if len(impratios) != 1:
        raise ValueError(
            f"scene {scene.name!r}: the MJCF files give different impratios {sorted(impratios)}"
        )
    return params, impratios.pop()


def scene_compliance(scene: Scene, model: ContactModelBase) -> ContactCompliance | None:
    """The soft contact the scene's ``compliance`` entry names for the candidates of ``model``
    (the scene's contact model), or None for hard contact (``kind: hard``, the default)."""
    spec = scene.compliance
    if not isinstance(spec, MujocoCompliance):
        return None
    contacts = model.contacts
    n = len(contacts)
    weights = np.array([body_inverse_weights(model.plant, _bodies(model.plant, c)).sum()
                        for c in contacts])  # fmt: skip
    frictional = np.array([c.friction is not None for c in contacts])
    if spec.from_model:
        params, impratio = _file_parameters(scene, contacts)
        solref = np.array([p.solref for p in params])
        solimp = np.array([p.solimp for p in params])
        margin = np.array([p.margin for p in params])
        condim = np.array([p.condim for p in params])
        if np.any(~np.isin(condim, (1, 3))):
            raise ValueError(
                f"scene {scene.name!r}: compliance.from_model: the MJCF contacts' condim must be "
                f"1 or 3 (sliding friction; torsional and rolling are not modelled); got "
                f"{sorted(set(condim.tolist()))}"
            )
    else:
        solref = np.tile(DEFAULT_SOLREF, (n, 1))
        solimp = np.tile(DEFAULT_SOLIMP, (n, 1))
        margin = np.zeros(n)
        condim = np.where(frictional, 3, 1)
        impratio = 1.0
    if spec.solref is not None:
        solref = np.tile(spec.solref, (n, 1))
    if spec.solimp is not None:
        solimp = np.tile(spec.solimp, (n, 1))
    if spec.margin is not None:
        margin = np.full(n, spec.margin)
    if spec.impratio is not None:
        impratio = spec.impratio
    if np.any(weights <= 0):
        bad = [i for i in range(n) if weights[i] <= 0]
        raise ValueError(
            f"scene {scene.name!r}: contact candidates {bad} have no inverse weight (bodies "
            "welded to the world?): soft contact needs bodies that move"
        )
    condim = np.where(frictional, condim, 1)
    return ContactCompliance(solref, solimp, margin, weights, condim, impratio, spec.refsafe)
