"""What produced a result: the drake-abs version, the git commit of its source, and the versions
of the libraries that change its numbers.

:func:`provenance` returns it as a JSON-able dict, which every sweep point records in its
``point.json`` (and the sweep in ``sweep.json``, :mod:`drake_abs.parallel.sweep`)::

    {"drake_abs_version": "0.2.0",
     "commit": "d80ba48...",          # None: not imported from a git checkout, or no git
     "dirty": False,                  # uncommitted changes (git status --porcelain); None as above
     "dependencies": {"drake": "1.58.0", "numpy": "2.2.1", ..., "torch": None}}

Nothing here fails: a package that is not installed is recorded as None, a drake-abs that is not
installed (a bare checkout) as ``"unknown"``, and the commit as None when the package is not
imported from the top of a git checkout (e.g. installed into site-packages), when git is
missing, or when it does not answer within :data:`GIT_TIMEOUT` seconds.

:func:`differences` compares a recorded provenance with the current one, as a sweep does before
it reuses a point: the drake-abs version and every dependency count; the commit does not (see
:func:`differences`).
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Mapping
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

#: The distributions whose versions a result records, the ones that compute its numbers (the
#: simulators and solvers, the array and learning libraries).
DEPENDENCIES = (
    "drake",
    "numpy",
    "scipy",
    "numba",
    "osqp",
    "pin",
    "gymnasium",
    "mujoco",
    "stable-baselines3",
    "sb3-contrib",
    "torch",
)
#: Seconds each git command may take before the commit is recorded as unknown (None).
GIT_TIMEOUT = 5.0
#: The folder holding the ``drake_abs`` package (the top of the checkout when it is one).
SOURCE_ROOT = Path(__file__).resolve().parents[2]


def package_version() -> str:
    """The installed drake-abs version, or ``"unknown"`` for a checkout that is not installed."""
    try:
        return version("drake-abs")
    except PackageNotFoundError:
        return "unknown"


def dependency_versions(names: tuple[str, ...] = DEPENDENCIES) -> dict[str, str | None]:
    """The installed version of every distribution in ``names`` (None for one not installed)."""
    out: dict[str, str | None] = {}
    for name in names:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = None
    return out


def _git(root: Path, *args: str) -> str | None:
    """The output of ``git -C root ARGS``, or None when git is missing, fails or is slow."""
    try:
        done = subprocess.run(
            ["git", "-C", str(root), *args], capture_output=True, text=True,
            timeout=GIT_TIMEOUT, check=False, stdin=subprocess.DEVNULL,
        )  # fmt: skip
    except (OSError, subprocess.SubprocessError, ValueError):
        return None
    return done.stdout if done.returncode == 0 else None


def source_commit(root: str | Path | None = None) -> dict[str, Any]:
    """``{"commit": SHA, "dirty": bool}`` of the git checkout whose top folder is ``root``
    (default :data:`SOURCE_ROOT`, the folder the package is imported from); ``dirty`` is whether
    ``git status --porcelain`` lists anything (changed, staged or untracked files that are not
    ignored). Both are None when ``root`` is not the top of a checkout (a package installed into
    site-packages that sits inside some other repository does not count), when the checkout has
    no commit yet, or when git is missing or times out."""
    unknown: dict[str, Any] = {"commit": None, "dirty": None}
    try:
        folder = Path(SOURCE_ROOT if root is None else root).resolve()
    except (OSError, RuntimeError):
        return unknown
    if not folder.is_dir():
        return unknown
    answer = _git(folder, "rev-parse", "--show-toplevel", "HEAD")
    lines = answer.splitlines() if answer else []
    if len(lines) != 2:
        return unknown
    try:
        if Path(lines[0]).resolve() != folder:
            return unknown
    except (OSError, RuntimeError):
        return unknown
    status = _git(folder, "status", "--porcelain")
    return {"commit": lines[1], "dirty": None if status is None else bool(status.strip())}


def provenance(root: str | Path | None = None) -> dict[str, Any]:
    """What produces a result in this process (see the module doc): ``drake_abs_version``,
    ``commit`` and ``dirty`` (of the checkout at ``root``, default :data:`SOURCE_ROOT`; None if
    there is none) and ``dependencies`` (name -> version or None). JSON-able; never raises."""
    return {
        "drake_abs_version": package_version(),
        **source_commit(root),
        "dependencies": dependency_versions(),
    }


def _text(value: Any) -> str:
    """A recorded value as it reads in a reason: JSON, except that None reads ``absent``."""
    if value is None:
        return "absent"
    if isinstance(value, str):
        return value
    return json.dumps(value, sort_keys=True)


def differences(recorded: Any, current: Mapping[str, Any]) -> list[str]:
    """Why a result recorded with provenance ``recorded`` is not one the current code would
    produce (``current``: :func:`provenance`), as reasons that read ``recorded != current``:
    ``"drake-abs: 0.1.0 != 0.2.0"``, ``"numpy: 2.1.0 != 2.2.1"`` (None reads ``absent``; a
    dependency the record does not list reads ``not recorded``). Empty when they match.

    The commit and the dirty flag are not compared: the package version is the release key (a
    result is reused when its whole Config and package version match), so work on a checkout
    between releases does not recompute finished results; the commit stays recorded, to be
    shown and looked up."""
    if not isinstance(recorded, Mapping):
        return ["no provenance recorded (written before drake-abs recorded it)"]
    reasons = []
    old, new = recorded.get("drake_abs_version"), current.get("drake_abs_version")
    if old != new:
        reasons.append(f"drake-abs: {_text(old)} != {_text(new)}")
    old_deps = recorded.get("dependencies")
    old_deps = old_deps if isinstance(old_deps, Mapping) else {}
    new_deps = current.get("dependencies") or {}
    for name in new_deps:  # a library no longer tracked does not count
        missing = name not in old_deps
        old, new = old_deps.get(name), new_deps.get(name)
        if missing and new is None:
            continue  # not recorded and not installed: nothing differs
        if missing or old != new:
            shown = "not recorded" if missing else _text(old)
            reasons.append(f"{name}: {shown} != {_text(new)}")
    return reasons


def short_commit(record: Any) -> str:
    """The commit of a provenance record as it is shown: ``d80ba48``, ``d80ba48 (dirty)``, or
    ``unknown`` (no checkout, no git, or no record)."""
    commit = record.get("commit") if isinstance(record, Mapping) else None
    if not isinstance(commit, str) or not commit:
        return "unknown"
    return commit[:7] + (" (dirty)" if record.get("dirty") else "")
