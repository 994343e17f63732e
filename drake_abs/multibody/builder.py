"""Build a scene's MultibodyPlant, its contact model and its stepper from a
:class:`drake_abs.multibody.scene.Scene`.

``make_stepper(scene)`` (or ``build_scene_model(scene).stepper()``) is the one way to get a
scene's batched step with every setting the scene names applied (smoothing policy, activation
distance); arguments override a setting explicitly, nothing is copied by hand.
"""

from __future__ import annotations

import difflib
import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import PackageMap, Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    ModelInstanceIndex,
    PrismaticJoint,
    QuaternionFloatingJoint,
    RevoluteJoint,
    SpatialInertia,
)

from drake_abs.contact.lcs import GradientMode
from drake_abs.contact.smoothing import SmoothingPolicy
from drake_abs.multibody.drake_dynamics import (
    ContactModelBase,
    GroundPlane,
    MultibodyContactModel,
    PointContact,
)
from drake_abs.multibody.geometry_contacts import PairContact, Shape, ground_points, shape_of
from drake_abs.multibody.model_files import add_models, apply_mjcf, model_report, read_mjcf
from drake_abs.multibody.pinocchio_dynamics import PinocchioContactModel
from drake_abs.multibody.scene import ModelSpec, Scene
from drake_abs.multibody.stepper import ComplementarityStepper

PACKAGE_DIR = Path(__import__("drake_abs").__file__).resolve().parent


@functools.cache
def example_robot_data_dir() -> Path:
    """The installed example-robot-data share folder (…/share/example-robot-data)."""
    import sys

    for base in map(Path, sys.path):
        for candidate in (
            base / "cmeel.prefix/share/example-robot-data",
            base / "share/example-robot-data",
        ):
            if (candidate / "robots").is_dir():
                return candidate
    prefix = Path(sys.prefix) / "share/example-robot-data"
    if (prefix / "robots").is_dir():
        return prefix
    raise FileNotFoundError(
        "example-robot-data is not installed (pip install example-robot-data): its robots/ "
        "folder was not found under sys.path or sys.prefix"
    )


@functools.cache
def gymnasium_assets_dir() -> Path:
    """The installed gymnasium's MuJoCo model files (…/gymnasium/envs/mujoco/assets), found
    without importing gymnasium."""
    import importlib.util

    found = importlib.util.find_spec("gymnasium")
    if found is None or found.origin is None:
        raise FileNotFoundError(
            "gymnasium is not installed (pip install gymnasium): a model file "
            "'package://gymnasium/<file>.xml' names one of its MuJoCo assets"
        )
    return Path(found.origin).parent / "envs" / "mujoco" / "assets"


#: The model-file prefixes of earlier versions, still read as aliases of ``package://`` URIs
#: (``drake_abs:models/box.sdf`` is ``package://drake_abs/models/box.sdf``). Write the URI.
MODEL_FILE_ALIASES = {
    "drake_abs:": "package://drake_abs/",
    "example-robot-data:": "package://example-robot-data/robots/",
    "gymnasium:": "package://gymnasium/",
}


def model_file_url(file: str) -> str | None:
    """The ``package://`` URI a scene's model ``file`` names (an alias of
    :data:`MODEL_FILE_ALIASES` rewritten), or None when ``file`` is a path on disk."""
    if file.startswith("package://"):
        return file
    for alias, prefix in MODEL_FILE_ALIASES.items():
        if file.startswith(alias):
            return prefix + file[len(alias) :]
    return None


def package_folders() -> dict[str, Path]:
    """A copy of :func:`_package_folders` (listed once per process)."""
    return dict(_package_folders())


@functools.cache
def _package_folders() -> dict[str, Path]:
    """The packages a scene's ``package://<package>/<path>`` may name, name -> folder:
    ``drake_abs`` (this package's folder: ``models/``, ``scenes/``); when installed,
    ``example-robot-data`` (its share folder: ``robots/<robot>_description/...``) and each of its
    robots' own ``<robot>_description`` folders, and ``gymnasium`` (its MuJoCo model files,
    ``gymnasium/envs/mujoco/assets``; found without importing gymnasium)."""
    folders = {"drake_abs": PACKAGE_DIR}
    try:
        robot_data = example_robot_data_dir()
    except FileNotFoundError:
        pass
    else:
        folders["example-robot-data"] = robot_data
        for robot in sorted((robot_data / "robots").iterdir()):
            if robot.is_dir():
                folders.setdefault(robot.name, robot)
    try:
        assets = gymnasium_assets_dir()
    except FileNotFoundError:
        pass
    else:
        if assets.is_dir():
            folders["gymnasium"] = assets
    return folders


def register_packages(package_map: PackageMap) -> None:
    """Add every package of :func:`package_folders` that ``package_map`` lacks (the model files
    name their meshes by ``package://`` URIs too; a package already there is left as it is)."""
    for name, folder in package_folders().items():
        if not package_map.Contains(name):
            package_map.Add(name, str(folder))


def model_file_problem(file: str) -> str | None:
    """What is wrong with a scene's model ``file`` before any file is opened: None for a path
    on disk or a ``package://`` URI (or alias) of a known package; otherwise the reason, naming
    the expected form and the known packages."""
    url = model_file_url(file)
    if url is None:
        return None
    package, slash, rest = url.removeprefix("package://").partition("/")
    if not package or not slash or not rest:
        return f"{file!r} is not of the form package://<package>/<path>"
    folders = package_folders()
    if package in folders:
        return None
    top = ("drake_abs", "example-robot-data", "gymnasium")
    known = ", ".join(n for n in top if n in folders)
    robots = [n for n in folders if n not in top]  # example-robot-data's robots/ folders
    if robots:
        shown = ", ".join(robots[:4] + ["..."] + robots[-1:] if len(robots) > 6 else robots)
        known += (
            f", and the {len(robots)} robot packages of example-robot-data, the folders of "
            f"{folders['example-robot-data'] / 'robots'} ({shown})"
        )
    close = difflib.get_close_matches(package, list(folders), n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    missing = [
        f"{name} is not installed (pip install {name})"
        for name in ("example-robot-data", "gymnasium")
        if name not in folders
    ]
    missing_text = f"; {'; '.join(missing)}" if missing else ""
    return (
        f"unknown package {package!r} in {file!r}{hint}; a model file is "
        f"package://<package>/<path> with a known package: {known}{missing_text}"
    )


def resolve_package_file(file: str, where: str = "", what: str = "model file") -> Path:
    """The file ``file`` names: ``package://<package>/<path>``, resolved through Drake's
    ``PackageMap`` with the packages of :func:`package_folders` (for example
    ``package://drake_abs/models/box_planar.sdf``,
    ``package://example-robot-data/robots/go1_description/urdf/go1.urdf``,
    ``package://gymnasium/hopper.xml``), an alias of one (:data:`MODEL_FILE_ALIASES`), or a path
    on disk. ``ValueError`` (prefixed with ``where``) for an unknown package,
    ``FileNotFoundError`` for a missing file (``what``: the kind of file, for the message)."""
    url = model_file_url(file)
    if url is None:
        path = Path(file).expanduser()
    else:
        problem = model_file_problem(file)
        if problem is not None:
            raise ValueError(f"{where}: {problem}" if where else problem)
        package, _, rest = url.removeprefix("package://").partition("/")
        folder = package_folders()[package]
        package_map = PackageMap.MakeEmpty()
        package_map.Add(package, str(folder))
        try:
            path = Path(package_map.ResolveUrl(url))
        except RuntimeError:  # Drake's: the URI resolves to a file that does not exist
            path = folder / rest
    if not path.is_file():
        raise FileNotFoundError(f"{what} {file!r} not found (looked at {path})")
    return path


def resolve_model_file(spec: ModelSpec, where: str = "") -> Path:
    """The model file a ModelSpec names (see :func:`resolve_package_file`); ``where`` (such as
    ``"scene 'box_push': models[0].file"``) prefixes the message of an unknown package."""
    return resolve_package_file(spec.file, where)


@dataclass(frozen=True)
class SceneModel:
    """A scene's dynamics: a continuous MultibodyPlant (no SceneGraph: contacts are the scene's
    declared points) and its contact model, plus the initial state."""

    scene: Scene
    plant: MultibodyPlant
    contact_model: ContactModelBase
    q0: np.ndarray
    v0: np.ndarray

    @property
    def x0(self) -> np.ndarray:
        """The scene's initial state x = (q0, v0), shape (nq + nv,)."""
        return np.concatenate([self.q0, self.v0])

    def model_report(self) -> dict:
        """What the plant holds of the scene's model files: per joint its coordinates, limits,
        damping and armature, per actuator its gear and effort limit (see
        :func:`drake_abs.multibody.model_files.model_report`)."""
        return model_report(self.plant)

    def stepper(
        self,
        *,
        smoothing: SmoothingPolicy | None = None,
        activation_distance: float | None = None,
        gradient: GradientMode = "total",
        friction: str | None = None,
        **solver_options,
    ) -> ComplementarityStepper:
        """The scene's batched step, with the scene's smoothing policy and activation distance.

        Args:
            smoothing: replaces the scene's smoothing policy (larger mu: more smoothing). It
                is used as given at the scene's ``time_step``: the smoothing's
                ``reference_time_step`` does not rescale it (wrap it in
                :class:`~drake_abs.contact.smoothing.TimeStepScaled` for that).
            activation_distance: replaces the scene's activation distance (m).
            gradient: ``"frozen"`` or ``"total"`` (see :class:`ComplementarityStepper`).
            friction: replaces the scene's friction formulation (``"stewart_trinkle"`` or
                ``"anitescu"``).
            solver_options: passed to the interior-point solver.
        """
        stepper = ComplementarityStepper(
            self.contact_model,
            self.scene.smoothing_policy() if smoothing is None else smoothing,
            gradient,
            self.scene.activation_distance if activation_distance is None else activation_distance,
            self.scene.friction_model if friction is None else friction,
            **solver_options,
        )
        stepper.scene = self.scene
        return stepper


def _parse(parser: Parser, path: Path, collisions: bool, spec: ModelSpec, where: str):
    """Parse one model file: its model instances, with the bodies its URDF ``floating`` joints
    name given a quaternion floating joint of that name, at the joint's origin (see
    :func:`add_floating_base_chains`); an MJCF file (``.xml``) checked and completed by
    :func:`~drake_abs.multibody.model_files.read_mjcf` and
    :func:`~drake_abs.multibody.model_files.apply_mjcf` (``spec.ignore``, ``spec.keyframe``)."""
    mjcf = None
    if path.suffix.lower() == ".xml":
        try:
            mjcf = read_mjcf(path, spec.ignore)
        except ValueError as err:
            raise ValueError(f"{where} ({spec.file}): {err}") from err
    elif spec.ignore or spec.keyframe is not None:
        raise ValueError(
            f"{where}: ignore and keyframe apply to MuJoCo files (.xml) only; {spec.file!r} is "
            "not one"
        )
    instances, floating = add_models(parser, path, collisions=collisions, mjcf=mjcf)
    plant = parser.plant()
    if mjcf is not None:
        apply_mjcf(plant, instances[0], mjcf, spec.keyframe, where=f"{where} ({spec.file})")
    for joint in floating:
        body = plant.GetBodyByName(joint.link, instances[0])
        added = plant.AddJoint(
            QuaternionFloatingJoint(joint.name, plant.world_frame(), body.body_frame())
        )
        added.SetDefaultPose(RigidTransform(RollPitchYaw(joint.rpy), joint.xyz))
    return instances


def add_scene_models(
    plant: MultibodyPlant, scene: Scene, parser: Parser | None = None, *, collisions: bool = True
) -> None:
    """Parse the scene's models into ``plant`` (not finalized), with welds, actuators and
    floating bases (a quaternion floating joint where a URDF declares a ``floating`` joint to
    the world, :func:`add_floating_base_chains` for the other free bodies); ``collisions=False``
    leaves the files' collision geometry out (and draws STL visuals through OBJ copies; see
    :mod:`drake_abs.multibody.model_files`)."""
    parser = parser or Parser(plant)
    register_packages(parser.package_map())  # the files' own package:// URIs (meshes)
    for i, spec in enumerate(scene.models):
        where = f"scene {scene.name!r}: models[{i}]"
        path = resolve_model_file(spec, where=f"{where}.file")
        instances = _parse(parser, path, collisions, spec, where)
        instance = instances[0]
        if spec.name:
            plant.RenameModelInstance(instance, spec.name)
        if spec.weld:
            plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(spec.weld, instance))
        for joint in spec.actuate:
            plant.AddJointActuator(f"{joint}_actuator", plant.GetJointByName(joint, instance))
    add_floating_base_chains(plant)


#: The joints of a floating base, parent to child, with q = (x, y, z, yaw, pitch, roll) and v their
#: rates, with the body's pose p = (x, y, z), R = Rz(yaw) Ry(pitch) Rx(roll).
FLOATING_BASE_JOINTS = (
    ("x", PrismaticJoint, (1.0, 0.0, 0.0)),
    ("y", PrismaticJoint, (0.0, 1.0, 0.0)),
    ("z", PrismaticJoint, (0.0, 0.0, 1.0)),
    ("yaw", RevoluteJoint, (0.0, 0.0, 1.0)),
    ("pitch", RevoluteJoint, (0.0, 1.0, 0.0)),
    ("roll", RevoluteJoint, (1.0, 0.0, 0.0)),
)


def add_floating_base_chains(plant: MultibodyPlant) -> list[str]:
    """Give every free root body of ``plant`` (not finalized) a floating base made of joints:
    three prismatic and three revolute joints (:data:`FLOATING_BASE_JOINTS`) through massless
    intermediate bodies, named ``<body>_x`` ... ``<body>_roll``. Its coordinates are positions
    and Euler angles with ``qdot = v`` (the velocities are the angle rates, not the angular
    velocity), so rigid-body libraries and the step's Jacobians need no quaternion or
    angular-velocity map; like any roll-pitch-yaw parametrisation it is singular at
    pitch = +-pi/2. Bodies that already have a joint from the world (such as the quaternion
    floating joint a URDF ``floating`` joint asks for: see :func:`add_scene_models`) keep it.
    Each chain's default positions place the body at its default pose from the model file (an
    SDF link's ``<pose>``, an MJCF body's ``pos``/``quat``): x, y, z and the yaw, pitch and roll
    of its orientation. Returns the names of the bodies given a floating base."""
    inboard = {int(plant.get_joint(i).child_body().index()) for i in plant.GetJointIndices()}
    roots = []
    for k in range(plant.num_model_instances()):
        instance = ModelInstanceIndex(k)
        for i in plant.GetBodyIndices(instance):
            body = plant.get_body(i)
            if int(i) != int(plant.world_body().index()) and int(i) not in inboard:
                roots.append(body)
    for body in roots:
        pose = plant.GetDefaultFloatingBaseBodyPose(body)
        rpy = RollPitchYaw(pose.rotation())
        default = (*pose.translation(), rpy.yaw_angle(), rpy.pitch_angle(), rpy.roll_angle())
        parent = plant.world_body()
        instance = body.model_instance()
        for j, (name, kind, axis) in enumerate(FLOATING_BASE_JOINTS):
            last = j == len(FLOATING_BASE_JOINTS) - 1
            child = (
                body
                if last
                else plant.AddRigidBody(f"{body.name()}_{name}", instance, SpatialInertia.Zero())
            )
            joint = plant.AddJoint(
                kind(f"{body.name()}_{name}", parent.body_frame(), child.body_frame(), axis)
            )
            joint.set_default_positions([float(default[j])])
            parent = child
    return [b.name() for b in roots]


def _check_armature(model: PinocchioContactModel, plant: MultibodyPlant) -> None:
    """``NotImplementedError`` unless the pinocchio model has the plant's reflected inertias
    (actuator armature, which Drake's mass matrix includes) as its armature."""
    reflected = np.zeros(plant.num_velocities())
    for i in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(i)
        reflected[actuator.joint().velocity_start()] += actuator.default_reflected_inertia()
    armature = np.asarray(getattr(model.pin_model, "armature", np.zeros_like(reflected)))
    if not np.allclose(armature, reflected, rtol=1e-12, atol=0.0):
        raise NotImplementedError(
            "the plant's actuators have reflected inertia (armature) "
            f"{reflected.tolist()} that the pinocchio dynamics do not include (they have "
            f"{armature.tolist()}); use dynamics: drake"
        )


#: Scene models rebuilt in this process from pickled steppers, by scene (as YAML text): a
#: worker that receives several objectives of one scene parses its model files once.
_REBUILT: dict[str, SceneModel] = {}


def rebuild_stepper(scene: Scene, settings: dict) -> ComplementarityStepper:
    """A pickled :class:`ComplementarityStepper` rebuilt from its scene and settings (smoothing,
    gradient, activation_distance, friction, joint_limits, damping, solver options, and
    ``parameters``: the model parameters changed by
    :meth:`~ComplementarityStepper.with_parameters`, ``{name: value}``)."""
    key = scene.to_yaml()
    model = _REBUILT.get(key)
    if model is None:
        model = _REBUILT.setdefault(key, build_scene_model(scene))
    settings = dict(settings)
    parameters = settings.pop("parameters", None)
    stepper = ComplementarityStepper(model.contact_model, **settings)
    stepper.scene = model.scene
    if parameters:
        stepper = stepper.with_parameters(parameters)
    return stepper


def make_stepper(scene: Scene | str | Path, **overrides) -> ComplementarityStepper:
    """The batched step of ``scene`` (a :class:`Scene`, a shipped scene's name such as
    ``"box_push"``, or a YAML path) with every scene setting applied; keyword arguments override
    a setting explicitly (see :meth:`SceneModel.stepper`)."""
    return build_scene_model(scene).stepper(**overrides)


def scene_contacts(scene: Scene) -> list[PointContact | PairContact]:
    """The contact candidates of ``scene``, in its order: each ``contacts`` entry's listed
    points, or its body's collision shapes as exact point candidates against the ground
    (``geometry: collision``), then each ``pairs`` entry's unfiltered pairs of collision shapes.
    Collision geometry is read from a plant built with a SceneGraph for the purpose (the step's
    own plant has none)."""
    needs_geometry = scene.pairs or any(c.geometry is not None for c in scene.contacts)
    shapes = _CollisionShapes(scene) if needs_geometry else None
    out: list[PointContact | PairContact] = []
    for c in scene.contacts:
        if c.geometry is None:
            out.extend(PointContact(c.body, tuple(p), c.radius, c.friction, c.model)
                       for p in c.points)  # fmt: skip
            continue
        for _, shape in shapes.of(c.body, c.model):
            out.extend(PointContact(c.body, p, radius, c.friction, c.model)
                       for p, radius in ground_points(shape))  # fmt: skip
    for pair in scene.pairs:
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
                f"scene {scene.name!r}: pair {pair.a!r}-{pair.b!r}: the model's collision "
                "filters exclude every pair of their collision shapes"
            )
        out.extend(found)
    return out


class _CollisionShapes:
    """The collision shapes of a scene's bodies (a plant and SceneGraph parsed for them)."""

    def __init__(self, scene: Scene):
        from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
        from pydrake.systems.framework import DiagramBuilder

        self.scene = scene
        self._builder = DiagramBuilder()
        self.plant, scene_graph = AddMultibodyPlantSceneGraph(self._builder, 0.0)
        add_scene_models(self.plant, scene, collisions=True)
        self.plant.Finalize()
        self.inspector = scene_graph.model_inspector()

    def of(self, body_name: str, model: str | None) -> list[tuple[object, Shape]]:
        """``[(geometry id, Shape)]`` of a body's collision geometry; ``ValueError`` for a body
        without any, or with a shape other than a sphere, capsule or box."""
        plant, where = self.plant, f"scene {self.scene.name!r}: body {body_name!r}"
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


def build_scene_model(scene: Scene | str | Path) -> SceneModel:
    """The dynamics plant, contact model and initial state of ``scene`` (a :class:`Scene`, a
    shipped scene's name, or a YAML path)."""
    if not isinstance(scene, Scene):
        scene = Scene.load(scene)
    plant = MultibodyPlant(0.0)
    add_scene_models(plant, scene)
    plant.Finalize()
    contacts = scene_contacts(scene)
    ground = GroundPlane(scene.ground_normal, scene.ground_height)
    args = (plant, contacts, ground, scene.time_step, scene.friction_directions)
    if scene.dynamics == "drake":
        model = MultibodyContactModel(*args)
    else:
        try:
            model = PinocchioContactModel(*args)
            _check_armature(model, plant)
        except NotImplementedError:
            if scene.dynamics == "pinocchio":
                raise
            model = MultibodyContactModel(*args)
    context = plant.CreateDefaultContext()
    q0 = np.asarray(scene.initial_state.get("q", plant.GetPositions(context)), float)
    v0 = np.asarray(scene.initial_state.get("v", plant.GetVelocities(context)), float)
    if q0.shape != (plant.num_positions(),) or v0.shape != (plant.num_velocities(),):
        raise ValueError(
            f"scene {scene.name!r}: initial_state q and v must have {plant.num_positions()} and "
            f"{plant.num_velocities()} entries; got {q0.shape} and {v0.shape}"
        )
    for s in model.quaternion_starts:  # a free body's (qw, qx, qy, qz): unit, to rounding
        norm = float(np.linalg.norm(q0[s : s + 4]))
        if not abs(norm - 1.0) <= 1e-3:
            raise ValueError(
                f"scene {scene.name!r}: initial_state q[{s}:{s + 4}] is a unit quaternion "
                f"(qw, qx, qy, qz); got norm {norm:.6g}"
            )
        q0[s : s + 4] /= norm
    return SceneModel(scene, plant, model, q0, v0)
