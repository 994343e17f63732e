"""Model files parsed without their collision geometry, and URDF floating joints.

With a SceneGraph attached, Drake refuses some collision geometry (example-robot-data's STL
collision meshes: "MakeConvexHull only applies to .obj, .vtk, and .gltf meshes"), and this
package's plants do not need it: contacts are the scene's declared points. URDF and SDF files
are read as text, their ``<collision>`` elements removed and relative file references made
absolute, and parsed from that copy; other formats are parsed unchanged. Drake's Meshcat does not
draw STL meshes either (it warns and skips them), so STL visual meshes are replaced by OBJ copies,
converted once and cached in the temp folder.

URDF ``floating`` joints (a free body's 6-dof joint to the world), which MultibodyPlant's parser
does not build, are left out of the parsed text and returned by :func:`add_models`: the builder
gives those bodies a quaternion floating joint (:func:`floating_joints`).
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
from pydrake.multibody.parsing import PackageMap, Parser

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


def floating_joints(path: str | Path) -> tuple[tuple[str, str], ...]:
    """A URDF file's free joints: ``(joint name, child link)`` of every ``<joint
    type="floating">``, whose parent must be the world (``()`` for other formats, or none).

    MultibodyPlant's URDF parser does not build such joints (it warns and leaves the link
    free); :func:`add_models` leaves them out of what it parses and returns them, and
    :func:`drake_abs.multibody.builder.add_scene_models` gives each link a quaternion floating
    joint of that name: the way a model file asks for a floating base with no singular
    orientation (see :mod:`drake_abs.multibody.floating`)."""
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
        out.append((joint.get("name"), child.get("link")))
    return tuple(out)


def _model_text(path: Path, package_map: PackageMap, *, collisions: bool) -> tuple[str, str] | None:
    """A URDF or SDF file's text with relative file references made absolute and URDF floating
    joints removed; without ``collisions``, also without ``<collision>`` elements and with STL
    meshes replaced by OBJ copies. With its file type (``"urdf"`` or ``"sdf"``); None for other
    formats."""
    kind = path.suffix.lower().lstrip(".")
    if kind not in ("urdf", "sdf"):
        return None
    text = path.read_text()
    if not collisions:
        text = _COLLISION.sub("", text)
    base = path.resolve().parent

    def rewrite(ref: str) -> str:
        return _rewrite_reference(ref, base, package_map, meshes=not collisions)

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


def add_models(parser: Parser, path: str | Path, *, collisions: bool = True):
    """``parser.AddModels(path)``, and the file's :func:`floating_joints`, which the parser is
    not shown (the caller builds them): ``(model instances, floating joints)``.
    ``collisions=False`` leaves the file's collision geometry out and draws STL visual meshes
    through OBJ copies (see the module docstring)."""
    path = Path(path)
    floating = floating_joints(path)
    if collisions and not floating:
        return parser.AddModels(str(path)), floating
    rewritten = _model_text(path, parser.package_map(), collisions=collisions)
    if rewritten is None:
        return parser.AddModels(str(path)), floating
    text, kind = rewritten
    with tempfile.TemporaryDirectory(prefix="drake_abs_model_") as folder:
        copy = Path(folder) / f"{path.stem}.{kind}"  # absolute references only
        copy.write_text(text)
        return parser.AddModels(str(copy)), floating


def add_models_without_collisions(parser: Parser, path: Path):
    """``parser.AddModels(path)`` with the file's collision geometry left out and STL visual
    meshes drawn through OBJ copies (see the module docstring); a URDF's floating joints are
    left out too, their links free (as MultibodyPlant's own parser leaves them)."""
    return add_models(parser, path, collisions=False)[0]
