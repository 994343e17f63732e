"""Scene descriptions: which models, which contacts, which time step and smoothing (pure data,
loadable from YAML). A scene models only what it declares: the complementarity plant built from
it contains exactly its contact candidates, and no others.

Example (YAML)::

    name: box_push
    time_step: 0.01
    models:
      - file: drake_abs:models/box_planar.sdf
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

Model files: ``drake_abs:<path>`` is a file shipped with this package (``models/``),
``example-robot-data:<path>`` one of the installed example-robot-data robots,
``gymnasium:<file>`` one of gymnasium's MuJoCo model files (``gymnasium:hopper.xml``), anything
else a path on disk. URDF, SDF and MJCF files are used as published (see README, "Model files as
published").
"""

from __future__ import annotations

import functools
import numbers
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

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
            raise ValueError(f"scene {self.name!r}: time_step must be > 0; got {self.time_step}")
        if int(self.friction_directions) < 2:
            raise ValueError(f"scene {self.name!r}: friction_directions must be >= 2")
        if not self.activation_distance > 0:
            raise ValueError(f"scene {self.name!r}: activation_distance must be > 0")
        for c in self.pairs:
            if c.friction is not None and not (np.isfinite(c.friction) and c.friction >= 0):
                raise ValueError(f"scene {self.name!r}: pair {c.a!r}-{c.b!r}: friction must be "
                                 f"a finite number >= 0 or null; got {c.friction!r}")  # fmt: skip
        for c in self.contacts:
            if c.geometry is not None:
                if c.geometry not in GEOMETRY_SOURCES:
                    raise ValueError(
                        f"scene {self.name!r}: contact on {c.body!r}: geometry must be one of "
                        f"{GEOMETRY_SOURCES}; got {c.geometry!r}"
                    )
                if c.points or c.radius != 0.0:
                    raise ValueError(
                        f"scene {self.name!r}: contact on {c.body!r}: give points (and radius) "
                        "or geometry, not both"
                    )
            elif not c.points:
                raise ValueError(
                    f"scene {self.name!r}: contact on {c.body!r} lists no points (or geometry)"
                )
            for p in c.points:
                if len(p) != 3 or not np.all(np.isfinite(np.asarray(p, float))):
                    raise ValueError(
                        f"scene {self.name!r}: contact on {c.body!r}: every point must be 3 "
                        f"finite coordinates [x, y, z] in m; got {list(p)}"
                    )
            if not (np.isfinite(c.radius) and c.radius >= 0):
                raise ValueError(f"scene {self.name!r}: contact on {c.body!r}: radius must be a "
                                 f"finite number >= 0 (m); got {c.radius!r}")  # fmt: skip
            if c.friction is not None and not (np.isfinite(c.friction) and c.friction >= 0):
                raise ValueError(f"scene {self.name!r}: contact on {c.body!r}: friction must be "
                                 f"a finite number >= 0 or null; got {c.friction!r}")  # fmt: skip
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
                raise ValueError(f"scene {self.name!r}: initial_state {key} must be finite")
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
                f"{where}: smoothing kind must be one of {sorted(_SMOOTHING)}; got {kind!r}"
            )
        try:
            policy = _SMOOTHING[kind](**spec)
        except TypeError as err:
            raise ValueError(f"{where}: bad smoothing parameters {spec}: {err}") from err
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
        """The number of contact candidates: the listed points, and (read from the model files)
        those of the ``geometry`` entries and of the pairs."""
        if not self.pairs and all(c.geometry is None for c in self.contacts):
            return sum(len(c.points) for c in self.contacts)
        from drake_abs.multibody.builder import scene_contacts  # reads the model files

        return len(scene_contacts(self))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Scene:
        data = dict(data)
        unknown = set(data) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown scene keys {sorted(unknown)}")
        where = f"scene {data.get('name')!r}"
        if "name" not in data:
            raise ValueError("a scene needs a name")
        for kind, spec in (("models", ModelSpec), ("contacts", ContactSpec), ("pairs", PairSpec)):
            if not isinstance(data.get(kind, ()), list | tuple):
                raise ValueError(f"{where}: {kind} must be a list of mappings; got {data[kind]!r}")
            for i, entry in enumerate(data.get(kind, ())):
                if not isinstance(entry, dict):
                    raise ValueError(f"{where}: {kind}[{i}] must be a mapping; got {entry!r}")
                bad = set(entry) - set(spec.__dataclass_fields__)
                if bad:
                    raise ValueError(
                        f"{where}: unknown keys {sorted(bad)} in {kind}[{i}]; expected some of "
                        f"{sorted(spec.__dataclass_fields__)}"
                    )
        for i, m in enumerate(data.get("models", ())):
            if "file" not in m:
                raise ValueError(f"{where}: models[{i}] needs a file")
        for i, c in enumerate(data.get("contacts", ())):
            for key in ("body", "points"):
                if key not in c and not (key == "points" and "geometry" in c):
                    raise ValueError(f"{where}: contacts[{i}] needs {key}")
        for i, c in enumerate(data.get("pairs", ())):
            for key in ("a", "b"):
                if key not in c:
                    raise ValueError(f"{where}: pairs[{i}] needs {key}")
        # the values' types are checked (and numbers made floats) by the Scene itself
        models = tuple(ModelSpec(**m) for m in data.pop("models", ()))
        contacts = tuple(ContactSpec(**c) for c in data.pop("contacts", ()))
        pairs = tuple(PairSpec(**c) for c in data.pop("pairs", ()))
        return cls(models=models, contacts=contacts, pairs=pairs, **data)

    @classmethod
    def load(cls, name: str | Path) -> Scene:
        """A shipped scene by name (e.g. ``"box_push"``, see :func:`shipped_scenes`) or a scene
        YAML file by path."""
        path = Path(name)
        if path.suffix in (".yaml", ".yml"):
            if not path.is_file():
                raise FileNotFoundError(f"scene file {str(name)!r} not found")
            return cls.from_yaml(path)
        shipped = SCENES_DIR / f"{name}.yaml"
        if not shipped.is_file():
            raise ValueError(
                f"no shipped scene {str(name)!r}: give a YAML path or one of {shipped_scenes()}"
            )
        return cls.from_yaml(shipped)

    @classmethod
    def from_yaml(cls, source: str | Path) -> Scene:
        """Load from a YAML file path or a YAML string."""
        text = Path(source).read_text() if Path(str(source)).suffix in (".yaml", ".yml") else source
        data = yaml.load(text, Loader=_SceneLoader)
        if not isinstance(data, dict):
            raise ValueError("a scene YAML must be a mapping at the top level")
        return cls.from_dict(data)

    def to_yaml(self) -> str:
        return yaml.safe_dump(_plain(self.to_dict()), sort_keys=False)


def _plain(obj):
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    return obj
