"""The entries of a scene's lists (``models``, ``contacts``, ``pairs``) and the two helpers
that state each key of a scene once.

``models`` holds :class:`ModelSpec` entries, ``contacts`` :class:`ContactSpec` entries and
``pairs`` :class:`PairSpec` entries.

A key is a dataclass field made by :func:`key`: its type is the annotation, its default the
field's, and its metadata says how its value is written (``form``: quoted by the error message
of a wrong value) and what it means (``doc``). :func:`documented` renders every key of a class
into the class's docstring, which the API reference shows; :mod:`drake_abs.multibody.scene`
checks and reads scene files against the same fields.
"""

from __future__ import annotations

import inspect
from dataclasses import MISSING, dataclass, field, fields
from typing import Any

from drake_abs.multibody.model_files import IGNORABLE


def key(
    form: str,
    doc: str = "",
    *,
    default: Any = MISSING,
    factory: Any = MISSING,
    item: str | None = None,
    choices: tuple[str, ...] | None = None,
    kw_only: bool = False,
) -> Any:
    """A key of a scene file: a dataclass field (``dataclasses.field``) with its explanation.

    Args:
        form: how the value is written, such as ``"a number > 0: the time step (s)"`` (error
            messages say "<key> must be <form>").
        doc: what the key means, beyond its form (reStructuredText).
        default, factory: the value when the key is left out; neither: the key is required.
        item: for a list, the form of one entry.
        choices: the values a text (or each entry of a list of text) may take.
        kw_only: a keyword-only field (a field of a base class, before required ones).
    """
    metadata = {"form": form, "doc": doc, "item": item, "choices": choices}
    return field(default=default, default_factory=factory, metadata=metadata, kw_only=kw_only)


def is_required(f) -> bool:
    """Whether the field ``f`` (made by :func:`key`) has no default."""
    return f.default is MISSING and f.default_factory is MISSING


def documented(cls: type) -> type:
    """The dataclass ``cls`` with its keys (made by :func:`key`) listed in its docstring, each
    with its form and meaning (an ``Attributes`` section, which the API reference renders)."""
    lines = [inspect.cleandoc(cls.__doc__ or ""), "", "Attributes:"]
    for f in fields(cls):
        sentences = [f.metadata["form"], f.metadata["doc"], "Required" if is_required(f) else ""]
        lines.append(f"    {f.name}: {'. '.join(s for s in sentences if s)}.")
    cls.__doc__ = "\n".join(lines)
    return cls


_OPTIONAL_TEXT = "a string or null"
_FRICTION = "a number >= 0: the Coulomb friction coefficient, or null for frictionless contact"

#: The coordinates ``ModelSpec.floating_base`` may give a free root body.
FLOATING_BASES = ("euler", "quaternion")


@documented
@dataclass(frozen=True)
class ModelSpec:
    """One model file of a scene (an entry of ``models``)."""

    file: str = key(
        "a model file: package://<package>/<path> (packages: drake_abs, example-robot-data, "
        "<robot>_description, gymnasium) or a path on disk",
        'URDF, SDF or MJCF, used as published (docs/howto/own_robot.md, "Model files as '
        'published"); a path on disk is absolute or relative to the working directory. '
        "Packages and the older prefixes: :mod:`drake_abs.multibody.packages`",
    )
    name: str | None = key(
        f"{_OPTIONAL_TEXT}: the model instance's name", "Default: the file's", default=None
    )
    weld: str | None = key(
        f"{_OPTIONAL_TEXT}: the name of a frame of the model, welded to the world",
        "Welded at the origin (a fixed base). Without it the model's root body floats: "
        "q = (x, y, z, yaw, pitch, roll), v their rates (a chain of joints, "
        ":func:`~drake_abs.multibody.parsing.add_floating_base_chains`). The root body's pose "
        "in the file (an SDF ``<pose>``, an MJCF body's ``pos``/``quat``, a URDF ``floating`` "
        "joint's ``<origin>``) is its default pose: the scene's initial q when "
        "``initial_state`` gives none",
        default=None,
    )
    actuate: tuple[str, ...] = key(
        "a list of joint names (text), each given an actuator",
        "For URDFs without ``<transmission>`` tags",
        default=(),
        item="a joint name (text)",
    )
    keyframe: str | None = key(
        f"{_OPTIONAL_TEXT}: the name of a <key> of the MuJoCo file's <keyframe>",
        "MuJoCo files (``.xml``) only: the key's qpos gives the default joint positions "
        '(unnamed keys by index, ``"0"``)',
        default=None,
    )
    ignore: tuple[str, ...] = key(
        f"a list of some of {list(IGNORABLE)} (attributes to drop)",
        "MuJoCo files only: the file's attributes the step does not model "
        "(:data:`drake_abs.multibody.model_files.IGNORABLE`) that may be dropped; a file that "
        "has them is refused otherwise",
        default=(),
        choices=IGNORABLE,
    )
    floating_base: str = key(
        f"one of {list(FLOATING_BASES)}: the coordinates of a free root body",
        '``"euler"``: a chain of joints, q = (x, y, z, yaw, pitch, roll), v their rates '
        '(singular at pitch = +-pi/2); ``"quaternion"``: a quaternion floating joint named by '
        "the body, q = (qw, qx, qy, qz, x, y, z), v = (angular, translational velocity) in the "
        "world, no singular orientation (:mod:`drake_abs.multibody.floating`). A URDF "
        "``floating`` joint is a quaternion joint either way",
        default="euler",
        choices=FLOATING_BASES,
    )


#: Where ``ContactSpec.geometry`` may take a body's contact candidates from.
GEOMETRY_SOURCES = ("collision",)


@documented
@dataclass(frozen=True)
class ContactSpec:
    """Contact candidates on one body against the ground (an entry of ``contacts``): listed
    ``points``, or the body's collision shapes (``geometry``)."""

    body: str = key("a body's name (text)")
    points: tuple[tuple[float, float, float], ...] = key(
        "a list of points [x, y, z] (m, in the body's frame)",
        "Each a sphere of ``radius``",
        default=(),
        item="a point [x, y, z]: 3 numbers (m, in the body's frame)",
    )
    radius: float = key("a number >= 0: the sphere radius at each point (m)", default=0.0)
    friction: float | None = key(_FRICTION, default=None)
    model: str | None = key(
        f"{_OPTIONAL_TEXT}: the body's model instance", "When its name is not unique", default=None
    )
    geometry: str | None = key(
        f"one of {list(GEOMETRY_SOURCES)} (the body's collision shapes), or null",
        "Instead of ``points``: the body's collision shapes in its model file as exact point "
        "candidates (spheres: their centre and radius; capsules: their two end-cap centres and "
        "radius; boxes: their 8 vertices; see :mod:`drake_abs.multibody.geometry_contacts`)",
        default=None,
        choices=GEOMETRY_SOURCES,
    )


@documented
@dataclass(frozen=True)
class PairSpec:
    """Body-body contact candidates (an entry of ``pairs``): every pair of collision shapes of
    bodies ``a`` and ``b`` (from their model files) that the model's collision filters leave in,
    evaluated in closed form (sphere-sphere, sphere-box, sphere-capsule; see
    :mod:`drake_abs.multibody.geometry_contacts`). Only ``dynamics: drake`` (or ``auto``, which
    then uses Drake) evaluates pairs."""

    a: str = key("a body's name (text)")
    b: str = key("a body's name (text)")
    friction: float | None = key(_FRICTION, default=None)
    model_a: str | None = key(
        f"{_OPTIONAL_TEXT}: body a's model instance", "When its name is not unique", default=None
    )
    model_b: str | None = key(
        f"{_OPTIONAL_TEXT}: body b's model instance", "When its name is not unique", default=None
    )


@documented
@dataclass(frozen=True)
class HardCompliance:
    """``kind: hard``, the default: rigid contact (the hard complementarity step: no
    penetration, no regulariser)."""

    kind = "hard"


_SOLREF = "[timeconst, dampratio] (s, both > 0) or [-stiffness, -damping] (both <= 0), or null"
_SOLIMP = "[d0, dwidth, width, midpoint, power] (d0, dwidth, midpoint in [0, 1]; m; >= 1), or null"


@documented
@dataclass(frozen=True)
class MujocoCompliance:
    """``kind: mujoco``: MuJoCo's soft contact (solref, solimp, margin) as a regularised
    complementarity problem (:mod:`drake_abs.contact.compliance`): each contact candidate acts
    within its margin as a damped spring whose time constant is ``solref``'s and whose strength
    is the impedance ``solimp`` gives; the step may end with a contact below the ground. A
    larger timeconst and a smaller impedance are softer. Joint limits stay hard."""

    kind = "mujoco"

    from_model: bool = key(
        "true or false",
        "true: each candidate's solref, solimp, margin (the geoms' margins minus gaps) and "
        "condim from its body's geom and the ground plane in the scene's MJCF file, mixed by "
        "MuJoCo's rule (:mod:`drake_abs.multibody.mjcf_contact_parameters`), and the file's "
        "impratio; the keys given below replace the file's",
        default=False,
    )
    solref: tuple[float, float] | None = key(
        _SOLREF, "Default: the file's (from_model) or MuJoCo's [0.02, 1]", default=None,
        item="a number",
    )  # fmt: skip
    solimp: tuple[float, float, float, float, float] | None = key(
        _SOLIMP, "Default: the file's (from_model) or MuJoCo's [0.9, 0.95, 0.001, 0.5, 2]",
        default=None, item="a number",
    )  # fmt: skip
    margin: float | None = key(
        "a number >= 0 (m), or null",
        "A candidate has rows while its distance is below this. Default: the file's "
        "(from_model) or 0",
        default=None,
    )
    impratio: float | None = key(
        "a number > 0, or null", "MuJoCo's impratio. Default: the file's (from_model) or 1",
        default=None,
    )  # fmt: skip
    refsafe: bool = key(
        "true or false", "Raise timeconst to twice the time step, as MuJoCo does by default",
        default=True,
    )  # fmt: skip
