"""Package resolution: where a scene's ``package://<package>/<path>`` (a model file, a scene
file) is on disk.

The packages are ``drake_abs`` (this package's folder: ``package://drake_abs/models/<file>``,
``package://drake_abs/scenes/<file>``) and, when installed, ``example-robot-data``
(``package://example-robot-data/robots/<robot>_description/...``, the form the robots' own URDFs
use for their meshes; each ``<robot>_description`` is a package too) and ``gymnasium`` (its
MuJoCo model files: ``package://gymnasium/hopper.xml``). URIs resolve through Drake's
``PackageMap``. The prefixes of earlier versions, ``drake_abs:<path>``,
``example-robot-data:<path>`` (under ``robots/``) and ``gymnasium:<file>``, are still read as
aliases of these URIs (:data:`MODEL_FILE_ALIASES`).

This module is the bottom of :mod:`drake_abs.multibody`'s scene modules: it imports none of them.
"""

from __future__ import annotations

import difflib
import functools
import importlib.util
import sys
from pathlib import Path

from pydrake.multibody.parsing import PackageMap

#: The folder of the ``drake_abs`` package (``models/``, ``scenes/``).
PACKAGE_DIR = Path(__file__).resolve().parents[1]


@functools.cache
def example_robot_data_dir() -> Path:
    """The installed example-robot-data share folder (…/share/example-robot-data)."""
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
    """The packages a ``package://<package>/<path>`` may name, name -> folder: ``drake_abs``
    (this package's folder: ``models/``, ``scenes/``); when installed, ``example-robot-data``
    (its share folder: ``robots/<robot>_description/...``) and each of its robots' own
    ``<robot>_description`` folders, and ``gymnasium`` (its MuJoCo model files,
    ``gymnasium/envs/mujoco/assets``; found without importing gymnasium). A copy of a list made
    once per process."""
    return dict(_package_folders())


@functools.cache
def _package_folders() -> dict[str, Path]:
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
    on disk. ``ValueError`` for an unknown package, ``FileNotFoundError`` for a missing file
    (``what``: the kind of file, for the message), both prefixed with ``where``."""
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
        prefix = f"{where}: " if where else ""
        raise FileNotFoundError(f"{prefix}{what} {file!r} not found (looked at {path.absolute()})")
    return path
