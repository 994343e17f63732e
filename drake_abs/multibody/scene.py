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

Keys (a file is read against the schema :class:`SceneFile`; ``[x, y, z]`` is a list of three
numbers; lengths are in m, times in s, angles in rad; "text" is a YAML string):

``name`` (required)
    text: the scene's name.
``models`` (required)
    a list of model entries, each a mapping:

    - ``file`` (required): the model file (URDF, SDF or MJCF, used as published: see README,
      "Model files as published"): ``package://<package>/<path>`` (below), or a path on disk
      (absolute, or relative to the working directory).
    - ``name``: text, the model instance's name (default: the file's).
    - ``weld``: text, a frame of the model welded to the world at the origin (default: none,
      the model's root body floats).
    - ``actuate``: a list of joint names (text), each given an actuator (for URDFs without
      ``<transmission>`` tags).
    - ``keyframe`` (MuJoCo files only): text, the name of a ``<keyframe>`` ``<key>`` whose qpos
      gives the default joint positions.
    - ``ignore`` (MuJoCo files only): a list of the file's attributes that may be dropped, some
      of ``joint.stiffness``, ``joint.frictionloss``, ``joint.armature``.
``contacts``
    a list of contact entries against the ground, each a mapping:

    - ``body`` (required): text, the body's name.
    - ``points``: a list of points ``[x, y, z]`` (m, in the body's frame).
    - ``geometry``: ``collision``, instead of ``points``: the body's collision shapes in its
      model file (spheres, capsules, boxes).
    - ``radius``: a number >= 0, the radius of the sphere at each point (m; default 0).
    - ``friction``: a number >= 0, the Coulomb friction coefficient, or ``null`` (the
      default) for frictionless contact.
    - ``model``: text, the body's model instance (when its name is not unique).
``pairs``
    a list of body-body entries, each a mapping: ``a``, ``b`` (required): text, the bodies'
    names; ``friction``: as in ``contacts``; ``model_a``, ``model_b``: text, their model
    instances.
``time_step``
    a number > 0: the step h (s; default 0.01).
``friction_directions``
    an integer >= 2: tangent directions per frictional contact (default 4; 2 for planar
    scenes).
``ground_normal``, ``ground_height``
    ``[nx, ny, nz]``, not all zero (default ``[0, 0, 1]``), and a number (m; default 0): the
    ground is the half-space ``n . p >= height``.
``activation_distance``
    a number > 0: contacts farther than this are left out of a step's LCP (m; default
    ``.inf``: none).
``smoothing``
    a mapping: ``kind``, one of ``exact`` (the default), ``fixed`` (parameter ``value``, mu in
    m N s), ``contact_aware`` (``mu_max``, ``mu_min``: m N s; ``length``: m) or
    ``gaussian_matched`` (``sigma``: m; ``c1``, ``c2``), and optionally
    ``reference_time_step``: a number > 0, the step mu is stated at (s). See
    :attr:`Scene.smoothing`.
``initial_state``
    a mapping ``{q: [...], v: [...]}``: lists of numbers, the plant's positions (m, rad) and
    velocities (m/s, rad/s) (default: the plant's default state).
``dynamics``
    one of ``auto`` (the default), ``pinocchio``, ``drake``.
``friction_model``
    one of ``stewart_trinkle`` (the default), ``anitescu``.

A key the schema does not know, a value of the wrong form or a missing required key is a
``ValueError`` that names the file, its line, the key (such as ``contacts[0].points[1]``) and
the expected form. Root keys starting with ``_`` are ignored (for YAML anchors).

Model files: ``package://<package>/<path>`` is resolved through Drake's ``PackageMap``, with
the packages ``drake_abs`` (this package's folder: ``package://drake_abs/models/<file>``),
``example-robot-data`` (``package://example-robot-data/robots/<robot>_description/...``, the
form the robots' own URDFs use for their meshes; each ``<robot>_description`` is a package
too) and ``gymnasium`` (its MuJoCo model files: ``package://gymnasium/hopper.xml``), the last
two when installed. The prefixes of earlier versions, ``drake_abs:<path>``,
``example-robot-data:<path>`` (under ``robots/``) and ``gymnasium:<file>``, are still read as
aliases of these URIs.
"""

from __future__ import annotations

import difflib
import functools
import numbers
import re
import types
import typing
from collections.abc import Mapping
from dataclasses import MISSING, asdict, dataclass, field, fields, is_dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydrake.common.yaml import yaml_load_typed

from drake_abs.contact.contact_lcp import FORMULATIONS
from drake_abs.contact.smoothing import (
    ContactAware,
    Exact,
    Fixed,
    GaussianMatched,
    SmoothingPolicy,
    TimeStepScaled,
)
from drake_abs.multibody.model_files import IGNORABLE

_SMOOTHING = {
    "exact": Exact,
    "fixed": Fixed,
    "contact_aware": ContactAware,
    "gaussian_matched": GaussianMatched,
}


# ---------------------------------------------------------------------------------------------
# type checks: every wrongly typed value names its key (``where`` is "scene 'name'")


def _is_number(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _number(value, where: str, key: str, unit: str = "", *, optional: bool = False):
    """``value`` as a float, or ``ValueError`` naming ``key`` (booleans and strings are not
    numbers); None stays None when ``optional``."""
    if optional and value is None:
        return None
    if not _is_number(value):
        unit = f" ({unit})" if unit else ""
        null = " or null" if optional else ""
        raise ValueError(f"{where}: {key} must be a number{unit}{null}; got {value!r}")
    return float(value)


def _numbers(value, where: str, key: str, form: str, size: int | None = None) -> tuple:
    """``value`` (a list of numbers, of ``size`` entries if given) as a tuple of floats."""
    ok = isinstance(value, list | tuple | np.ndarray) and (size is None or len(value) == size)
    if ok and isinstance(value, np.ndarray):
        ok = value.ndim == 1
    if not ok or not all(_is_number(x) for x in value):
        raise ValueError(f"{where}: {key} must be a list of {form}; got {value!r}")
    return tuple(float(x) for x in value)


def _text(value, where: str, key: str, form: str, *, optional: bool = False):
    if not (isinstance(value, str) or (optional and value is None)):
        null = " or null" if optional else ""
        raise ValueError(f"{where}: {key} must be a string ({form}){null}; got {value!r}")
    return value


def _mapping(value, where: str, key: str, form: str) -> dict:
    if not isinstance(value, Mapping):
        raise ValueError(f"{where}: {key} must be a mapping ({form}); got {value!r}")
    return dict(value)


class _SceneLoader(yaml.SafeLoader):
    """YAML's safe loader, except that exponent-only numbers such as ``1e-3`` are numbers (as in
    YAML 1.2; PyYAML follows YAML 1.1 and reads them as strings, which the type checks would
    reject)."""


_SceneLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


#: The folder of the scenes shipped with the package.
SCENES_DIR = Path(__file__).resolve().parents[1] / "scenes"


def shipped_scenes() -> list[str]:
    """The names of the scenes shipped with the package (``Scene.load(name)``)."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.yaml"))


#: The rigid-body dynamics providers a scene can name (see ``Scene.dynamics``).
DYNAMICS = ("auto", "pinocchio", "drake")


@dataclass(frozen=True)
class ModelSpec:
    """One model file. ``weld``: a frame of the model welded to the world at the origin (a fixed
    base); otherwise its root body floats: q = (x, y, z, yaw, pitch, roll), v their rates (a
    chain of joints: ``drake_abs.multibody.builder.add_floating_base_chains``).
    ``actuate``: joints to give an actuator (for URDFs without ``<transmission>`` tags).
    The root body's pose in the file (an SDF ``<pose>``, an MJCF body's ``pos``/``quat``, a URDF
    ``floating`` joint's ``<origin>``) is its default pose: the scene's initial q when
    ``initial_state`` gives none.

    MuJoCo files (``.xml``) only: ``keyframe``, the name of a ``<keyframe>`` ``<key>`` whose
    qpos gives the default joint positions (unnamed keys by index, ``"0"``); ``ignore``, the
    file's attributes the step does not model that may be dropped, from
    :data:`drake_abs.multibody.model_files.IGNORABLE` (``joint.stiffness``,
    ``joint.frictionloss``, ``joint.armature``): a file that has them is refused otherwise."""

    file: str
    name: str | None = None
    weld: str | None = None
    actuate: tuple[str, ...] = ()
    keyframe: str | None = None
    ignore: tuple[str, ...] = ()


#: Where ``ContactSpec.geometry`` may take a body's contact candidates from.
GEOMETRY_SOURCES = ("collision",)


@dataclass(frozen=True)
class ContactSpec:
    """Contact candidates on one body against the ground: ``points`` (m, body frame), each a
    sphere of ``radius`` (m; 0 for a point), or ``geometry: collision``: the body's collision
    shapes in its model file, as exact point candidates (spheres: their centre and radius;
    capsules: their two end-cap centres and radius; boxes: their 8 vertices; see
    :mod:`drake_abs.multibody.geometry_contacts`). ``friction`` the Coulomb coefficient, or None
    for frictionless contact."""

    body: str
    points: tuple[tuple[float, float, float], ...] = ()
    radius: float = 0.0
    friction: float | None = None
    model: str | None = None
    geometry: str | None = None


@dataclass(frozen=True)
class PairSpec:
    """Body-body contact candidates: every pair of collision shapes of bodies ``a`` and ``b``
    (from their model files) that the model's collision filters leave in, evaluated in closed
    form (sphere-sphere, sphere-box, sphere-capsule; see
    :mod:`drake_abs.multibody.geometry_contacts`). ``friction`` the Coulomb coefficient (None:
    frictionless); ``model_a``, ``model_b`` the bodies' model instances (None: unique names).
    Only ``dynamics: drake`` (or ``auto``, which then uses Drake) evaluates pairs."""

    a: str
    b: str
    friction: float | None = None
    model_a: str | None = None
    model_b: str | None = None


@dataclass(frozen=True)
class Scene:
    """A complementarity scene.

    Attributes:
        name: identifier.
        models: the model files.
        contacts: the contact candidates against the ground.
        pairs: the body-body contact candidates (:class:`PairSpec`). The step's plant has
            exactly the contacts and pairs listed, and no others.
        time_step: h in s.
        friction_directions: k, tangent directions per frictional contact (2 for planar scenes).
        ground_normal, ground_height: the ground half-space ``n . p >= height``.
        activation_distance: contacts whose distance exceeds this (m) are left out of a step's
            LCP. Under exact contact this changes nothing; under smoothing it drops their force
            at a distance (about mu / distance each) and, for ContactAware, their say in mu.
        smoothing: ``{"kind": "exact" | "fixed" | "contact_aware" | "gaussian_matched", ...}``
            with the policy's parameters; larger mu is smoother. Optional
            ``reference_time_step`` (s): the step mu was stated at (default: ``time_step``).
            At another ``time_step`` mu is multiplied by ``time_step / reference_time_step``
            (:class:`~drake_abs.contact.smoothing.TimeStepScaled`), so that a resting body's
            barrier gap and the barrier's force law stay those of the reference step (mu is an
            impulse times a distance, m N s: at a fixed mu the rest gap grows like 1 / h).
            Not for ``gaussian_matched``.
        initial_state: ``{"q": [...], "v": [...]}`` (defaults: the plant's default state).
        dynamics: who evaluates M, the bias terms, the contact Jacobians and their derivatives:
            ``"pinocchio"`` (analytic derivatives; revolute, prismatic and weld joints, which
            includes this package's floating bases), ``"drake"`` (the MultibodyPlant itself,
            AutoDiffXd for derivatives; any joint), or ``"auto"`` (pinocchio where it applies).
            Both give the same numbers (tested); pinocchio is much faster.
        friction_model: ``"stewart_trinkle"`` (the papers' linearised-cone LCP; exact Coulomb
            friction, but not monotone: under smoothing its solves can fail) or
            ``"anitescu"`` (the convex relaxation: a monotone LCP that converges under every
            smoothing; a sliding contact lifts off at ``friction x |v_t|``). See
            :class:`drake_abs.contact.contact_lcp.FrictionCone` and docs/math.md section 6b.
    """

    name: str
    models: tuple[ModelSpec, ...]
    contacts: tuple[ContactSpec, ...] = ()
    pairs: tuple[PairSpec, ...] = ()
    time_step: float = 0.01
    friction_directions: int = 4
    ground_normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    ground_height: float = 0.0
    activation_distance: float = float("inf")
    smoothing: dict = field(default_factory=lambda: {"kind": "exact"})
    initial_state: dict = field(default_factory=dict)
    dynamics: str = "auto"
    friction_model: str = "stewart_trinkle"

    def __post_init__(self):
        self._check_types()
        if self.friction_model not in FORMULATIONS:
            raise ValueError(
                f"scene {self.name!r}: friction_model must be one of {FORMULATIONS}; got "
                f"{self.friction_model!r}"
            )
        if self.dynamics not in DYNAMICS:
            raise ValueError(
                f"scene {self.name!r}: dynamics must be one of {DYNAMICS}; got {self.dynamics!r}"
            )
        if not self.models:
            raise ValueError(f"scene {self.name!r}: models must list at least one model file")
        if not self.contacts and not self.pairs:
            raise ValueError(
                f"scene {self.name!r}: contacts or pairs must list at least one candidate"
            )
        if not (np.isfinite(self.time_step) and self.time_step > 0):
            raise ValueError(
                f"scene {self.name!r}: time_step must be a number > 0 (s); got {self.time_step}"
            )
        if int(self.friction_directions) < 2:
            raise ValueError(
                f"scene {self.name!r}: friction_directions must be an integer >= 2; got "
                f"{self.friction_directions}"
            )
        if not self.activation_distance > 0:
            raise ValueError(
                f"scene {self.name!r}: activation_distance must be a number > 0 (m; .inf for "
                f"none); got {self.activation_distance}"
            )
        for i, c in enumerate(self.pairs):
            if c.friction is not None and not (np.isfinite(c.friction) and c.friction >= 0):
                raise ValueError(f"scene {self.name!r}: pairs[{i}].friction must be a finite "
                                 f"number >= 0 or null (pair {c.a!r}-{c.b!r}); got "
                                 f"{c.friction!r}")  # fmt: skip
        for i, c in enumerate(self.contacts):
            key = f"contacts[{i}]"
            if c.geometry is not None:
                if c.geometry not in GEOMETRY_SOURCES:
                    raise ValueError(
                        f"scene {self.name!r}: {key}.geometry must be one of "
                        f"{list(GEOMETRY_SOURCES)} (body {c.body!r}); got {c.geometry!r}"
                    )
                if c.points or c.radius != 0.0:
                    raise ValueError(
                        f"scene {self.name!r}: {key} (body {c.body!r}): give points (and "
                        "radius) or geometry, not both"
                    )
            elif not c.points:
                raise ValueError(
                    f"scene {self.name!r}: {key} (body {c.body!r}) lists no points (or "
                    "geometry): give points, a list of [x, y, z] (m, in the body's frame), or "
                    "geometry: collision"
                )
            for j, p in enumerate(c.points):
                if len(p) != 3 or not np.all(np.isfinite(np.asarray(p, float))):
                    raise ValueError(
                        f"scene {self.name!r}: {key}.points[{j}] must be 3 finite coordinates "
                        f"[x, y, z] in m (body {c.body!r}); got {list(p)}"
                    )
            if not (np.isfinite(c.radius) and c.radius >= 0):
                raise ValueError(f"scene {self.name!r}: {key}.radius must be a finite number "
                                 f">= 0 (m; body {c.body!r}); got {c.radius!r}")  # fmt: skip
            if c.friction is not None and not (np.isfinite(c.friction) and c.friction >= 0):
                raise ValueError(f"scene {self.name!r}: {key}.friction must be a finite number "
                                 f">= 0 or null (body {c.body!r}); got {c.friction!r}")  # fmt: skip
        if not np.isfinite(self.ground_height):
            raise ValueError(
                f"scene {self.name!r}: ground_height must be finite (m); got {self.ground_height}"
            )
        n = np.asarray(self.ground_normal, float)
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-12:
            raise ValueError(
                f"scene {self.name!r}: ground_normal must be 3 finite numbers, not all zero; "
                f"got {list(self.ground_normal)}"
            )
        unknown = set(self.initial_state) - {"q", "v"}
        if unknown:
            raise ValueError(
                f"scene {self.name!r}: initial_state may set q and v only; got {sorted(unknown)}"
            )
        for key, values in self.initial_state.items():
            if not np.all(np.isfinite(np.asarray(values, float))):
                raise ValueError(
                    f"scene {self.name!r}: initial_state.{key} must be a list of finite numbers"
                )
        self.smoothing_policy()  # validates the smoothing parameters now, not at the first step

    def _check_types(self) -> None:
        """Raise ``ValueError`` naming the key of any wrongly typed value; store numbers as
        floats and lists as tuples (a scene from YAML or from the constructor alike)."""
        if not isinstance(self.name, str):
            raise ValueError(f"scene name must be a string; got {self.name!r}")
        where = f"scene {self.name!r}"
        put = functools.partial(object.__setattr__, self)
        put("time_step", _number(self.time_step, where, "time_step", "s"))
        k = self.friction_directions
        if not (isinstance(k, numbers.Integral) and not isinstance(k, bool)):
            raise ValueError(
                f"{where}: friction_directions must be an integer >= 2 (tangent directions "
                f"per contact); got {k!r}"
            )
        put("friction_directions", int(k))
        put(
            "ground_normal",
            _numbers(self.ground_normal, where, "ground_normal", "3 numbers [nx, ny, nz]", 3),
        )
        put("ground_height", _number(self.ground_height, where, "ground_height", "m"))
        put(
            "activation_distance",
            _number(self.activation_distance, where, "activation_distance", "m; .inf for none"),
        )
        _text(self.dynamics, where, "dynamics", f"one of {DYNAMICS}")
        _text(self.friction_model, where, "friction_model", f"one of {FORMULATIONS}")
        if not isinstance(self.models, list | tuple):
            raise ValueError(
                f"{where}: models must be a list of model entries; got {self.models!r}"
            )
        models = []
        for i, m in enumerate(self.models):
            key = f"models[{i}]"
            if not isinstance(m, ModelSpec):
                raise ValueError(f"{where}: {key} must be a ModelSpec; got {m!r}")
            _text(m.file, where, f"{key}.file", "a model file path")
            _text(m.name, where, f"{key}.name", "a model instance name", optional=True)
            _text(m.weld, where, f"{key}.weld", "a frame name", optional=True)
            if not (
                isinstance(m.actuate, list | tuple) and all(isinstance(j, str) for j in m.actuate)
            ):
                raise ValueError(
                    f"{where}: {key}.actuate must be a list of joint names; got {m.actuate!r}"
                )
            _text(m.keyframe, where, f"{key}.keyframe", "a keyframe key's name", optional=True)
            if not (
                isinstance(m.ignore, list | tuple)
                and all(isinstance(a, str) and a in IGNORABLE for a in m.ignore)
            ):
                raise ValueError(
                    f"{where}: {key}.ignore must be a list of some of {list(IGNORABLE)} "
                    f"(attributes to drop); got {m.ignore!r}"
                )
            models.append(replace(m, actuate=tuple(m.actuate), ignore=tuple(m.ignore)))
        put("models", tuple(models))
        if not isinstance(self.contacts, list | tuple):
            raise ValueError(
                f"{where}: contacts must be a list of contact entries; got {self.contacts!r}"
            )
        contacts = []
        for i, c in enumerate(self.contacts):
            key = f"contacts[{i}]"
            if not isinstance(c, ContactSpec):
                raise ValueError(f"{where}: {key} must be a ContactSpec; got {c!r}")
            _text(c.body, where, f"{key}.body", "a body name")
            _text(c.model, where, f"{key}.model", "a model instance name", optional=True)
            _text(c.geometry, where, f"{key}.geometry", f"one of {GEOMETRY_SOURCES}", optional=True)
            if not isinstance(c.points, list | tuple):
                raise ValueError(
                    f"{where}: {key}.points must be a list of [x, y, z] points "
                    f"(m); got {c.points!r}"
                )
            points = tuple(
                _numbers(p, where, f"{key}.points[{j}]", "3 finite coordinates [x, y, z] (m)", 3)
                for j, p in enumerate(c.points)
            )
            radius = _number(c.radius, where, f"{key}.radius", "m")
            friction = _number(
                c.friction, where, f"{key}.friction", "Coulomb coefficient", optional=True
            )
            contacts.append(replace(c, points=points, radius=radius, friction=friction))
        put("contacts", tuple(contacts))
        if not isinstance(self.pairs, list | tuple):
            raise ValueError(f"{where}: pairs must be a list of pair entries; got {self.pairs!r}")
        pairs = []
        for i, c in enumerate(self.pairs):
            key = f"pairs[{i}]"
            if not isinstance(c, PairSpec):
                raise ValueError(f"{where}: {key} must be a PairSpec; got {c!r}")
            for name in ("a", "b"):
                _text(getattr(c, name), where, f"{key}.{name}", "a body name")
            for name in ("model_a", "model_b"):
                _text(getattr(c, name), where, f"{key}.{name}", "a model instance name",
                      optional=True)  # fmt: skip
            friction = _number(
                c.friction, where, f"{key}.friction", "Coulomb coefficient", optional=True
            )
            pairs.append(replace(c, friction=friction))
        put("pairs", tuple(pairs))
        smoothing = _mapping(self.smoothing, where, "smoothing", "{kind: ..., parameters...}")
        _text(
            smoothing.get("kind", "exact"), where, "smoothing.kind", f"one of {sorted(_SMOOTHING)}"
        )
        for name, value in smoothing.items():
            if name != "kind" and not callable(value):
                _number(value, where, f"smoothing.{name}")
        state = _mapping(self.initial_state, where, "initial_state", "{q: [...], v: [...]}")
        for name, values in state.items():
            if name in ("q", "v"):
                state[name] = _numbers(values, where, f"initial_state.{name}", "numbers")
        put("initial_state", state)

    def smoothing_policy(self) -> SmoothingPolicy:
        """The smoothing policy object this scene names, at this scene's time step: when the
        smoothing states a ``reference_time_step`` other than ``time_step``, the named policy
        wrapped in :class:`~drake_abs.contact.smoothing.TimeStepScaled` (mu times
        ``time_step / reference_time_step``)."""
        where = f"scene {self.name!r}"
        spec = dict(self.smoothing)
        kind = spec.pop("kind", "exact")
        reference = spec.pop("reference_time_step", None)
        if kind not in _SMOOTHING:
            raise ValueError(
                f"{where}: smoothing.kind must be one of {sorted(_SMOOTHING)}; got {kind!r}"
            )
        try:
            policy = _SMOOTHING[kind](**spec)
        except TypeError as err:
            takes = [f.name for f in fields(_SMOOTHING[kind]) if f.name != "g"]
            raise ValueError(
                f"{where}: smoothing: bad smoothing parameters {spec} for kind {kind!r}, which "
                f"takes {takes or 'none'} (and reference_time_step): {err}"
            ) from err
        except ValueError as err:
            raise ValueError(f"{where}: smoothing: {err}") from err
        if reference is None:
            return policy
        reference = _number(reference, where, "smoothing.reference_time_step", "s")
        if not (np.isfinite(reference) and reference > 0):
            raise ValueError(
                f"{where}: smoothing.reference_time_step must be a finite number > 0 (s); got "
                f"{reference!r}"
            )
        if kind == "gaussian_matched":
            raise ValueError(
                f"{where}: smoothing.reference_time_step does not apply to gaussian_matched "
                "(its impulse does not scale with mu; choose sigma for the time step)"
            )
        return TimeStepScaled.between(policy, self.time_step, reference)

    @property
    def num_contacts(self) -> int:
        """The number of contact candidates, counting the listed points and (read from the model
        files) those of the ``geometry`` entries and of the pairs."""
        if not self.pairs and all(c.geometry is None for c in self.contacts):
            return sum(len(c.points) for c in self.contacts)
        from drake_abs.multibody.builder import scene_contacts  # reads the model files

        return len(scene_contacts(self))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Scene:
        """A scene from plain data (mappings, lists or tuples, numbers, text, as YAML gives):
        checked against the schema (:class:`SceneFile`: keys, forms, required keys), then by the
        Scene itself (values). ``ValueError`` naming the key and the expected form."""
        name = data.get("name") if isinstance(data, Mapping) else None
        checker = _Checker(f"scene {name!r}" if isinstance(name, str) else "scene")
        checker.check_scene(data)
        return _scene_of(data)

    @classmethod
    def load(cls, name: str | Path) -> Scene:
        """A scene, from any working directory: a shipped scene by name (e.g. ``"box_push"``,
        see :func:`shipped_scenes`), a scene file by ``package://`` URI
        (``"package://drake_abs/scenes/box_push.yaml"``) or a scene YAML file by path
        (absolute, or relative to the working directory)."""
        text = str(name)
        if text.startswith("package://"):
            from drake_abs.multibody.builder import resolve_package_file

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
        return yaml.safe_dump(_plain(self.to_dict()), sort_keys=False)


def _plain(obj):
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    return obj


# ---------------------------------------------------------------------------------------------
# the scene-file schema: mutable dataclasses read by Drake's yaml_load_typed, then converted to
# the frozen Scene (which checks the values). Each field's metadata gives its expected form
# ("form"), whether it is required, a fixed length ("size"), its allowed values ("choices"), and
# for a list of entries the form of one entry ("item").


def _key(form: str, default=MISSING, *, factory=MISSING, required=False, size=None,
         choices=None, item=None):  # fmt: skip
    meta = {"form": form, "required": required, "size": size, "choices": choices, "item": item}
    return field(default=default, default_factory=factory, metadata=meta)


def _schema(cls):
    """A dataclass whose fields' ``type`` is the annotation itself, not its text (this module
    postpones annotations; Drake's ``yaml_load_typed`` reads ``field.type``)."""
    cls = dataclass(cls)
    hints = typing.get_type_hints(cls)
    for f in fields(cls):
        f.type = hints[f.name]
    return cls


_DEFAULT = {f.name: f for f in fields(Scene)}


def _scene_default(name: str):
    """The Scene's default for ``name`` (so that a key left out of a file means the same)."""
    f = _DEFAULT[name]
    return f.default if f.default_factory is MISSING else f.default_factory()


_OPTIONAL_TEXT = "text, or null"
_FRICTION = "a number >= 0: the Coulomb friction coefficient, or null for frictionless contact"
_POINT = {"form": "a point [x, y, z]: 3 numbers (m, in the body's frame)", "size": 3}


@_schema
class ModelEntry:
    """One entry of a scene file's ``models`` (see :class:`ModelSpec`)."""

    file: str = _key(
        "a model file: package://<package>/<path> (packages: drake_abs, example-robot-data, "
        "<robot>_description, gymnasium) or a path on disk",
        "",
        required=True,
    )
    name: str | None = _key(f"the model instance's name: {_OPTIONAL_TEXT}", None)
    weld: str | None = _key(
        f"the name of a frame of the model, welded to the world: {_OPTIONAL_TEXT}", None
    )
    actuate: list[str] = _key(
        "a list of joint names (text), each given an actuator",
        factory=list,
        item={"form": "a joint name (text)"},
    )
    keyframe: str | None = _key(
        f"the name of a <key> of the MuJoCo file's <keyframe>: {_OPTIONAL_TEXT}", None
    )
    ignore: list[str] = _key(
        f"a list of the MuJoCo file's attributes to drop, some of {list(IGNORABLE)}",
        factory=list,
        item={"form": f"one of {list(IGNORABLE)}", "choices": tuple(IGNORABLE)},
    )


@_schema
class ContactEntry:
    """One entry of a scene file's ``contacts`` (see :class:`ContactSpec`)."""

    body: str = _key("a body's name (text)", "", required=True)
    points: list[list[float]] = _key(
        "a list of points [x, y, z] (m, in the body's frame)", factory=list, item=_POINT
    )
    radius: float = _key("a number >= 0: the sphere radius at each point (m)", 0.0)
    friction: float | None = _key(_FRICTION, None)
    model: str | None = _key(f"the body's model instance: {_OPTIONAL_TEXT}", None)
    geometry: str | None = _key(
        f"one of {list(GEOMETRY_SOURCES)} (the body's collision shapes), or null",
        None,
        choices=GEOMETRY_SOURCES,
    )


@_schema
class PairEntry:
    """One entry of a scene file's ``pairs`` (see :class:`PairSpec`)."""

    a: str = _key("a body's name (text)", "", required=True)
    b: str = _key("a body's name (text)", "", required=True)
    friction: float | None = _key(_FRICTION, None)
    model_a: str | None = _key(f"body a's model instance: {_OPTIONAL_TEXT}", None)
    model_b: str | None = _key(f"body b's model instance: {_OPTIONAL_TEXT}", None)


@_schema
class SmoothingEntry:
    """A scene file's ``smoothing``: the policy's kind and its parameters (those a kind does
    not take are refused when the policy is made: :meth:`Scene.smoothing_policy`)."""

    kind: str = _key(
        f"one of {sorted(_SMOOTHING)}", _scene_default("smoothing")["kind"],
        choices=tuple(sorted(_SMOOTHING)),
    )  # fmt: skip
    value: float | None = _key("a number >= 0: mu of kind fixed (m N s)", None)
    mu_max: float | None = _key("a number > 0: contact_aware's mu at contact (m N s)", None)
    mu_min: float | None = _key("a number >= 0: contact_aware's mu far away (m N s)", None)
    length: float | None = _key("a number > 0: contact_aware's decay length (m)", None)
    sigma: float | None = _key("a number > 0: gaussian_matched's noise scale (m)", None)
    c1: float | None = _key("a number: gaussian_matched's c1", None)
    c2: float | None = _key("a number: gaussian_matched's c2", None)
    reference_time_step: float | None = _key(
        "a number > 0: the time step mu is stated at (s)", None
    )


@_schema
class InitialStateEntry:
    """A scene file's ``initial_state``."""

    q: list[float] | None = _key("a list of numbers: the positions (m, rad)", None)
    v: list[float] | None = _key("a list of numbers: the velocities (m/s, rad/s)", None)


@_schema
class SceneFile:
    """The schema of a scene file (the YAML format of the module docstring), read by Drake's
    ``yaml_load_typed``; :class:`Scene` is made from it. Keys left out take the Scene's
    defaults."""

    name: str = _key("the scene's name (text)", "", required=True)
    models: list[ModelEntry] = _key(
        "a list of model entries, each {file: package://<package>/<path>, ...}",
        factory=list,
        required=True,
        item={"form": "a model entry: a mapping {file: ..., name: ..., weld: ..., ...}"},
    )
    contacts: list[ContactEntry] = _key(
        "a list of contact entries, each {body: ..., points: [[x, y, z], ...], ...}",
        factory=list,
        item={
            "form": "a contact entry: a mapping {body: ..., points: [[x, y, z], ...], radius: "
            "..., friction: ...} or {body: ..., geometry: collision, friction: ...}"
        },
    )
    pairs: list[PairEntry] = _key(
        "a list of pair entries, each {a: <body>, b: <body>, friction: ...}",
        factory=list,
        item={"form": "a pair entry: a mapping {a: <body>, b: <body>, friction: ...}"},
    )
    time_step: float = _key("a number > 0: the time step (s)", _scene_default("time_step"))
    friction_directions: int = _key(
        "an integer >= 2: tangent directions per frictional contact",
        _scene_default("friction_directions"),
    )
    ground_normal: list[float] = _key(
        "[nx, ny, nz]: 3 numbers, not all zero",
        factory=lambda: list(_scene_default("ground_normal")),
        size=3,
    )
    ground_height: float = _key(
        "a number: the ground's height (m)", _scene_default("ground_height")
    )
    activation_distance: float = _key(
        "a number > 0 (m), or .inf for none", _scene_default("activation_distance")
    )
    smoothing: SmoothingEntry = _key(
        f"a mapping {{kind: one of {sorted(_SMOOTHING)}, <the kind's parameters>}}",
        factory=SmoothingEntry,
    )
    initial_state: InitialStateEntry = _key(
        "a mapping {q: [...], v: [...]}", factory=InitialStateEntry
    )
    dynamics: str = _key(f"one of {list(DYNAMICS)}", _scene_default("dynamics"), choices=DYNAMICS)
    friction_model: str = _key(
        f"one of {list(FORMULATIONS)}", _scene_default("friction_model"), choices=FORMULATIONS
    )


def _scene_of(data: Mapping[str, Any]) -> Scene:
    """The Scene of plain data that passed the schema checks (the nulls of ``smoothing`` and
    ``initial_state``, keys the file left out, dropped)."""
    rest = dict(data)
    models = tuple(ModelSpec(**m) for m in rest.pop("models"))
    contacts = tuple(ContactSpec(**c) for c in rest.pop("contacts", ()))
    pairs = tuple(PairSpec(**c) for c in rest.pop("pairs", ()))
    for key in ("smoothing", "initial_state"):
        if key in rest:
            rest[key] = {k: v for k, v in rest[key].items() if v is not None}
    return Scene(models=models, contacts=contacts, pairs=pairs, **rest)


def _load_yaml(text: str, label: str) -> Scene:
    """A Scene from YAML ``text``: parsed (syntax errors name the line), checked against
    :class:`SceneFile` (naming line, key and form), read by ``yaml_load_typed``, made a Scene
    (its value errors prefixed with ``label`` and the key's line)."""
    data, lines = _read_yaml(text, label)
    if isinstance(data, Mapping):  # yaml_load_typed ignores root keys starting with "_"
        data = {k: v for k, v in data.items() if not (isinstance(k, str) and k.startswith("_"))}
    checker = _Checker(label, lines)
    checker.check_scene(data)
    try:
        loaded = yaml_load_typed(
            schema=SceneFile,
            data=text,
            allow_yaml_with_no_schema=False,
            allow_schema_with_no_yaml=True,
            retain_map_defaults=False,
        )
    except Exception as err:  # not expected: the checks above pass only what it reads
        raise ValueError(f"{label}: {type(err).__name__}: {err}") from err
    try:
        return _scene_of(asdict(loaded))
    except ValueError as err:
        message = str(err).removeprefix(f"scene {data['name']!r}: ")
        key = re.match(r"[A-Za-z_]\w*(\[\d+\])*(\.[A-Za-z_]\w*(\[\d+\])*)*", message)
        raise ValueError(f"{checker.at(key.group(0) if key else '')}: {message}") from None


_COLLECTION_TAGS = ("tag:yaml.org,2002:map", "tag:yaml.org,2002:seq")


def _read_yaml(text: str, label: str) -> tuple[Any, dict[str, int]]:
    """The plain data of YAML ``text`` and the line of each key (``"contacts[0].points"``);
    ``ValueError`` naming ``label`` and the line for a syntax error, a duplicate key or a key
    that is not text."""
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


def _optional_of(hint):
    """``X`` for ``Optional[X]``, else None."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is type(None):
            return args[0]
    return None


def _is_integer(value) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _is_sequence(value) -> bool:
    return isinstance(value, list | tuple) or (isinstance(value, np.ndarray) and value.ndim == 1)


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


class _Checker:
    """Checks plain scene data against :class:`SceneFile`: each error a ``ValueError`` that
    names ``label`` (the file, or the scene), the key's line when ``lines`` has it, the key and
    the expected form."""

    def __init__(self, label: str, lines: Mapping[str, int] | None = None):
        self.label = label
        self.lines = lines or {}

    def at(self, key: str) -> str:
        """The label with the line of ``key`` (or of the nearest enclosing key known)."""
        while key:
            if key in self.lines:
                return f"{self.label}, line {self.lines[key]}"
            key = re.sub(r"(\.[^.\[]+|\[\d+\])$", "", key) if re.search(r"[.\[]", key) else ""
        return self.label

    def fail(self, key: str, message: str):
        raise ValueError(f"{self.at(key)}: {message}")

    def check_scene(self, data) -> None:
        self.mapping(data, SceneFile, "", "a mapping {name: ..., models: [...], ...}")
        from drake_abs.multibody.builder import model_file_problem  # it imports this module

        for i, model in enumerate(data["models"]):
            problem = model_file_problem(model["file"])
            if problem is not None:
                self.fail(f"models[{i}].file", f"models[{i}].file: {problem}")

    def mapping(self, value, schema, key: str, form: str) -> None:
        what = key or "a scene"
        if not isinstance(value, Mapping):
            self.fail(key, f"{what} must be {form}; got {_describe(value)}")
        known = {f.name: f for f in fields(schema)}
        for name in value:
            if name not in known:
                child = f"{key}.{name}" if key else str(name)
                close = difflib.get_close_matches(str(name), list(known), n=1)
                hint = ""
                if close:
                    hint = f" (did you mean {(f'{key}.' if key else '') + close[0]!r}?)"
                self.fail(
                    child,
                    f"unknown key {child!r}{hint}; {what} takes the keys {', '.join(known)}",
                )
        for f in known.values():
            child = f"{key}.{f.name}" if key else f.name
            if f.metadata["required"] and f.name not in value:
                self.fail(key, f"{child} is missing: {what} needs it, as {f.metadata['form']}")
        for name, item in value.items():
            child = f"{key}.{name}" if key else name
            self.value(item, known[name].type, child, known[name].metadata)

    def value(self, value, hint, key: str, meta: Mapping) -> None:
        form = meta["form"]
        inner = _optional_of(hint)
        if inner is not None:
            if value is None:
                return
            hint = inner
        if is_dataclass(hint):
            self.mapping(value, hint, key, form)
            return
        if typing.get_origin(hint) is list:
            (item,) = typing.get_args(hint)
            size = meta.get("size")
            if (
                not _is_sequence(value)
                or (size is not None and len(value) != size)
                or (item is float and not all(_is_number(x) for x in value))
            ):
                self.fail(key, f"{key} must be {form}; got {_describe(value)}")
            if item is not float:
                for j, entry in enumerate(value):
                    self.value(entry, item, f"{key}[{j}]", meta["item"])
            return
        ok = {str: lambda v: isinstance(v, str), float: _is_number, int: _is_integer}[hint]
        choices = meta.get("choices")
        if not ok(value) or (choices is not None and value not in choices):
            self.fail(key, f"{key} must be {form}; got {_describe(value)}")
