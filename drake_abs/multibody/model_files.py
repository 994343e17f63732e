"""Model files parsed without their collision geometry, and URDF floating joints.

With a SceneGraph attached, Drake refuses some collision geometry (example-robot-data's STL
collision meshes: "MakeConvexHull only applies to .obj, .vtk, and .gltf meshes"), and this
package's plants do not need it: contacts are the scene's declared points. URDF and SDF files
are read as text, their ``<collision>`` elements removed and relative file references made
absolute, and parsed from that copy; other formats are parsed unchanged. Drake's Meshcat does not
draw STL meshes either (it warns and skips them), so STL visual meshes are replaced by OBJ copies,
converted once and cached in the temp folder.

URDF ``floating`` joints (a free body's 6-dof joint to the world), which MultibodyPlant's parser
does not build, are left out of the parsed text and returned by :func:`add_models`:
:func:`drake_abs.multibody.parsing.add_model_specs` gives those bodies a quaternion floating joint
(:func:`floating_joints`), placed at the joint's ``<origin>``.

MuJoCo (MJCF) files are parsed by Drake as published, except for what Drake drops and the step
needs (:func:`read_mjcf`): ``<compiler settotalmass>`` (applied: the bodies' masses and inertias
scaled), actuator effort limits (Drake keeps ``ctrlrange`` in control units while the actuation
input is the joint torque: applied as ``gear * ctrlrange``, clipped by ``forcerange``), joint
springs (``stiffness`` towards ``springref`` on hinge and slide joints: added to the plant as
Drake's ``RevoluteSpring`` / ``PrismaticSpring`` force elements, which the step takes implicitly,
:func:`drake_abs.multibody.joint_limits.joint_springs`), dry joint friction (``frictionloss`` on
hinge and slide joints: read here, given to the step as complementarity rows,
:mod:`drake_abs.multibody.joint_friction`), and ``<keyframe>`` (applied on request). What
neither Drake nor this package models (armature of an unactuated joint, springs and dry friction
on ball and free joints, tendons, equality constraints, actuators other than ``<motor>``) is
refused, naming the element and attribute; joint attributes can be dropped explicitly (a scene's
``ignore``: ``joint.stiffness`` drops the springs too, ``joint.frictionloss`` the friction).
:func:`model_report` lists what a built plant holds.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple
from xml.etree import ElementTree

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import PackageMap, Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    JointActuatorIndex,
    JointIndex,
    ModelInstanceIndex,
    PrismaticJoint,
    PrismaticSpring,
    RevoluteJoint,
    RevoluteSpring,
)

from drake_abs.multibody.joint_limits import joint_springs
from drake_abs.multibody.parser_messages import drake_parser_messages, report_parser_messages

_COLLISION = re.compile(r"<collision\b[^>]*?/>|<collision\b.*?</collision\s*>", re.DOTALL)
_URDF_FILENAME = re.compile(r'(\bfilename\s*=\s*)(["\'])(.*?)\2')
_SDF_URI = re.compile(r"(<uri>\s*)(.*?)(\s*</uri>)", re.DOTALL)
_URDF_FLOATING = re.compile(
    r"<joint\b(?=[^>]*\btype\s*=\s*[\"']floating[\"'])[^>]*>.*?</joint\s*>", re.DOTALL
)


def read_stl(path: str | Path) -> np.ndarray:
    """The triangles (n, 3, 3) of a binary or ASCII STL file (its units)."""
    data = Path(path).read_bytes()
    if len(data) >= 84:
        n = int(np.frombuffer(data, "<u4", 1, 80)[0])
        if len(data) == 84 + 50 * n:  # binary (its header may also start with "solid")
            record = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
            return np.frombuffer(data, record, n, 84)["v"].astype(float)
    words = data.decode("ascii", errors="replace").split()
    coords = [
        float(words[i + 1 + j]) for i, w in enumerate(words) if w == "vertex" for j in range(3)
    ]
    return np.asarray(coords, float).reshape(-1, 3, 3)


def stl_to_obj(stl: str | Path, obj: str | Path) -> Path:
    """Write an STL mesh as a Wavefront OBJ (shared vertices, one flat normal per face): Drake's
    Meshcat draws .obj, .gltf and .dae meshes but not .stl."""
    tri = read_stl(stl)
    vertices, index = np.unique(tri.reshape(-1, 3), axis=0, return_inverse=True)
    faces = index.reshape(-1, 3) + 1
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    k = np.arange(1, len(faces) + 1)
    lines = [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in vertices]
    lines += [f"vn {x:.6g} {y:.6g} {z:.6g}" for x, y, z in normals]
    lines += [f"f {a}//{n} {b}//{n} {c}//{n}" for (a, b, c), n in zip(faces, k, strict=True)]
    obj = Path(obj)
    obj.parent.mkdir(parents=True, exist_ok=True)
    tmp = obj.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(obj)
    return obj


def _obj_for_stl(stl: Path) -> Path:
    """A cached OBJ copy of an STL mesh (in the temp folder, keyed by the file and its mtime)."""
    stat = stl.stat()
    key = hashlib.sha1(f"{stl.resolve()}:{stat.st_size}:{stat.st_mtime_ns}".encode()).hexdigest()
    obj = Path(tempfile.gettempdir()) / "drake_abs_meshes" / f"{stl.stem}_{key[:16]}.obj"
    return obj if obj.is_file() else stl_to_obj(stl, obj)


def _rewrite_reference(
    reference: str, base: Path, package_map: PackageMap, *, meshes: bool = True
) -> str:
    """A file reference of a model file, made absolute when relative, with STL meshes replaced
    by OBJ copies (unless ``meshes`` is False)."""
    ref = reference.strip()
    if not ref:
        return reference
    path = None
    for scheme in ("package://", "model://"):
        if ref.startswith(scheme):
            package, _, rest = ref[len(scheme) :].partition("/")
            if package_map.Contains(package):
                path = Path(package_map.GetPath(package)) / rest
    if ref.startswith("file://"):
        path = Path(ref[len("file://") :])
    elif "://" not in ref:
        path = Path(ref) if Path(ref).is_absolute() else (base / ref).resolve()
    if path is None:
        return reference
    if meshes and path.suffix.lower() == ".stl" and path.is_file():
        return str(_obj_for_stl(path))
    return str(path) if "://" not in ref else reference


class FloatingJoint(NamedTuple):
    """A URDF ``floating`` joint: its name, its child link, and the child's default pose in the
    world (the joint's ``<origin>``: ``xyz`` in m, ``rpy`` roll, pitch, yaw in rad)."""

    name: str
    link: str
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


def _triple(text: str | None, where: str) -> tuple[float, float, float]:
    if text is None:
        return (0.0, 0.0, 0.0)
    try:
        values = tuple(float(x) for x in text.split())
    except ValueError:
        values = ()
    if len(values) != 3:
        raise ValueError(f"{where} must be 3 numbers; got {text!r}")
    return values


def floating_joints(path: str | Path) -> tuple[FloatingJoint, ...]:
    """A URDF file's free joints (:class:`FloatingJoint`: name, child link, origin) of every
    ``<joint type="floating">``, whose parent must be the world (``()`` for other formats).

    MultibodyPlant's URDF parser does not build such joints (it warns and leaves the link
    free); :func:`add_models` leaves them out of what it parses and returns them, and
    :func:`drake_abs.multibody.parsing.add_model_specs` gives each link a quaternion floating
    joint of that name whose default pose is the joint's ``<origin>``: the way a model file asks
    for a floating base with no singular orientation (see :mod:`drake_abs.multibody.floating`)."""
    path = Path(path)
    if path.suffix.lower() != ".urdf":
        return ()
    out = []
    for joint in ElementTree.parse(path).getroot().iter("joint"):
        if joint.get("type") != "floating":
            continue
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None or parent.get("link") != "world":
            raise ValueError(
                f"{path}: floating joint {joint.get('name')!r} must have the world as its parent "
                "link (a free body)"
            )
        origin = joint.find("origin")
        where = f"{path}: floating joint {joint.get('name')!r}: <origin>"
        xyz = _triple(None if origin is None else origin.get("xyz"), f"{where} xyz")
        rpy = _triple(None if origin is None else origin.get("rpy"), f"{where} rpy")
        out.append(FloatingJoint(joint.get("name"), child.get("link"), xyz, rpy))
    return tuple(out)


def _model_text(
    path: Path, package_map: PackageMap, *, collisions: bool, obj_meshes: bool = False
) -> tuple[str, str] | None:
    """A URDF or SDF file's text with relative file references made absolute and URDF floating
    joints removed; without ``collisions``, also without ``<collision>`` elements and with STL
    meshes replaced by OBJ copies (with ``obj_meshes`` also with them). With its file type
    (``"urdf"`` or ``"sdf"``); None for other formats."""
    kind = path.suffix.lower().lstrip(".")
    if kind not in ("urdf", "sdf"):
        return None
    text = path.read_text()
    if not collisions:
        text = _COLLISION.sub("", text)
    base = path.resolve().parent

    def rewrite(ref: str) -> str:
        return _rewrite_reference(ref, base, package_map, meshes=obj_meshes or not collisions)

    if kind == "urdf":
        text = _URDF_FLOATING.sub("", text)
        text = _URDF_FILENAME.sub(lambda m: m[1] + m[2] + rewrite(m[3]) + m[2], text)
    else:
        text = _SDF_URI.sub(lambda m: m[1] + rewrite(m[2]) + m[3], text)
    return text, kind


def visual_only_model_text(
    path: Path, package_map: PackageMap | None = None
) -> tuple[str, str] | None:
    """A URDF or SDF file's text without its ``<collision>`` elements (nor URDF floating
    joints: see :func:`floating_joints`), with relative file references made absolute and STL
    meshes replaced by OBJ copies, and its file type (``"urdf"`` or ``"sdf"``); None for other
    formats."""
    return _model_text(Path(path), package_map or PackageMap(), collisions=False)


def add_models(
    parser: Parser,
    path: str | Path,
    *,
    collisions: bool = True,
    mjcf: MjcfInfo | None = None,
    obj_meshes: bool = False,
):
    """``parser.AddModels(path)``, and the file's :func:`floating_joints`, which the parser is
    not shown (the caller builds them): ``(model instances, floating joints)``.
    ``collisions=False`` leaves the file's collision geometry out and draws STL visual meshes
    through OBJ copies (see the module docstring); ``obj_meshes=True`` keeps the collision
    geometry and replaces a URDF's or SDF's STL meshes by OBJ copies, so that a plant registered
    with a SceneGraph takes them (it computes the convex hull of OBJ, VTK and glTF meshes only;
    :mod:`drake_abs.multibody.unmodelled_geometry` reads the hulls). For an MJCF file,
    ``mjcf`` (from :func:`read_mjcf`) with a total mass has its ``settotalmass`` applied.

    Drake's parser warnings are held back and reported once per file and process, with what
    drake-abs does about each ignored part
    (:func:`~drake_abs.multibody.parser_messages.report_parser_messages`)."""
    path = Path(path)
    floating = floating_joints(path)
    springs = friction = None
    if mjcf is not None:
        springs, friction = len(mjcf.springs), len(mjcf.frictionloss)
    dropped = () if mjcf is None else mjcf.dropped
    try:
        with drake_parser_messages() as messages:
            instances = _add_models(parser, path, floating, collisions, mjcf, obj_meshes)
    finally:  # also what a failed parse said
        report_parser_messages(path, messages, springs=springs, friction=friction, dropped=dropped)
    return instances, floating


def _add_models(
    parser: Parser,
    path: Path,
    floating: tuple[FloatingJoint, ...],
    collisions: bool,
    mjcf: MjcfInfo | None,
    obj_meshes: bool = False,
):
    """The parse of :func:`add_models`: the model instances."""
    if mjcf is not None and mjcf.total_mass is not None:
        text, kind = _mjcf_with_total_mass(path, mjcf.total_mass), "xml"
    elif collisions and not floating and not obj_meshes:
        return parser.AddModels(str(path))
    else:
        rewritten = _model_text(
            path, parser.package_map(), collisions=collisions, obj_meshes=obj_meshes
        )
        if rewritten is None:
            return parser.AddModels(str(path))
        text, kind = rewritten
    with tempfile.TemporaryDirectory(prefix="drake_abs_model_") as folder:
        copy = Path(folder) / f"{path.stem}.{kind}"  # absolute references only
        copy.write_text(text)
        return parser.AddModels(str(copy))


def add_models_without_collisions(parser: Parser, path: Path):
    """``parser.AddModels(path)`` with the file's collision geometry left out and STL visual
    meshes drawn through OBJ copies (see the module docstring); a URDF's floating joints are
    left out too, their links free (as MultibodyPlant's own parser leaves them)."""
    return add_models(parser, path, collisions=False)[0]


# --- MuJoCo (MJCF) files ---------------------------------------------------------------------

#: What a scene may drop explicitly from an MJCF file (``ModelSpec.ignore``): the attributes
#: neither Drake nor the step models and that do not change what the rest of the model means.
IGNORABLE = ("joint.stiffness", "joint.frictionloss", "joint.armature")

_ACTUATORS = ("general", "motor", "position", "velocity", "intvelocity", "damper", "cylinder",
              "muscle", "adhesion", "plugin")  # fmt: skip


class _MjcfDefaults:
    """MJCF default classes: an attribute of an element is its own, or its class's, or that
    class's parent's ... (the top-level class is ``main``); every actuator shortcut shares one
    default (``actuator``)."""

    def __init__(self, root: ElementTree.Element):
        self.classes: dict[str, tuple[str | None, dict[str, dict[str, str]]]] = {}
        for top in root.findall("default"):
            self._add(top, None)

    def _add(self, node: ElementTree.Element, parent: str | None) -> None:
        attrs: dict[str, dict[str, str]] = {}
        for child in node:
            if child.tag != "default":
                tag = "actuator" if child.tag in _ACTUATORS else child.tag
                attrs.setdefault(tag, {}).update(child.attrib)
        name = node.get("class") or "main"
        self.classes[name] = (parent, attrs)
        for child in node.findall("default"):
            self._add(child, name)

    def get(self, element: ElementTree.Element, tag: str, cls: str | None, attr: str):
        if attr in element.attrib:
            return element.get(attr)
        while cls is not None and cls in self.classes:
            parent, attrs = self.classes[cls]
            if attr in attrs.get(tag, {}):
                return attrs[tag][attr]
            cls = parent
        return None


#: MJCF default classes, for readers of other elements' attributes
#: (:mod:`drake_abs.multibody.mjcf_contact_parameters`)
MjcfDefaults = _MjcfDefaults


def _floats(text: str | None, where: str) -> tuple[float, ...]:
    try:
        return tuple(float(x) for x in (text or "").split())
    except ValueError:
        raise ValueError(f"{where} must be numbers; got {text!r}") from None


@dataclass(frozen=True)
class MjcfActuator:
    """An MJCF ``<motor>``: the joint it drives, its ``gear`` and its effort limit as a joint
    torque or force, ``gear * min(ctrlrange, forcerange)`` (N m or N; inf: unlimited). The
    step's input for it is that torque (MuJoCo's ``ctrl`` times ``gear``)."""

    name: str
    joint: str
    gear: float
    effort_limit: float


@dataclass(frozen=True)
class MjcfInfo:
    """What :func:`read_mjcf` read from an MJCF file that Drake's parser drops.

    Attributes:
        actuators: the ``<motor>`` elements, in file order.
        total_mass: ``<compiler settotalmass>`` (kg), or None.
        joints: ``(name, type, qpos size)`` in MuJoCo's qpos order (a free joint is named by
            its body: Drake leaves such a body free).
        keyframes: ``{name: (qpos, qvel)}`` of the ``<keyframe>`` keys (unnamed keys by their
            index, ``"0"``, ``"1"``, ...; an absent qpos is None).
        dropped: what the scene's ``ignore`` dropped, one line each.
        springs: ``(joint, stiffness, springref)`` of every hinge or slide joint with a
            stiffness > 0 (N m / rad or N / m; springref in rad or m, converted from degrees
            where ``<compiler angle="degree">``, MuJoCo's default), in file order; none when
            ``joint.stiffness`` is ignored.
        frictionloss: ``(joint, frictionloss)`` of every hinge or slide joint with a
            ``frictionloss`` > 0 (its dry friction bound, N m or N), in file order; none when
            ``joint.frictionloss`` is ignored.
    """

    actuators: tuple[MjcfActuator, ...]
    total_mass: float | None
    joints: tuple[tuple[str, str, int], ...]
    keyframes: dict
    dropped: tuple[str, ...]
    springs: tuple[tuple[str, float, float], ...] = ()
    frictionloss: tuple[tuple[str, float], ...] = ()


_QPOS_SIZE = {"free": 7, "ball": 4, "slide": 1, "hinge": 1}


def read_mjcf(path: str | Path, ignore: tuple[str, ...] = ()) -> MjcfInfo:
    """Read what Drake's MJCF parser drops from the file at ``path`` (motors' effort limits,
    ``settotalmass``, keyframes, the joints' springs: ``stiffness`` towards ``springref``, and
    their dry friction, ``frictionloss``), and refuse what neither it nor the step models
    (``ValueError`` naming each element and attribute): ``armature`` on a joint with no motor
    (Drake keeps armature only as a motor's reflected inertia), ``stiffness`` or
    ``frictionloss`` on a ball or free joint (or negative), unless ``ignore`` lists
    ``"joint.armature"``, ``"joint.stiffness"`` or ``"joint.frictionloss"`` (they are then
    dropped, and listed in ``dropped``; ``"joint.stiffness"`` drops every spring,
    ``"joint.frictionloss"`` every friction); actuators other than ``<motor>`` on a joint, a
    multi-component ``gear``, asymmetric ``ctrlrange`` or ``forcerange``, tendons and equality
    constraints, always."""
    path = Path(path)
    unknown = sorted(set(ignore) - set(IGNORABLE))
    if unknown:
        raise ValueError(f"{path}: ignore may list {list(IGNORABLE)}; got {unknown}")
    root = ElementTree.parse(path).getroot()
    if root.tag != "mujoco":
        raise ValueError(f"{path}: an MJCF file has a <mujoco> root element; got <{root.tag}>")
    defaults = _MjcfDefaults(root)
    compiler = {k: v for c in root.findall("compiler") for k, v in c.attrib.items()}
    autolimits = compiler.get("autolimits", "true") == "true"
    degrees = compiler.get("angle", "degree") == "degree"  # MuJoCo's default unit of angles
    problems: list[tuple[str | None, str]] = []  # (ignore key or None: always refused, what)

    actuators, actuated = [], set()
    for block in root.findall("actuator"):
        for k, act in enumerate(block):
            cls = act.get("class") or "main"
            name = act.get("name") or f"{act.tag}{k}"
            where = f"actuator <{act.tag}> {name!r}"
            if act.tag != "motor":
                problems.append((None, f"{where}: only <motor> actuators are supported"))
                continue
            joint = act.get("joint")
            if joint is None:
                problems.append((None, f"{where}: a motor needs a joint (tendon, site and body "
                                       "transmissions are not supported)"))  # fmt: skip
                continue
            gear = _floats(defaults.get(act, "actuator", cls, "gear") or "1", f"{where} gear")
            if any(g != 0 for g in gear[1:]):
                problems.append((None, f"{where}: gear must be one number; got {gear}"))
            limit = float("inf")
            for attr in ("ctrl", "force"):
                lims = defaults.get(act, "actuator", cls, f"{attr}limited")
                text = defaults.get(act, "actuator", cls, f"{attr}range")
                bounds = _floats(text, f"{where} {attr}range")
                on = lims == "true" or (lims in (None, "auto") and autolimits and bounds != ())
                if not on or not bounds:
                    continue
                if len(bounds) != 2 or bounds[0] != -bounds[1]:
                    problems.append((None, f"{where}: {attr}range must be symmetric [-a, a] "
                                           f"(one effort limit); got {text!r}"))  # fmt: skip
                    continue
                limit = min(limit, abs(bounds[1]))
            actuators.append(MjcfActuator(name, joint, gear[0], abs(gear[0]) * limit))
            actuated.add(joint)

    joints, springs, friction = [], [], []
    parents = {child: parent for parent in root.iter() for child in parent}
    for world in root.findall("worldbody"):
        for body in world.iter("body"):
            childclass = None
            node = body
            while node is not None and childclass is None:
                childclass = node.get("childclass")
                node = parents.get(node)
            for joint in body:
                if joint.tag == "freejoint":
                    joints.append((body.get("name"), "free", 7))
                    continue
                if joint.tag != "joint":
                    continue
                cls = joint.get("class") or childclass or "main"
                kind = defaults.get(joint, "joint", cls, "type") or "hinge"
                name = joint.get("name")
                joints.append(
                    (name if kind != "free" else body.get("name"), kind, _QPOS_SIZE[kind])
                )
                where = f"joint {name!r}"
                stiffness = _floats(defaults.get(joint, "joint", cls, "stiffness"),
                                    f"{where} stiffness")  # fmt: skip
                if stiffness and stiffness[0] != 0:
                    if stiffness[0] < 0 or kind not in ("hinge", "slide"):
                        problems.append(("joint.stiffness", f"{where}: stiffness={stiffness[0]:g} "
                                         f"(a spring on a {kind} joint; springs on hinge and "
                                         "slide joints only, stiffness >= 0)"))  # fmt: skip
                    else:
                        ref = _floats(defaults.get(joint, "joint", cls, "springref") or "0",
                                      f"{where} springref")  # fmt: skip
                        ref = ref[0] if ref else 0.0
                        if kind == "hinge" and degrees:
                            ref = float(np.deg2rad(ref))
                        springs.append((name, float(stiffness[0]), float(ref)))
                loss = _floats(defaults.get(joint, "joint", cls, "frictionloss"),
                               f"{where} frictionloss")  # fmt: skip
                if loss and loss[0] != 0:
                    if loss[0] < 0 or kind not in ("hinge", "slide"):
                        problems.append(("joint.frictionloss", f"{where}: frictionloss="
                                         f"{loss[0]:g} (dry friction on a {kind} joint; on "
                                         "hinge and slide joints only, >= 0)"))  # fmt: skip
                    else:
                        friction.append((name, float(loss[0])))
                text = defaults.get(joint, "joint", cls, "armature")
                value = _floats(text, f"{where} armature")
                if value and value[0] != 0 and name not in actuated:  # else Drake: the motor's
                    problems.append(("joint.armature", f"{where}: armature={text} (armature of "
                                     "a joint no motor drives)"))  # fmt: skip
    for tag in ("tendon", "equality"):
        for block in root.findall(tag):
            for element in block:
                problems.append((None, f"<{tag}> <{element.tag}> {element.get('name', '')!r}: "
                                       f"{tag}s are not supported"))  # fmt: skip

    refused = [what for key, what in problems if key is None or key not in ignore]
    if refused:
        keys = sorted({key for key, what in problems if key is not None and what in refused})
        hint = f"; list {keys} in the model's ignore to drop the joint attributes" if keys else ""
        raise ValueError(
            f"{path}: not supported (remove from the file{hint}): " + "; ".join(refused)
        )

    keyframes = {}
    for block in root.findall("keyframe"):
        for key in block.findall("key"):
            name = key.get("name") or str(len(keyframes))
            where = f"keyframe key {name!r}"
            qpos, qvel = key.get("qpos"), key.get("qvel")
            keyframes[name] = (
                None if qpos is None else np.array(_floats(qpos, f"{where} qpos")),
                None if qvel is None else np.array(_floats(qvel, f"{where} qvel")),
            )
    total = compiler.get("settotalmass")
    total_mass = None
    if total is not None and float(total) > 0:  # MuJoCo: a value <= 0 leaves the masses
        total_mass = float(total)
    dropped = tuple(what for key, what in problems if key in ignore)
    if "joint.stiffness" in ignore:
        dropped += tuple(f"joint {n!r}: stiffness={k:g} (a joint spring)" for n, k, _ in springs)
        springs = []
    if "joint.frictionloss" in ignore:
        dropped += tuple(
            f"joint {n!r}: frictionloss={f:g} (dry joint friction)" for n, f in friction
        )
        friction = []
    return MjcfInfo(
        tuple(actuators), total_mass, tuple(joints), keyframes, dropped, tuple(springs),
        tuple(friction),
    )  # fmt: skip


def _mjcf_with_total_mass(path: Path, total_mass: float) -> str:
    """The MJCF file's text with ``<compiler settotalmass>`` applied as MuJoCo applies it: every
    body's mass and inertia (as Drake computes them from the file) scaled by one factor so that
    they add up to ``total_mass``, written as explicit ``<inertial>`` elements (and
    ``inertiafromgeom="false"``); relative file references made absolute."""
    scratch = MultibodyPlant(0.0)
    drake_log = logging.getLogger("drake")
    level = drake_log.level
    drake_log.setLevel(logging.ERROR)  # the warnings are the second parse's to give
    try:
        (instance,) = Parser(scratch).AddModels(str(path))[:1]
    finally:
        drake_log.setLevel(level)
    inertia = {}
    for i in scratch.GetBodyIndices(instance):
        body = scratch.get_body(i)
        inertia[body.name()] = body.default_spatial_inertia()
    mass = sum(M.get_mass() for M in inertia.values())
    if not mass > 0:
        raise ValueError(f"{path}: settotalmass={total_mass} given, but the bodies have no mass")
    scale = total_mass / mass
    root = ElementTree.parse(path).getroot()
    base = path.resolve().parent
    for compiler in root.findall("compiler"):
        compiler.attrib.pop("settotalmass", None)
        compiler.set("inertiafromgeom", "false")
        for attr in ("meshdir", "texturedir", "assetdir"):
            if compiler.get(attr) and not Path(compiler.get(attr)).is_absolute():
                compiler.set(attr, str(base / compiler.get(attr)))
    if not root.findall("compiler"):
        root.insert(0, ElementTree.Element("compiler", inertiafromgeom="false"))
    compiler = root.find("compiler")
    for attr in ("meshdir", "texturedir"):
        compiler.attrib.setdefault(attr, str(base))
    for include in root.iter("include"):
        if include.get("file") and not Path(include.get("file")).is_absolute():
            include.set("file", str(base / include.get("file")))
    for world in root.findall("worldbody"):
        for body in world.iter("body"):
            name = body.get("name")
            if name not in inertia:
                raise ValueError(
                    f"{path}: settotalmass needs every <body> named; found {name!r}, not one of "
                    f"Drake's bodies {sorted(inertia)}"
                )
            for old in body.findall("inertial"):
                body.remove(old)
            M = inertia[name]
            if not M.get_mass() > 0:
                continue
            com = np.asarray(M.get_com())
            I = M.Shift(com).CalcRotationalInertia().CopyToFullMatrix3() * scale  # noqa: N806
            full = (I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])
            body.insert(
                0,
                ElementTree.Element(
                    "inertial",
                    pos=" ".join(f"{x:.17g}" for x in com),
                    mass=f"{M.get_mass() * scale:.17g}",
                    fullinertia=" ".join(f"{x:.17g}" for x in full),
                ),
            )
    return ElementTree.tostring(root, encoding="unicode")


def apply_mjcf(
    plant: MultibodyPlant,
    instance: ModelInstanceIndex,
    info: MjcfInfo,
    keyframe: str | None = None,
    *,
    where: str = "model",
) -> None:
    """Apply to the model ``instance`` parsed (not finalized) from an MJCF file what Drake's
    parser drops (see :func:`read_mjcf`): each motor's effort limit as a joint torque (``gear``
    times ``ctrlrange``, clipped by ``forcerange``), each joint spring as a ``RevoluteSpring``
    (hinge) or ``PrismaticSpring`` (slide) force element, and the joint positions of the
    keyframe named ``keyframe`` (hinge and slide joints by name; a free body's ``(x, y, z, qw,
    qx, qy, qz)`` as its default pose)."""
    drake_actuators = [
        plant.get_joint_actuator(i)
        for i in plant.GetJointActuatorIndices()  # (per instance only once finalized)
        if plant.get_joint_actuator(i).model_instance() == instance
    ]
    if len(drake_actuators) != len(info.actuators):
        raise ValueError(
            f"{where}: Drake built {len(drake_actuators)} actuators from the file; its "
            f"<actuator> lists {len(info.actuators)} motors"
        )
    for actuator, motor in zip(drake_actuators, info.actuators, strict=True):
        if actuator.joint().name() != motor.joint:
            raise ValueError(
                f"{where}: actuator {actuator.name()!r} drives {actuator.joint().name()!r}; the "
                f"file's motor {motor.name!r} drives {motor.joint!r}"
            )
        actuator.set_effort_limit(motor.effort_limit)
    for name, stiffness, reference in info.springs:
        joint = plant.GetJointByName(name, instance)
        if isinstance(joint, RevoluteJoint):
            plant.AddForceElement(RevoluteSpring(joint, reference, stiffness))
        elif isinstance(joint, PrismaticJoint):
            plant.AddForceElement(PrismaticSpring(joint, reference, stiffness))
        else:
            raise ValueError(
                f"{where}: joint {name!r} has a spring but Drake built it as a "
                f"{type(joint).__name__} (expected a RevoluteJoint or PrismaticJoint)"
            )
    if keyframe is None:
        return
    if keyframe not in info.keyframes:
        raise ValueError(
            f"{where}: keyframe must name a <keyframe> <key> of the file, one of "
            f"{sorted(info.keyframes)}; got {keyframe!r}"
        )
    qpos, qvel = info.keyframes[keyframe]
    if qvel is not None and np.any(qvel != 0):
        raise ValueError(
            f"{where}: keyframe {keyframe!r} has a nonzero qvel: give the velocities in the "
            "scene's initial_state v"
        )
    if qpos is None:
        return
    nq = sum(size for _, _, size in info.joints)
    if qpos.size != nq:
        raise ValueError(
            f"{where}: keyframe {keyframe!r} qpos has {qpos.size} entries; the file's joints "
            f"have {nq}"
        )
    k = 0
    for name, kind, size in info.joints:
        values = qpos[k : k + size]
        k += size
        if kind == "free":
            body = plant.GetBodyByName(name, instance)
            pose = RigidTransform(Quaternion(values[3:] / np.linalg.norm(values[3:])), values[:3])
            plant.SetDefaultFloatingBaseBodyPose(body, pose)
        elif kind in ("hinge", "slide"):
            plant.GetJointByName(name, instance).set_default_positions(values)
        else:
            raise ValueError(
                f"{where}: keyframe {keyframe!r}: joint {name!r} is a {kind} joint; keyframes "
                "set hinge, slide and free joints only"
            )


def model_report(plant: MultibodyPlant) -> dict:
    """What a finalized plant holds of its model files, as the step uses it: per joint with
    degrees of freedom ``{name, type, q_index, v_index, lower, upper, damping, armature,
    stiffness, springref}`` (limits, damping and spring of its first degree of freedom;
    armature: the reflected inertia of the actuators on it, kg m^2 or kg; stiffness in N m / rad
    or N / m towards springref in rad or m, from the plant's joint springs,
    :func:`~drake_abs.multibody.joint_limits.joint_springs`) and per actuator ``{name, joint,
    gear, rotor_inertia, reflected_inertia, effort_limit}`` (the effort limit a joint torque or
    force, N m or N), and the total mass (kg)."""
    springs = joint_springs(plant)
    reflected = {}
    actuators = []
    for i in plant.GetJointActuatorIndices():
        a = plant.get_joint_actuator(JointActuatorIndex(int(i)))
        reflected[a.joint().name()] = reflected.get(a.joint().name(), 0.0) + float(
            a.default_reflected_inertia()
        )
        actuators.append(
            {
                "name": a.name(),
                "joint": a.joint().name(),
                "gear": float(a.default_gear_ratio()),
                "rotor_inertia": float(a.default_rotor_inertia()),
                "reflected_inertia": float(a.default_reflected_inertia()),
                "effort_limit": float(a.effort_limit()),
            }
        )
    joints = []
    for i in plant.GetJointIndices():
        j = plant.get_joint(JointIndex(int(i)))
        if j.num_velocities() == 0:
            continue
        joints.append(
            {
                "name": j.name(),
                "type": j.type_name(),
                "q_index": int(j.position_start()),
                "v_index": int(j.velocity_start()),
                "lower": float(j.position_lower_limits()[0]),
                "upper": float(j.position_upper_limits()[0]),
                "damping": float(j.default_damping_vector()[0]),
                "armature": reflected.get(j.name(), 0.0),
                "stiffness": float(springs.stiffness[j.velocity_start()]),
                "springref": float(springs.reference[j.velocity_start()]),
            }
        )
    mass = plant.CalcTotalMass(plant.CreateDefaultContext())
    return {"joints": joints, "actuators": actuators, "mass": float(mass)}


def format_model_report(report: dict) -> str:
    """:func:`model_report` as a text table (with each joint's dry friction where the report
    has it: :meth:`drake_abs.multibody.builder.SceneModel.model_report`)."""
    lines = [f"total mass {report['mass']:.6g} kg", "joints:"]
    lines.append(f"  {'name':24s} {'type':20s} {'q':>3s} {'v':>3s} {'lower':>10s} {'upper':>10s} "
                 f"{'damping':>9s} {'armature':>9s} {'stiffness':>9s} "
                 f"{'springref':>9s} {'friction':>9s}")  # fmt: skip
    for j in report["joints"]:
        lines.append(
            f"  {j['name']:24s} {j['type']:20s} {j['q_index']:3d} {j['v_index']:3d} "
            f"{j['lower']:10.4g} {j['upper']:10.4g} {j['damping']:9.4g} {j['armature']:9.4g} "
            f"{j['stiffness']:9.4g} {j['springref']:9.4g} {j.get('frictionloss', 0.0):9.4g}"
        )
    lines.append("actuators:")
    lines.append(f"  {'name':24s} {'joint':24s} {'gear':>8s} {'effort limit':>13s}")
    for a in report["actuators"]:
        lines.append(
            f"  {a['name']:24s} {a['joint']:24s} {a['gear']:8.4g} {a['effort_limit']:13.6g}"
        )
    return "\n".join(lines)
