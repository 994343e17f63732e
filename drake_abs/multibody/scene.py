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
    activation_distance: 0.1        # m; farther contacts are left out of the step's LCP
    smoothing: {kind: contact_aware, mu_max: 1.0e-3, length: 0.02}
    initial_state: {q: [0, 0.1, 0], v: [1.0, 0, 0]}

Model files: ``drake_abs:<path>`` is a file shipped with this package (``models/``),
``example-robot-data:<path>`` one of the installed example-robot-data robots, anything else a
path on disk.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from drake_abs.contact.smoothing import ContactAware, Exact, Fixed, GaussianMatched, SmoothingPolicy

_SMOOTHING = {
    "exact": Exact,
    "fixed": Fixed,
    "contact_aware": ContactAware,
    "gaussian_matched": GaussianMatched,
}


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
    ``actuate``: joints to give an actuator (for URDFs without ``<transmission>`` tags)."""

    file: str
    name: str | None = None
    weld: str | None = None
    actuate: tuple[str, ...] = ()


@dataclass(frozen=True)
class ContactSpec:
    """Contact candidates on one body: ``points`` (m, body frame), each a sphere of ``radius``
    (m; 0 for a point) against the ground; ``friction`` the Coulomb coefficient, or None for
    frictionless contact."""

    body: str
    points: tuple[tuple[float, float, float], ...]
    radius: float = 0.0
    friction: float | None = None
    model: str | None = None


@dataclass(frozen=True)
class Scene:
    """A complementarity scene.

    Attributes:
        name: identifier.
        models: the model files.
        contacts: the contact candidates (the only contacts the plant has).
        time_step: h in s.
        friction_directions: k, tangent directions per frictional contact (2 for planar scenes).
        ground_normal, ground_height: the ground half-space ``n . p >= height``.
        activation_distance: contacts whose distance exceeds this (m) are left out of a step's
            LCP. Under exact contact this changes nothing; under smoothing it drops their force
            at a distance (about mu / distance each) and, for ContactAware, their say in mu.
        smoothing: ``{"kind": "exact" | "fixed" | "contact_aware" | "gaussian_matched", ...}``
            with the policy's parameters; larger mu is smoother.
        initial_state: ``{"q": [...], "v": [...]}`` (defaults: the plant's default state).
        dynamics: who evaluates M, the bias terms, the contact Jacobians and their derivatives:
            ``"pinocchio"`` (analytic derivatives; revolute, prismatic and weld joints, which
            includes this package's floating bases), ``"drake"`` (the MultibodyPlant itself,
            AutoDiffXd for derivatives; any joint), or ``"auto"`` (pinocchio where it applies).
            Both give the same numbers (tested); pinocchio is much faster.
    """

    name: str
    models: tuple[ModelSpec, ...]
    contacts: tuple[ContactSpec, ...]
    time_step: float = 0.01
    friction_directions: int = 4
    ground_normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    ground_height: float = 0.0
    activation_distance: float = float("inf")
    smoothing: dict = field(default_factory=lambda: {"kind": "exact"})
    initial_state: dict = field(default_factory=dict)
    dynamics: str = "auto"

    def __post_init__(self):
        if self.dynamics not in DYNAMICS:
            raise ValueError(
                f"scene {self.name!r}: dynamics must be one of {DYNAMICS}; got {self.dynamics!r}"
            )
        if not self.models:
            raise ValueError(f"scene {self.name!r}: models must list at least one model file")
        if not self.contacts:
            raise ValueError(f"scene {self.name!r}: contacts must list at least one candidate")
        if not (np.isfinite(self.time_step) and self.time_step > 0):
            raise ValueError(f"scene {self.name!r}: time_step must be > 0; got {self.time_step}")
        if int(self.friction_directions) < 2:
            raise ValueError(f"scene {self.name!r}: friction_directions must be >= 2")
        if not self.activation_distance > 0:
            raise ValueError(f"scene {self.name!r}: activation_distance must be > 0")
        for c in self.contacts:
            if not c.points:
                raise ValueError(f"scene {self.name!r}: contact on {c.body!r} lists no points")
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

    def smoothing_policy(self) -> SmoothingPolicy:
        """The smoothing policy object this scene names."""
        spec = dict(self.smoothing)
        kind = spec.pop("kind", "exact")
        if kind not in _SMOOTHING:
            raise ValueError(
                f"scene {self.name!r}: smoothing kind must be one of {sorted(_SMOOTHING)}; "
                f"got {kind!r}"
            )
        try:
            return _SMOOTHING[kind](**spec)
        except TypeError as err:
            raise ValueError(
                f"scene {self.name!r}: bad smoothing parameters {spec}: {err}"
            ) from err

    @property
    def num_contacts(self) -> int:
        return sum(len(c.points) for c in self.contacts)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Scene:
        data = dict(data)
        unknown = set(data) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown scene keys {sorted(unknown)}")
        for kind, spec in (("models", ModelSpec), ("contacts", ContactSpec)):
            for i, entry in enumerate(data.get(kind, ())):
                if not isinstance(entry, dict):
                    raise ValueError(f"{kind}[{i}] must be a mapping; got {entry!r}")
                bad = set(entry) - set(spec.__dataclass_fields__)
                if bad:
                    raise ValueError(
                        f"unknown keys {sorted(bad)} in {kind}[{i}]; expected some of "
                        f"{sorted(spec.__dataclass_fields__)}"
                    )
        models = tuple(
            ModelSpec(**{**m, "actuate": tuple(m.get("actuate", ()))})
            for m in data.pop("models", ())
        )
        contacts = []
        for i, c in enumerate(data.pop("contacts", ())):
            try:
                points = tuple(tuple(map(float, p)) for p in c["points"])
            except (KeyError, TypeError, ValueError) as err:
                raise ValueError(
                    f"contacts[{i}].points must be a list of [x, y, z] numbers (m): {err}"
                ) from err
            contacts.append(ContactSpec(**{**c, "points": points}))
        contacts = tuple(contacts)
        if "ground_normal" in data:
            data["ground_normal"] = tuple(float(x) for x in data["ground_normal"])
        for key in ("time_step", "ground_height", "activation_distance"):
            if key in data:
                data[key] = float(data[key])
        return cls(models=models, contacts=contacts, **data)

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
        data = yaml.safe_load(text)
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
