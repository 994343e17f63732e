"""Scenes re-built with one model parameter moved: the central-difference references of the
model-parameter derivatives (a step's in tests/multibody, a whole rollout's in tests/engine)."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from drake_abs.multibody import Scene
from drake_abs.multibody.parsing import resolve_model_file


def contact_state(name: str, model) -> tuple[np.ndarray, np.ndarray]:
    """A state in contact and an input, per scene (none at a contact-mode switch): the states
    the model-parameter derivatives are checked at."""
    cm = model.contact_model
    x = model.x0.copy()
    if name == "box_push":  # on its two bottom corners, sliding at 1 m/s, pushed
        return x, np.full(cm.nu, 3.0)
    if name == "hopper":  # pitched, hip bent, foot landing within the step: the foot sticks
        x[2], x[3], x[cm.nq + 1] = 0.2, -0.3, -6.0
        return x, np.array([4.0, -3.0])
    if name == "gym_hopper":  # falling onto its foot, legs moving, torques applied
        x[cm.nq : cm.nq + 2] = [1.0, -4.0]
        x[cm.nq + 3 :] = [1.0, -2.0, 3.0]
        return x, np.array([30.0, -50.0, 20.0])
    # ball_throw: just above the ground, moving down and sideways (sliding)
    x[6], x[10], x[11], x[12] = 0.0505, 3.0, 1.0, -0.6
    return x, np.zeros(cm.nu)


def with_mass(scene: Scene, body: str, factor: float, folder: Path) -> Scene:
    """The scene with ``body``'s mass and rotational inertia scaled by ``factor`` (centre of
    mass and unit inertia held, as Drake's ``RigidBody::SetMass``), through a re-written SDF or
    URDF (elements ``<mass>0.2</mass>``, or attributes ``<mass value="0.2"/>``)."""
    spec = scene.models[0]
    source = resolve_model_file(spec)
    text = source.read_text()
    link = re.search(rf'<link name="{body}">.*?</inertial>', text, flags=re.S)
    if source.suffix == ".urdf":
        scaled = re.sub(
            r'\b(value|ixx|iyy|izz|ixy|ixz|iyz)="([^"]+)"',
            lambda m: f'{m.group(1)}="{float(m.group(2)) * factor!r}"',
            link.group(0),
        )
    else:
        scaled = re.sub(
            r"<(mass|ixx|iyy|izz|ixy|ixz|iyz)>([^<]+)</\1>",
            lambda m: f"<{m.group(1)}>{float(m.group(2)) * factor!r}</{m.group(1)}>",
            link.group(0),
        )
    assert scaled != link.group(0) or factor == 1.0, f"no mass found for {body!r} in {source}"
    path = folder / f"{body}_{factor!r}{source.suffix}"
    path.write_text(text[: link.start()] + scaled + text[link.end() :])
    return replace(scene, models=(replace(spec, file=str(path)),))


def with_friction(scene: Scene, k: int, delta: float) -> Scene:
    """The scene with contact spec k's friction coefficient moved by delta."""
    contacts = list(scene.contacts)
    contacts[k] = replace(contacts[k], friction=contacts[k].friction + delta)
    return replace(scene, contacts=tuple(contacts))


def with_joint_damping(scene: Scene, joint: str, value: float, folder: Path) -> Scene:
    """The scene with ``joint``'s viscous damping set to ``value`` (N m s / rad or N s / m)
    through a re-written model file: an MJCF ``<joint name="..." .../>`` gets its ``damping``
    attribute (replaced where the file gives one), an SDF ``<joint name="...">`` a
    ``<dynamics><damping>`` element in its ``<axis>``."""
    spec = scene.models[0]
    source = resolve_model_file(spec)
    text = source.read_text()
    value = float(value)
    if source.suffix == ".xml":
        element = re.search(rf'<joint\b[^>]*\bname="{joint}"[^>]*/>', text)
        old = element.group(0)
        new = re.sub(r'\sdamping="[^"]*"', "", old)
        new = new.replace("<joint", f'<joint damping="{value!r}"', 1)
    else:
        element = re.search(rf'<joint name="{joint}".*?</joint>', text, flags=re.S)
        old = element.group(0)
        assert "<dynamics>" not in old, f"joint {joint!r} already has dynamics in {source}"
        new = old.replace("<axis>", f"<axis><dynamics><damping>{value!r}</damping></dynamics>", 1)
    assert new != old, f"joint {joint!r} not found in {source}"
    path = folder / f"{joint}_damping_{value!r}{source.suffix}"
    path.write_text(text[: element.start()] + new + text[element.end() :])
    return replace(scene, models=(replace(spec, file=str(path)),))


def with_inertia(
    scene: Scene, body: str, mass: float, unit_inertia, folder: Path, com=None
) -> Scene:
    """The scene with ``body``'s mass (kg) and unit rotational inertia about its centre of mass
    (m^2; the entries xx, yy, zz, xy, xz, yz of the matrix, in the body frame) set, its centre
    of mass kept, through a re-written model file: an SDF link's ``<mass>`` and ``<inertia>``
    elements or a URDF link's ``mass`` and ``inertia`` attributes (its inertial frame must not
    be rotated); an MJCF body gets an ``<inertial>`` element at ``com`` (m, body frame: the
    file's geoms give it, so the caller does) and the compiler ``inertiafromgeom="auto"``, so
    that the other bodies keep the inertia of their geoms."""
    spec = scene.models[0]
    source = resolve_model_file(spec)
    text = source.read_text()
    mass = float(mass)
    inertia = dict(zip(("ixx", "iyy", "izz", "ixy", "ixz", "iyz"),
                       (mass * float(g) for g in unit_inertia), strict=True))  # fmt: skip
    if source.suffix == ".xml":
        assert com is not None, "an MJCF body's centre of mass comes from its geoms: pass com"
        body_tag = re.search(rf'<body\b[^>]*\bname="{body}"[^>]*>', text)
        assert body_tag is not None, f"no body {body!r} in {source}"
        assert "<inertial" not in text, f"{source} already has <inertial> elements"
        element = (
            f'<inertial pos="{" ".join(repr(float(x)) for x in com)}" mass="{mass!r}" '
            f'fullinertia="{" ".join(repr(x) for x in inertia.values())}"/>'
        )
        new = text[: body_tag.end()] + element + text[body_tag.end() :]
        compiler = re.sub(r'inertiafromgeom="[^"]*"', 'inertiafromgeom="auto"', new)
        assert compiler != new or "inertiafromgeom" not in new
        new = compiler
    else:
        link = re.search(rf'<link name="{body}">.*?</inertial>', text, flags=re.S)
        assert link is not None, f"no inertial for {body!r} in {source}"
        old = link.group(0)
        rotated = re.search(r'rpy="([^"]+)"', old) or re.search(r"<pose>([^<]+)</pose>", old)
        if rotated is not None:
            angles = [float(a) for a in rotated.group(1).split()][-3:]
            assert not any(angles), f"{body!r}: a rotated inertial frame in {source}"
        if source.suffix == ".urdf":
            scaled = re.sub(r'(<mass\s+value=)"[^"]+"', rf'\1"{mass!r}"', old)
            for key, value in inertia.items():
                scaled = re.sub(rf'\b{key}="[^"]+"', f'{key}="{value!r}"', scaled)
        else:
            scaled = re.sub(r"<mass>[^<]+</mass>", f"<mass>{mass!r}</mass>", old)
            for key, value in inertia.items():
                scaled = re.sub(rf"<{key}>[^<]+</{key}>", f"<{key}>{value!r}</{key}>", scaled)
        new = text[: link.start()] + scaled + text[link.end() :]
    path = folder / f"{body}_inertia_{abs(hash((mass, *inertia.values()))):x}{source.suffix}"
    path.write_text(new)
    return replace(scene, models=(replace(spec, file=str(path)),))
