"""Scene descriptions: which models, which contacts, which time step and smoothing (pure data,
loadable from YAML). A scene models only what it declares: the complementarity plant built from
it contains exactly its contact candidates, and no others.

Load a shipped scene by name and a scene file by path, from any working directory::

    Scene.load("box_push")                                  # see shipped_scenes()
    Scene.load("package://drake_abs/scenes/box_push.yaml")  # the same file, by package URI
    Scene.load("/path/to/my_scene.yaml")

Example (YAML)::

    name: box_push
    time_step: 0.01
    models:
      - file: package://drake_abs/models/box_planar.sdf
    contacts:
      - body: box
        points: [[-0.2, 0, -0.1], [0.2, 0, -0.1]]
        friction: 0.5
    friction_directions: 2          # planar scene: +-x only
    # or from collision geometry:  contacts: [{body: box, geometry: collision, friction: 0.5}]
    # and body-body pairs:         pairs: [{a: pusher, b: box, friction: 0.3}]
    activation_distance: 0.1        # m; farther contacts are left out of the step's LCP
    smoothing: {kind: contact_aware, mu_max: 1.0e-3, length: 0.02}
    initial_state: {q: [0, 0.1, 0], v: [1.0, 0, 0]}

The keys, each with its form and meaning, are those of :class:`Scene` and of its entries:
:class:`~drake_abs.multibody.scene_entries.ModelSpec`,
:class:`~drake_abs.multibody.scene_entries.ContactSpec`,
:class:`~drake_abs.multibody.scene_entries.PairSpec`, :class:`InitialState` and the kinds of
smoothing. Each key is stated once, as a field of these dataclasses (its annotation, its default,
and :func:`~drake_abs.multibody.scene_entries.key`'s form and explanation).

The contact law is a union by kind too (``compliance``: ``{kind: hard}``, the default, or
``{kind: mujoco, solref: [0.02, 1], solimp: [...], margin: ...}`` or ``{kind: mujoco,
from_model: true}``: MuJoCo's soft contact, :mod:`drake_abs.contact.compliance`).

Smoothing is a union by kind: :class:`ExactSmoothing` | :class:`FixedSmoothing` |
:class:`ContactAwareSmoothing` | :class:`GaussianMatchedSmoothing`. A file writes it as a plain
mapping whose ``kind`` names the member (``{kind: fixed, value: 1.0e-4}``; no ``kind``: exact), as
do :meth:`Scene.from_dict`, :meth:`Scene.to_dict` and the constructor (which also takes the
member itself). At the boundary to Drake's reader, ``kind`` becomes the YAML tag that selects the
union's member (``!FixedSmoothing {value: 1.0e-4}``); scene files themselves carry no tags.

How a scene is read, whatever made it (a file, :meth:`Scene.from_dict`, the constructor):

1. its values are checked against the fields' annotations (known and required keys, text,
   numbers, lists and their lengths, allowed values): a ``ValueError`` names the key (such as
   ``contacts[0].points[1]``) and the expected form, and for a file the file and the line;
2. Drake's ``yaml_load_typed`` reads them into the typed dataclasses (mutable twins of these,
   made from their fields, which Drake's reader fills in; tuples become lists there);
3. the frozen :class:`Scene` holds the result and checks what types cannot say (ranges,
   finiteness, points or geometry, the smoothing's parameters).

Step 1 is stricter than Drake's reader, which would take the text ``'0.01'`` for a number, and
its messages name the key and the line. Root keys of a file that start with ``_`` are ignored
(for YAML anchors). Model files are named by ``package://`` URIs or paths (see
:mod:`drake_abs.multibody.packages`).
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import numbers
import re
import types
import typing
import weakref
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import yaml
from pydrake.common.yaml import yaml_dump, yaml_load_typed

from drake_abs.contact.compliance import check_solimp, check_solref
from drake_abs.contact.contact_lcp import FORMULATIONS
from drake_abs.contact.smoothing import (
    ContactAware,
    Exact,
    Fixed,
    GaussianMatched,
    Smoothing,
    TimeStepScaled,
)
from drake_abs.multibody.contacts import contact_candidates
from drake_abs.multibody.packages import PACKAGE_DIR, model_file_problem, resolve_package_file
from drake_abs.multibody.scene_entries import (
    ContactSpec,
    HardCompliance,
    ModelSpec,
    MujocoCompliance,
    PairSpec,
    documented,
    is_required,
    key,
)

#: The folder of the scenes shipped with the package.
SCENES_DIR = PACKAGE_DIR / "scenes"


def shipped_scenes() -> list[str]:
    """The names of the scenes shipped with the package (``Scene.load(name)``)."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.yaml"))


#: The rigid-body dynamics providers a scene can name (see ``Scene.dynamics``).
DYNAMICS = ("auto", "pinocchio", "drake")


# ---------------------------------------------------------------------------------------------
# smoothing: a union by kind


@dataclass(frozen=True)
class _Smoothing:
    """What every kind of smoothing has: its ``kind`` (the name a file gives), the
    :class:`~drake_abs.contact.smoothing.Smoothing` it builds, and the time step mu is stated
    at."""

    kind: ClassVar[str]
    smoothing_type: ClassVar[type[Smoothing]]

    reference_time_step: float | None = key(
        "a number > 0: the time step mu is stated at (s), or null",
        "Default: the scene's ``time_step``. At another ``time_step`` mu is multiplied by "
        "``time_step / reference_time_step`` "
        "(:class:`~drake_abs.contact.smoothing.TimeStepScaled`), so that a resting body's "
        "barrier gap and the barrier's force law stay those of the reference step (mu is an "
        "impulse times a distance, m N s: at a fixed mu the rest gap grows like 1 / h). Not for "
        "``gaussian_matched``",
        default=None,
        kw_only=True,
    )

    def build(self) -> Smoothing:
        """The smoothing, at the reference time step (``ValueError`` for parameters it
        refuses)."""
        own = {f.name: getattr(self, f.name) for f in fields(self)}
        del own["reference_time_step"]
        return self.smoothing_type(**own)


@documented
@dataclass(frozen=True)
class ExactSmoothing(_Smoothing):
    """``kind: exact``, the default: hard contact (:class:`~drake_abs.contact.smoothing.Exact`)."""

    kind = "exact"
    smoothing_type = Exact


@documented
@dataclass(frozen=True)
class FixedSmoothing(_Smoothing):
    """``kind: fixed``: the same mu for every contact
    (:class:`~drake_abs.contact.smoothing.Fixed`); larger is smoother."""

    kind = "fixed"
    smoothing_type = Fixed

    value: float = key("a number >= 0: mu of kind fixed (m N s)")


@documented
@dataclass(frozen=True)
class ContactAwareSmoothing(_Smoothing):
    """``kind: contact_aware``: mu from the distance of the nearest inactive contact
    (:class:`~drake_abs.contact.smoothing.ContactAware`)."""

    kind = "contact_aware"
    smoothing_type = ContactAware

    mu_max: float = key("a number > 0: contact_aware's mu at contact (m N s)")
    length: float = key("a number > 0: contact_aware's decay length (m)")
    mu_min: float = key("a number >= 0: contact_aware's mu far away (m N s)", default=0.0)


@documented
@dataclass(frozen=True)
class GaussianMatchedSmoothing(_Smoothing):
    """``kind: gaussian_matched``: per-contact mu matched to Gaussian randomised smoothing
    (:class:`~drake_abs.contact.smoothing.GaussianMatched`); a larger sigma is smoother."""

    kind = "gaussian_matched"
    smoothing_type = GaussianMatched

    sigma: float = key("a number > 0: gaussian_matched's noise scale (m)")
    c1: float = key("a number: gaussian_matched's c1", default=0.0)
    c2: float = key("a number: gaussian_matched's c2", default=0.0)


#: The smoothing of a scene, a union by kind (the type of :attr:`Scene.smoothing`).
SmoothingSpec = ExactSmoothing | FixedSmoothing | ContactAwareSmoothing | GaussianMatchedSmoothing

#: The kinds of smoothing a scene names, by ``kind``.
SMOOTHING_KINDS: dict[str, type[_Smoothing]] = {k.kind: k for k in typing.get_args(SmoothingSpec)}

#: The contact compliance of a scene, a union by kind (the type of :attr:`Scene.compliance`):
#: hard (the default) or MuJoCo's soft contact.
ComplianceSpec = HardCompliance | MujocoCompliance

#: The kinds of contact compliance a scene names, by ``kind``.
COMPLIANCE_KINDS: dict[str, type] = {k.kind: k for k in typing.get_args(ComplianceSpec)}


@documented
@dataclass(frozen=True)
class InitialState:
    """A scene's initial state; a part left out is the plant's default (positions from the
    model files, at rest)."""

    q: tuple[float, ...] | None = key("a list of numbers: the positions (m, rad)", default=None)
    v: tuple[float, ...] | None = key(
        "a list of numbers: the velocities (m/s, rad/s)", default=None
    )


# ---------------------------------------------------------------------------------------------
# the scene


@documented
@dataclass(frozen=True)
class Scene:
    """A complementarity scene. Made from a file (:meth:`load`, :meth:`from_yaml`), from plain
    data (:meth:`from_dict`) or by the constructor, whose entries may be plain mappings too
    (``smoothing={"kind": "fixed", "value": 1e-4}``); every value is checked, numbers stored as
    floats and lists as tuples (see the module docstring). ``ValueError`` names the key."""

    name: str = key("the scene's name (text)")
    models: tuple[ModelSpec, ...] = key(
        "a list of model entries, each {file: package://<package>/<path>, ...}",
        "The model files (:class:`~drake_abs.multibody.scene_entries.ModelSpec`); one at least",
        item="a model entry: a mapping {file: ..., name: ..., weld: ..., ...}",
    )
    contacts: tuple[ContactSpec, ...] = key(
        "a list of contact entries, each {body: ..., points: [[x, y, z], ...], ...}",
        "The contact candidates against the ground "
        "(:class:`~drake_abs.multibody.scene_entries.ContactSpec`). The step's plant has "
        "exactly the contacts and pairs listed, and no others; one at least",
        default=(),
        item="a contact entry: a mapping {body: ..., points: [[x, y, z], ...], radius: ..., "
        "friction: ...} or {body: ..., geometry: collision, friction: ...}",
    )
    pairs: tuple[PairSpec, ...] = key(
        "a list of pair entries, each {a: <body>, b: <body>, friction: ...}",
        "The body-body contact candidates (:class:`~drake_abs.multibody.scene_entries.PairSpec`)",
        default=(),
        item="a pair entry: a mapping {a: <body>, b: <body>, friction: ...}",
    )
    time_step: float = key("a number > 0: the time step (s)", "The step h", default=0.01)
    friction_directions: int = key(
        "an integer >= 2: tangent directions per frictional contact",
        "k; 2 for planar scenes (+-x only)",
        default=4,
    )
    ground_normal: tuple[float, float, float] = key(
        "[nx, ny, nz]: 3 numbers, not all zero",
        "The ground is the half-space ``n . p >= ground_height``",
        default=(0.0, 0.0, 1.0),
    )
    ground_height: float = key("a number: the ground's height (m)", default=0.0)
    activation_distance: float = key(
        "a number > 0 (m), or .inf for none",
        "Contacts whose distance exceeds this are left out of a step's LCP. Under exact contact "
        "this changes nothing; under smoothing it drops their force at a distance (about "
        "mu / distance each) and, for ContactAware, their say in mu",
        default=float("inf"),
    )
    smoothing: SmoothingSpec = key(
        f"a mapping {{kind: one of {sorted(SMOOTHING_KINDS)}, <the kind's parameters>}}",
        "The smoothing (:meth:`make_smoothing`), a member of the union named by "
        "``kind``: :class:`ExactSmoothing` (the default, and when ``kind`` is left out), "
        ":class:`FixedSmoothing`, :class:`ContactAwareSmoothing` or "
        ":class:`GaussianMatchedSmoothing`, each with its parameters; larger mu is smoother",
        default=ExactSmoothing(),
    )
    compliance: ComplianceSpec = key(
        f"a mapping {{kind: one of {sorted(COMPLIANCE_KINDS)}, <the kind's parameters>}}",
        "The contact law: :class:`~drake_abs.multibody.scene_entries.HardCompliance` (``kind: "
        "hard``, the default, and when ``kind`` is left out: rigid contact) or "
        ":class:`~drake_abs.multibody.scene_entries.MujocoCompliance` (``kind: mujoco``: "
        "MuJoCo's soft contact from solref, solimp and margin, or the MJCF file's with "
        "``from_model: true``; a larger timeconst is softer)",
        default=HardCompliance(),
    )
    initial_state: InitialState = key(
        "a mapping {q: [...], v: [...]}",
        "The initial state (:class:`InitialState`; default: the plant's default state)",
        default=InitialState(),
    )
    dynamics: str = key(
        f"one of {list(DYNAMICS)}",
        "Who evaluates M, the bias terms, the contact Jacobians and their derivatives: "
        '``"pinocchio"`` (analytic derivatives; revolute, prismatic and weld joints, which '
        'includes this package\'s floating bases), ``"drake"`` (the MultibodyPlant itself, '
        'AutoDiffXd for derivatives; any joint), or ``"auto"`` (pinocchio where it applies). '
        "Both give the same numbers (tested); pinocchio is much faster",
        default="auto",
        choices=DYNAMICS,
    )
    friction_model: str = key(
        f"one of {list(FORMULATIONS)}",
        '``"stewart_trinkle"`` (the papers\' linearised-cone LCP; exact Coulomb friction, but '
        'not monotone: under smoothing its solves can fail) or ``"anitescu"`` (the convex '
        "relaxation: a monotone LCP that converges under every smoothing; a sliding contact "
        "lifts off at ``friction x |v_t|``). See "
        ":class:`drake_abs.contact.contact_lcp.FrictionCone` and docs/math.md section 6b",
        default="stewart_trinkle",
        choices=FORMULATIONS,
    )
    joint_springs: str = key(
        'one of ["implicit", "explicit"]',
        "How the step takes the models' joint springs (an MJCF joint's ``stiffness``, an SDF "
        "joint's ``spring_stiffness``): ``\"implicit\"`` at the step's end, like the damping "
        "(stable at any time step; it removes some of an oscillation's energy each step), or "
        '``"explicit"`` at its start, as MuJoCo\'s default Euler integrator does (the same '
        "step as MuJoCo's; stable while h^2 K / M < 4). See :mod:`drake_abs.contact.damping`",
        default="implicit",
        choices=("implicit", "explicit"),
    )

    def __post_init__(self):
        where = f"scene {self.name!r}" if isinstance(self.name, str) else "scene"
        try:
            self._read()
            self._check_values()
        except _Problem as problem:
            raise ValueError(f"{where}: {problem.message}") from problem

    def _read(self) -> None:
        """Check every value against its annotation, read them all with Drake's
        ``yaml_load_typed`` and hold the result (steps 1 and 2 of the module docstring)."""
        hints = _hints(Scene)
        plain = {f.name: _plain(getattr(self, f.name), hints[f.name], f.name, f.metadata)
                 for f in fields(Scene)}  # fmt: skip
        typed = yaml_load_typed(
            schema=_SceneFile,
            data=yaml_dump(plain),
            allow_yaml_with_no_schema=False,
            allow_schema_with_no_yaml=False,
            retain_map_defaults=False,
        )
        for f in fields(Scene):
            object.__setattr__(self, f.name, _frozen(getattr(typed, f.name), hints[f.name]))

    def _check_values(self) -> None:
        """``_Problem`` for a value its type allows and the scene does not."""
        if not self.models:
            raise _Problem("models", "models must list at least one model file")
        if not self.contacts and not self.pairs:
            raise _Problem("contacts", "contacts or pairs must list at least one candidate")
        if not (np.isfinite(self.time_step) and self.time_step > 0):
            raise _Problem("time_step", f"time_step must be a number > 0 (s); got {self.time_step}")
        k = self.friction_directions
        if k < 2:
            raise _Problem(
                "friction_directions", f"friction_directions must be an integer >= 2; got {k}"
            )
        if not self.activation_distance > 0:
            raise _Problem(
                "activation_distance",
                "activation_distance must be a number > 0 (m; .inf for none); got "
                f"{self.activation_distance}",
            )
        for i, c in enumerate(self.pairs):
            if c.friction is not None and not (np.isfinite(c.friction) and c.friction >= 0):
                at = f"pairs[{i}].friction"
                raise _Problem(
                    at,
                    f"{at} must be a finite number >= 0 or null (pair {c.a!r}-{c.b!r}); got "
                    f"{c.friction!r}",
                )
        for i, c in enumerate(self.contacts):
            at = f"contacts[{i}]"
            if c.geometry is not None and (c.points or c.radius != 0.0):
                raise _Problem(
                    at, f"{at} (body {c.body!r}): give points (and radius) or geometry, not both"
                )
            if c.geometry is None and not c.points:
                raise _Problem(
                    at,
                    f"{at} (body {c.body!r}) lists no points (or geometry): give points, a list "
                    "of [x, y, z] (m, in the body's frame), or geometry: collision",
                )
            for j, p in enumerate(c.points):
                if not np.all(np.isfinite(p)):
                    point = f"{at}.points[{j}]"
                    raise _Problem(
                        point,
                        f"{point} must be 3 finite coordinates [x, y, z] in m (body "
                        f"{c.body!r}); got {list(p)}",
                    )
            if not (np.isfinite(c.radius) and c.radius >= 0):
                raise _Problem(
                    f"{at}.radius",
                    f"{at}.radius must be a finite number >= 0 (m; body {c.body!r}); got "
                    f"{c.radius!r}",
                )
            if c.friction is not None and not (np.isfinite(c.friction) and c.friction >= 0):
                raise _Problem(
                    f"{at}.friction",
                    f"{at}.friction must be a finite number >= 0 or null (body {c.body!r}); "
                    f"got {c.friction!r}",
                )
        if not np.isfinite(self.ground_height):
            raise _Problem(
                "ground_height", f"ground_height must be finite (m); got {self.ground_height}"
            )
        n = np.asarray(self.ground_normal)
        if not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-12:
            raise _Problem(
                "ground_normal",
                f"ground_normal must be 3 finite numbers, not all zero; got {list(n)}",
            )
        for part in ("q", "v"):
            values = getattr(self.initial_state, part)
            if values is not None and not np.all(np.isfinite(values)):
                at = f"initial_state.{part}"
                raise _Problem(at, f"{at} must be a list of finite numbers")
        self._built_smoothing()  # its parameters checked now, not at the first step
        self._check_compliance()

    def _check_compliance(self) -> None:
        """``_Problem`` for a soft-contact parameter out of its range."""
        spec = self.compliance
        if not isinstance(spec, MujocoCompliance):
            return
        for name, check in (("solref", check_solref), ("solimp", check_solimp)):
            value = getattr(spec, name)
            if value is not None:
                try:
                    check(np.array([value], dtype=float), f"compliance.{name}")
                except ValueError as err:
                    raise _Problem(f"compliance.{name}", str(err)) from None
        if spec.margin is not None and not (np.isfinite(spec.margin) and spec.margin >= 0):
            raise _Problem(
                "compliance.margin",
                f"compliance.margin must be a finite number >= 0 (m); got {spec.margin!r}",
            )
        if spec.impratio is not None and not (np.isfinite(spec.impratio) and spec.impratio > 0):
            raise _Problem(
                "compliance.impratio",
                f"compliance.impratio must be a finite number > 0; got {spec.impratio!r}",
            )

    def make_smoothing(self) -> Smoothing:
        """The smoothing object this scene names, at this scene's time step: when the
        smoothing states a ``reference_time_step`` other than ``time_step``, the named smoothing
        wrapped in :class:`~drake_abs.contact.smoothing.TimeStepScaled` (mu times
        ``time_step / reference_time_step``)."""
        try:
            return self._built_smoothing()
        except _Problem as problem:
            raise ValueError(f"scene {self.name!r}: {problem.message}") from problem

    def _built_smoothing(self) -> Smoothing:
        spec = self.smoothing
        try:
            smoothing = spec.build()
        except ValueError as err:
            raise _Problem("smoothing", f"smoothing: {err}") from err
        reference = spec.reference_time_step
        if reference is None:
            return smoothing
        at = "smoothing.reference_time_step"
        if not (np.isfinite(reference) and reference > 0):
            raise _Problem(at, f"{at} must be a finite number > 0 (s); got {reference!r}")
        if isinstance(spec, GaussianMatchedSmoothing):
            raise _Problem(at, f"{at} does not apply to gaussian_matched (its impulse does not "
                           "scale with mu; choose sigma for the time step)")  # fmt: skip
        return TimeStepScaled.between(smoothing, self.time_step, reference)

    @property
    def num_contacts(self) -> int:
        """The number of contact candidates, counting the listed points and (read from the model
        files) those of the ``geometry`` entries and of the pairs."""
        if not self.pairs and all(c.geometry is None for c in self.contacts):
            return sum(len(c.points) for c in self.contacts)
        where = f"scene {self.name!r}"
        return len(contact_candidates(where, self.models, self.contacts, self.pairs))

    def locate(self, key: str = "") -> str:
        """Where ``key`` of this scene is (``"contacts[0].body"``; ``""``: the scene itself), to
        start an error found after loading (a body a model file does not have, a missing model
        file): the scene file and the key's line (or the nearest enclosing key's) for a scene
        read from YAML, as the loader's own errors name them; else ``scene '<name>'``."""
        source = _SOURCES.get(id(self))
        if source is None or source[0]() is not self:
            return f"scene {self.name!r}"
        return _at(source[1], source[2], key)

    def to_dict(self) -> dict[str, Any]:
        """The scene as plain data, as a scene file writes it (mappings, lists, numbers, text,
        null; the smoothing named by ``kind``): ``Scene.from_dict(scene.to_dict()) == scene``."""
        hints = _hints(Scene)
        return {f.name: _plain(getattr(self, f.name), hints[f.name], f.name, f.metadata,
                               tags=False) for f in fields(Scene)}  # fmt: skip

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Scene:
        """A scene from plain data (mappings, lists or tuples, numbers, text, as YAML gives),
        read as a scene file is (see the module docstring); ``ValueError`` naming the scene, the
        key and the expected form."""
        name = data.get("name") if isinstance(data, Mapping) else None
        return _load(data, f"scene {name!r}" if isinstance(name, str) else "scene")

    @classmethod
    def load(cls, name: str | Path) -> Scene:
        """A scene, from any working directory: a shipped scene by name (e.g. ``"box_push"``,
        see :func:`shipped_scenes`), a scene file by ``package://`` URI
        (``"package://drake_abs/scenes/box_push.yaml"``) or a scene YAML file by path
        (absolute, or relative to the working directory)."""
        text = str(name)
        if text.startswith("package://"):
            return cls._from_file(resolve_package_file(text, what="scene file"), text)
        path = Path(name)
        if path.suffix in (".yaml", ".yml"):
            if not path.is_file():
                hint = ""
                if path.stem in shipped_scenes():
                    hint = (
                        f"; the shipped scene loads from any directory as Scene.load({path.stem!r})"
                    )
                raise FileNotFoundError(
                    f"scene file {text!r} not found (looked at {path.absolute()}){hint}"
                )
            return cls._from_file(path, text)
        shipped = SCENES_DIR / f"{name}.yaml"
        if not shipped.is_file():
            close = difflib.get_close_matches(text, shipped_scenes(), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ValueError(
                f"no shipped scene {text!r}{hint}: give a YAML path, a package:// URI or one "
                f"of {shipped_scenes()}"
            )
        return cls._from_file(shipped, f"shipped scene {text!r} ({shipped})")

    @classmethod
    def from_yaml(cls, source: str | Path) -> Scene:
        """Load from a YAML file path (a ``Path``, or a string ending in ``.yaml`` or
        ``.yml``) or a YAML string; see the module docstring for the format. Errors are
        ``ValueError`` naming the file (or "scene YAML text"), the line, the key and the
        expected form."""
        is_path = isinstance(source, Path) or (
            "\n" not in source and Path(source).suffix in (".yaml", ".yml")
        )
        if is_path:
            return cls._from_file(Path(source), str(source))
        return _load_yaml(source, "scene YAML text")

    @classmethod
    def _from_file(cls, path: Path, label: str) -> Scene:
        return _load_yaml(path.read_text(), label)

    def to_yaml(self) -> str:
        """The scene as a scene file (YAML text): ``Scene.from_yaml(scene.to_yaml()) == scene``."""
        return yaml.safe_dump(self.to_dict(), sort_keys=False)


# ---------------------------------------------------------------------------------------------
# reading: plain data checked against the annotations (with errors naming the key), read by
# Drake's yaml_load_typed into mutable twins of the dataclasses, held by the frozen ones


class _Problem(Exception):
    """A value the scene refuses: ``key`` (``"contacts[0].points[1]"``; ``""``: the scene
    itself) and the message, which names it; a file's loader adds the file and the key's line."""

    def __init__(self, key: str, message: str):
        super().__init__(message)
        self.key = key
        self.message = message


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    """The annotations of a dataclass's fields, evaluated (this module postpones them)."""
    return typing.get_type_hints(cls)


def _optional_of(hint: Any) -> Any:
    """``X`` for ``X | None``, else None."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is type(None):
            return args[0]
    return None


def _is_union(hint: Any) -> bool:
    return typing.get_origin(hint) in (typing.Union, types.UnionType)


def _default(f: dataclasses.Field) -> Any:
    return f.default if f.default_factory is dataclasses.MISSING else f.default_factory()


def _is_number(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _is_integer(value) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _is_sequence(value) -> bool:
    return isinstance(value, list | tuple) or (isinstance(value, np.ndarray) and value.ndim == 1)


_SCALARS = {
    bool: (lambda v: isinstance(v, bool), bool),
    str: (lambda v: isinstance(v, str), str),
    float: (_is_number, float),
    int: (_is_integer, int),
}


def _plain(value: Any, hint: Any, key: str, meta: Mapping[str, Any], *, tags: bool = True):
    """``value`` (plain data as YAML gives it, or the typed value) checked against the
    annotation ``hint``, as plain data: lists, floats, integers, text, null and mappings, a
    member of a union by kind as a mapping tagged with its class (``tags``, for Drake's reader)
    or with its ``kind``. ``_Problem`` naming ``key`` and the expected form (``meta["form"]``)
    otherwise."""
    form = meta["form"]
    inner = _optional_of(hint)
    if inner is not None:
        if value is None:
            return None
        hint = inner
    if _is_union(hint):
        return _plain_kind(value, typing.get_args(hint), key, form, tags)
    if dataclasses.is_dataclass(hint):
        return _plain_entry(value, hint, key, form, tags)
    if typing.get_origin(hint) is tuple:
        args = typing.get_args(hint)
        item, size = args[0], (None if args[-1] is Ellipsis else len(args))
        choices = meta.get("choices")
        if (
            not _is_sequence(value)
            or (size is not None and len(value) != size)
            or (item is float and not all(_is_number(x) for x in value))
            or (choices is not None and not all(isinstance(x, str) and x in choices for x in value))
        ):
            raise _Problem(key, f"{key} must be {form}; got {_describe(value)}")
        each = {"form": meta["item"], "choices": None, "item": None}
        return [_plain(x, item, f"{key}[{j}]", each, tags=tags) for j, x in enumerate(value)]
    ok, make = _SCALARS[hint]
    choices = meta.get("choices")
    if not ok(value) or (choices is not None and value not in choices):
        raise _Problem(key, f"{key} must be {form}; got {_describe(value)}")
    return make(value)


def _given(value: Any, names: list[str], key: str, form: str) -> dict[str, Any]:
    """The mapping ``value`` of keys among ``names``; ``_Problem`` for another value or an
    unknown key (naming the closest known one)."""
    what = key or "a scene"
    if not isinstance(value, Mapping):
        raise _Problem(key, f"{what} must be {form}; got {_describe(value)}")
    for name in value:
        if name not in names:
            child = f"{key}.{name}" if key else str(name)
            close = difflib.get_close_matches(str(name), names, n=1)
            hint = f" (did you mean {(f'{key}.' if key else '') + close[0]!r}?)" if close else ""
            raise _Problem(
                child, f"unknown key {child!r}{hint}; {what} takes the keys {', '.join(names)}"
            )
    return dict(value)


def _check_required(given: Mapping[str, Any], cls: type, key: str) -> None:
    """``_Problem`` for a required key of the dataclass ``cls`` that ``given`` lacks."""
    for f in fields(cls):
        if is_required(f) and f.name not in given:
            child = f"{key}.{f.name}" if key else f.name
            what = key or "a scene"
            raise _Problem(key, f"{child} is missing: {what} needs it, as {f.metadata['form']}")


def _plain_entry(value: Any, cls: type, key: str, form: str, tags: bool) -> dict[str, Any]:
    """A dataclass's value (an instance, or a mapping of its keys) as a plain mapping of every
    key (those left out at their defaults)."""
    if isinstance(value, cls):
        given = {f.name: getattr(value, f.name) for f in fields(cls)}
    else:
        given = _given(value, [f.name for f in fields(cls)], key, form)
    _check_required(given, cls, key)
    hints, out = _hints(cls), {}
    for f in fields(cls):
        child = f"{key}.{f.name}" if key else f.name
        item = given[f.name] if f.name in given else _default(f)
        out[f.name] = _plain(item, hints[f.name], child, f.metadata, tags=tags)
    return out


def _plain_kind(value: Any, members: tuple[type, ...], key: str, form: str, tags: bool):
    """A member of a union by kind (an instance, or a mapping ``{kind: ..., <its keys>}``) as a
    plain mapping: tagged ``!<class>`` (``tags``) or with its ``kind``; the parameters of
    another kind are refused naming the kind's own."""
    names = {m: [f.name for f in fields(m)] for m in members}
    common = [n for n in names[members[0]] if all(n in names[m] for m in members)]
    own = {m: [n for n in names[m] if n not in common] for m in members}
    if isinstance(value, members):
        member, given = type(value), {f.name: getattr(value, f.name) for f in fields(value)}
    else:
        known = ["kind", *dict.fromkeys(n for m in members for n in own[m]), *common]
        given = _given(value, known, key, form)
        kinds = {m.kind: m for m in members}
        kind = given.pop("kind", members[0].kind)
        if not isinstance(kind, str) or kind not in kinds:
            raise _Problem(f"{key}.kind", f"{key}.kind must be one of {sorted(kinds)}; got "
                           f"{_describe(kind)}")  # fmt: skip
        member = kinds[kind]
        if any(name not in names[member] for name in given):
            parameters = {k: v for k, v in given.items() if k not in common}
            raise _Problem(
                key,
                f"{key}: bad {key} parameters {parameters} for kind {kind!r}, which takes "
                f"{own[member] or 'none'}" + (f" (and {', '.join(common)})" if common else ""),
            )
    plain = _plain_entry(given, member, key, form, tags)
    head = {"_tag": f"!{_reading_schema(member).__name__}"} if tags else {"kind": member.kind}
    return head | {n: plain[n] for n in own[member] + common}


@functools.cache
def _reading_schema(hint: Any) -> Any:
    """The type Drake's ``yaml_load_typed`` reads for the annotation ``hint``: a dataclass's
    mutable twin (``<name>File``, every field with a default: Drake's reader makes an empty one
    and sets its fields; a union's member is selected by the tag ``!<name>File``), lists for
    tuples, and the same unions of the twins."""
    inner = _optional_of(hint)
    if inner is not None:
        return typing.Optional[_reading_schema(inner)]  # noqa: UP045 (a typing object to hold)
    if _is_union(hint):
        return typing.Union[tuple(_reading_schema(m) for m in typing.get_args(hint))]  # noqa: UP007
    if typing.get_origin(hint) is tuple:
        return list[_reading_schema(typing.get_args(hint)[0])]
    if not dataclasses.is_dataclass(hint):
        return hint
    twin = []
    for f in fields(hint):
        read = _reading_schema(_hints(hint)[f.name])
        empty = (dataclasses.field(default_factory=read) if dataclasses.is_dataclass(read)
                 else dataclasses.field(default=None))  # fmt: skip
        twin.append((f.name, read, empty))
    doc = f"What Drake's reader fills in for a :class:`{hint.__name__}`."
    return dataclasses.make_dataclass(
        f"{hint.__name__}File", twin, namespace={"__doc__": doc}, module=__name__
    )


def _frozen(value: Any, hint: Any) -> Any:
    """What Drake's reader made (``value``, of :func:`_reading_schema` ``(hint)``) as the
    annotation ``hint`` has it: frozen dataclasses, tuples."""
    inner = _optional_of(hint)
    if inner is not None:
        return None if value is None else _frozen(value, inner)
    if _is_union(hint):
        (member,) = [m for m in typing.get_args(hint) if _reading_schema(m) is type(value)]
        return _frozen(value, member)
    if dataclasses.is_dataclass(hint):
        hints = _hints(hint)
        return hint(**{f.name: _frozen(getattr(value, f.name), hints[f.name])
                       for f in fields(hint)})  # fmt: skip
    if typing.get_origin(hint) is tuple:
        return tuple(_frozen(x, typing.get_args(hint)[0]) for x in value)
    return value


#: The schema Drake's ``yaml_load_typed`` reads a scene into: the mutable twin of :class:`Scene`
#: (made from its fields; lists for tuples, every field with a default), which the frozen Scene
#: is then made from.
_SceneFile = _reading_schema(Scene)


def _describe(value) -> str:
    """A value as the message shows it: what YAML made of it."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"{str(value).lower()} (a boolean)"
    if isinstance(value, str):
        return f"{value!r} (text)"
    if isinstance(value, Mapping):
        return f"a mapping {_shorten(dict(value))}"
    if _is_sequence(value):
        return f"a list of {len(value)}: {_shorten(list(value))}"
    return repr(value)


def _shorten(value, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


# ---------------------------------------------------------------------------------------------
# loading: plain data (from YAML, with the line of each key) made a Scene


def _load(data: Any, label: str, lines: Mapping[str, int] | None = None) -> Scene:
    """The Scene of plain ``data``: its keys checked, made (every value checked and read, see
    the module docstring), its model files' packages checked. ``ValueError`` starting with
    ``label`` and the key's line in ``lines``."""
    try:
        names = [f.name for f in fields(Scene)]
        given = _given(data, names, "", "a mapping {name: ..., models: [...], ...}")
        _check_required(given, Scene, "")
        try:
            scene = Scene(**given)
        except ValueError as err:
            if isinstance(err.__cause__, _Problem):
                raise err.__cause__ from None
            raise
        for i, model in enumerate(scene.models):
            problem = model_file_problem(model.file)
            if problem is not None:
                raise _Problem(f"models[{i}].file", f"models[{i}].file: {problem}")
        if lines is not None:  # read from YAML: later errors name the file and line (locate)
            _remember_source(scene, label, lines)
        return scene
    except _Problem as problem:
        raise ValueError(f"{_at(label, lines or {}, problem.key)}: {problem.message}") from None


#: Where each scene read from YAML came from, by the scene's id: (a weak reference to it, the
#: file's label, the line of each key). Kept outside the scene (its fields are its data, and
#: equal scenes from different files stay equal); an entry goes with its scene.
_SOURCES: dict[int, tuple[weakref.ref, str, dict[str, int]]] = {}


def _remember_source(scene: Scene, label: str, lines: Mapping[str, int]) -> None:
    """Hold where ``scene`` was read from, for :meth:`Scene.locate`."""
    key = id(scene)
    ref = weakref.ref(scene, lambda _, key=key: _SOURCES.pop(key, None))
    _SOURCES[key] = (ref, label, dict(lines))


def _at(label: str, lines: Mapping[str, int], key: str) -> str:
    """``label`` with the line of ``key`` (or of the nearest enclosing key known)."""
    while key:
        if key in lines:
            return f"{label}, line {lines[key]}"
        key = re.sub(r"(\.[^.\[]+|\[\d+\])$", "", key) if re.search(r"[.\[]", key) else ""
    return label


def _load_yaml(text: str, label: str) -> Scene:
    """A Scene from YAML ``text`` (syntax errors name the line, other errors the key's line)."""
    data, lines = _read_yaml(text, label)
    if isinstance(data, Mapping):  # root keys starting with "_" are ignored (YAML anchors)
        data = {k: v for k, v in data.items() if not (isinstance(k, str) and k.startswith("_"))}
    return _load(data, label, lines)


class _SceneLoader(yaml.SafeLoader):
    """YAML's safe loader, except that exponent-only numbers such as ``1e-3`` are numbers (as in
    YAML 1.2; PyYAML follows YAML 1.1 and reads them as strings, which the type checks would
    reject)."""


_SceneLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)

_COLLECTION_TAGS = ("tag:yaml.org,2002:map", "tag:yaml.org,2002:seq")


def _read_yaml(text: str, label: str) -> tuple[Any, dict[str, int]]:
    """The plain data of YAML ``text`` and the line of each key (``"contacts[0].points"``);
    ``ValueError`` naming ``label`` and the line for a syntax error, a duplicate key, a tag or a
    key that is not text."""
    loader = _SceneLoader(text)
    lines: dict[str, int] = {}

    def read(node, key: str):
        lines.setdefault(key, node.start_mark.line + 1)
        if not isinstance(node, yaml.ScalarNode) and node.tag not in _COLLECTION_TAGS:
            raise ValueError(
                f"{label}, line {node.start_mark.line + 1}: {key or 'the scene'} has the YAML "
                f"tag {node.tag!r}; scene files use plain mappings and lists"
            )
        if isinstance(node, yaml.MappingNode):
            loader.flatten_mapping(node)  # YAML merge keys (<<: *anchor)
            out = {}
            for key_node, value_node in node.value:
                name = loader.construct_object(key_node, deep=True)
                line = key_node.start_mark.line + 1
                if not isinstance(name, str):
                    raise ValueError(f"{label}, line {line}: the key {name!r} is not text")
                child = f"{key}.{name}" if key else name
                if name in out:
                    raise ValueError(
                        f"{label}, line {line}: {child} is given twice (also at line "
                        f"{lines[child]})"
                    )
                lines[child] = line
                out[name] = read(value_node, child)
            return out
        if isinstance(node, yaml.SequenceNode):
            return [read(item, f"{key}[{i}]") for i, item in enumerate(node.value)]
        return loader.construct_object(node, deep=True)

    try:
        node = loader.get_single_node()
        return (None if node is None else read(node, "")), lines
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        where = f"{label}, line {mark.line + 1}, column {mark.column + 1}" if mark else label
        what = ": ".join(x for x in (err.context, err.problem) if x)
        raise ValueError(f"{where}: not valid YAML: {what}") from None
    except yaml.YAMLError as err:
        raise ValueError(f"{label}: not valid YAML: {err}") from None
    finally:
        loader.dispose()
