"""The contact parameters an MJCF file gives its geoms (``solref``, ``solimp``, ``margin``,
``gap``, ``condim``, ``friction``, ``solmix``, ``priority``) and MuJoCo's rule for the
parameters of a contact between two geoms, for the soft-contact option
(:mod:`drake_abs.contact.compliance`, ``compliance: {kind: mujoco, from_model: true}``).

A geom's attribute is its own, or its default class's (the class named by ``class``, else the
nearest ``childclass`` of its bodies, else ``main``), or MuJoCo's built-in default. The
parameters of a contact between geoms a and b (MuJoCo's documentation, "Modeling: contact
parameters"): when one has the larger ``priority``, its ``condim``, ``friction``, ``solref``
and ``solimp``; otherwise the larger ``condim`` and friction, and ``solref``, ``solimp``
averaged with the weights ``solmix_a / (solmix_a + solmix_b)`` and its complement (0.5 each
when both are below 1e-15). ``margin`` and ``gap`` are the sums of the two geoms'; the contact
exists while its distance is below ``margin - gap``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from drake_abs.contact.compliance import DEFAULT_SOLIMP, DEFAULT_SOLREF, MIN_VALUE
from drake_abs.multibody.model_files import MjcfDefaults

#: MuJoCo's built-in geom defaults of these attributes
GEOM_DEFAULTS = {
    "solref": DEFAULT_SOLREF,
    "solimp": DEFAULT_SOLIMP,
    "margin": (0.0,),
    "gap": (0.0,),
    "condim": (3.0,),
    "friction": (1.0, 0.005, 0.0001),
    "solmix": (1.0,),
    "priority": (0.0,),
}


@dataclass(frozen=True)
class GeomContact:
    """A geom's contact parameters: ``solref`` (2,), ``solimp`` (5,), ``margin`` and ``gap``
    (m), ``condim``, ``friction`` (sliding, torsional, rolling), ``solmix``, ``priority``."""

    name: str
    solref: tuple[float, float]
    solimp: tuple[float, float, float, float, float]
    margin: float
    gap: float
    condim: int
    friction: tuple[float, float, float]
    solmix: float
    priority: int

    def parameters(self) -> tuple:
        """What a contact takes from this geom (every field but the name)."""
        return (self.solref, self.solimp, self.margin, self.gap, self.condim, self.friction,
                self.solmix, self.priority)  # fmt: skip


@dataclass(frozen=True)
class ContactParameters:
    """The parameters of a contact between two geoms (MuJoCo's rule, the module docstring):
    ``solref`` (2,), ``solimp`` (5,), ``margin`` (m: the contact's ``margin - gap``, the
    distance below which it exists), ``condim`` and the sliding ``friction``."""

    solref: tuple[float, float]
    solimp: tuple[float, ...]
    margin: float
    condim: int
    friction: float


@dataclass(frozen=True)
class MjcfContactInfo:
    """What :func:`read_geom_contacts` read: the geoms of each body, by body name (the
    world's under ``"world"``), and ``<option impratio>``."""

    bodies: dict[str, tuple[GeomContact, ...]]
    impratio: float
    path: str

    def ground(self) -> GeomContact:
        """The world's plane geom (the ground); ValueError unless there is exactly one."""
        planes = [g for g in self.bodies.get("world", ()) if g.name.startswith("plane:")]
        if len(planes) != 1:
            raise ValueError(
                f"{self.path}: the ground is the world body's one plane geom; found {len(planes)}"
            )
        return planes[0]

    def body_geom(self, body: str) -> GeomContact:
        """The contact parameters of ``body``'s geoms (ValueError when it has none, or several
        with different parameters: then the candidate's are ambiguous)."""
        geoms = self.bodies.get(body, ())
        if not geoms:
            raise ValueError(f"{self.path}: body {body!r} has no geom that collides")
        if len({g.parameters() for g in geoms}) > 1:
            raise ValueError(
                f"{self.path}: body {body!r} has geoms with different contact parameters "
                f"({', '.join(g.name for g in geoms)}); state the compliance's solref, solimp "
                "and margin in the scene instead"
            )
        return geoms[0]


def _numbers(defaults, element, cls: str, attr: str, where: str) -> tuple[float, ...]:
    text = defaults.get(element, "geom", cls, attr)
    if text is None:
        return tuple(GEOM_DEFAULTS[attr])
    try:
        values = tuple(float(x) for x in text.split())
    except ValueError:
        raise ValueError(f"{where}: {attr} must be numbers; got {text!r}") from None
    default = GEOM_DEFAULTS[attr]
    if attr == "friction" and len(values) < 3:  # unset components keep their defaults
        values = values + tuple(default[len(values) :])
    if attr == "solimp" and 3 <= len(values) < 5:
        values = values + tuple(default[len(values) :])
    if len(values) != len(default):
        raise ValueError(f"{where}: {attr} must be {len(default)} numbers; got {text!r}")
    return values


def read_geom_contacts(path: str | Path) -> MjcfContactInfo:
    """The contact parameters of every geom of the MJCF file at ``path`` that can collide
    (``contype`` or ``conaffinity`` nonzero), by body (a plane's name starts with
    ``"plane:"``)."""
    path = Path(path)
    root = ElementTree.parse(path).getroot()
    if root.tag != "mujoco":
        raise ValueError(f"{path}: an MJCF file has a <mujoco> root element; got <{root.tag}>")
    defaults = MjcfDefaults(root)
    impratio = 1.0
    for option in root.findall("option"):
        if "impratio" in option.attrib:
            impratio = float(option.get("impratio"))
    parents = {child: parent for parent in root.iter() for child in parent}
    bodies: dict[str, list[GeomContact]] = {}
    for world in root.findall("worldbody"):
        for body in [world, *world.iter("body")]:
            name = "world" if body is world else body.get("name")
            childclass, node = None, body
            while node is not None and childclass is None:
                childclass = node.get("childclass")
                node = parents.get(node)
            for k, geom in enumerate(body.findall("geom")):
                cls = geom.get("class") or childclass or "main"
                label = geom.get("name") or f"{name} geom {k}"
                where = f"{path}: geom {label!r}"
                contype = defaults.get(geom, "geom", cls, "contype") or "1"
                conaffinity = defaults.get(geom, "geom", cls, "conaffinity") or "1"
                if int(contype) == 0 and int(conaffinity) == 0:
                    continue
                kind = defaults.get(geom, "geom", cls, "type") or "sphere"
                values = {a: _numbers(defaults, geom, cls, a, where) for a in GEOM_DEFAULTS}
                bodies.setdefault(name, []).append(
                    GeomContact(
                        name=f"plane:{label}" if kind == "plane" else label,
                        solref=values["solref"],
                        solimp=values["solimp"],
                        margin=values["margin"][0],
                        gap=values["gap"][0],
                        condim=int(values["condim"][0]),
                        friction=values["friction"],
                        solmix=values["solmix"][0],
                        priority=int(values["priority"][0]),
                    )
                )
    return MjcfContactInfo({k: tuple(v) for k, v in bodies.items()}, impratio, str(path))


def mixed(a: GeomContact, b: GeomContact) -> ContactParameters:
    """The parameters of a contact between geoms a and b (MuJoCo's rule, the module
    docstring). ValueError for two different direct-form solrefs (negative numbers), whose
    mixing this does not reproduce."""
    margin = a.margin + b.margin - (a.gap + b.gap)
    if a.priority != b.priority:
        first = a if a.priority > b.priority else b
        return ContactParameters(
            first.solref, first.solimp, margin, first.condim, first.friction[0]
        )
    if a.solmix < MIN_VALUE and b.solmix < MIN_VALUE:
        mix = 0.5
    else:
        mix = a.solmix / (a.solmix + b.solmix)
    if a.solref != b.solref and (min(a.solref) <= 0 or min(b.solref) <= 0):
        raise ValueError(
            f"geoms {a.name!r} and {b.name!r} have different direct-form solrefs "
            f"({a.solref}, {b.solref}); state the compliance's solref in the scene"
        )
    solref = tuple(mix * np.asarray(a.solref) + (1 - mix) * np.asarray(b.solref))
    solimp = tuple(mix * np.asarray(a.solimp) + (1 - mix) * np.asarray(b.solimp))
    if a.solref == b.solref:
        solref = a.solref
    if a.solimp == b.solimp:
        solimp = a.solimp
    return ContactParameters(
        tuple(float(x) for x in solref), tuple(float(x) for x in solimp), margin,
        max(a.condim, b.condim), max(a.friction[0], b.friction[0]),
    )  # fmt: skip
