"""Scenes re-built with one model parameter moved: the central-difference references of the
model-parameter derivatives (a step's in tests/multibody, a whole rollout's in tests/engine)."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

from drake_abs.multibody import PACKAGE_DIR, Scene


def with_mass(scene: Scene, body: str, factor: float, folder: Path) -> Scene:
    """The scene with ``body``'s mass and rotational inertia scaled by ``factor`` (centre of
    mass and unit inertia held, as Drake's ``RigidBody::SetMass``), through a re-written SDF."""
    spec = scene.models[0]
    text = (PACKAGE_DIR / spec.file.removeprefix("drake_abs:")).read_text()
    link = re.search(rf'<link name="{body}">.*?</inertial>', text, flags=re.S)
    scaled = re.sub(
        r"<(mass|ixx|iyy|izz|ixy|ixz|iyz)>([^<]+)</\1>",
        lambda m: f"<{m.group(1)}>{float(m.group(2)) * factor!r}</{m.group(1)}>",
        link.group(0),
    )
    path = folder / f"{body}_{factor!r}.sdf"
    path.write_text(text[: link.start()] + scaled + text[link.end() :])
    return replace(scene, models=(replace(spec, file=str(path)),))


def with_friction(scene: Scene, k: int, delta: float) -> Scene:
    """The scene with contact spec k's friction coefficient moved by delta."""
    contacts = list(scene.contacts)
    contacts[k] = replace(contacts[k], friction=contacts[k].friction + delta)
    return replace(scene, contacts=tuple(contacts))
