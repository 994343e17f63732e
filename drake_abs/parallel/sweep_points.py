"""One point of a sweep: its folder name, running it in a temporary folder, and its record.

A point is a dict of values (configuration overrides, e.g. ``{"seed": 0, "horizons": (10,)}``).
Its folder name is derived from the values alone, in their order: ``seed=0,horizons=10``
(lists joined with ``+``, booleans ``true``/``false``, None ``none``, no values ``default``).
Characters other than letters, digits and ``._+=,-`` become ``_``; a name that had to be changed
that way, or is longer than 120 characters, gets ``~`` and ten hex digits of the SHA-256 of the
values appended, so different values never share a folder.

:func:`execute_point` is what a worker runs: ``fn(values, folder)`` in a fresh temporary folder
on whichever machine executes it; it returns the summary (JSON-safe) and the bytes of every file
``fn`` wrote, or, when ``fn`` raised, the error with its full traceback. :func:`store_point` is
what the driver does with that: it writes the files into ``out/points/<name>/`` (paths that named
the temporary folder, in the summary and in text files, are rewritten to name that folder) and
``point.json`` last, atomically, so a ``point.json`` that says ``done`` means every file is there.
The record says what produced the point: the function's description, the point's whole resolved
configuration when the function can tell it, and the provenance (drake-abs version, commit,
dependency versions: :mod:`drake_abs.parallel.provenance`) of the process that ran it.
:func:`differences` says how two records' fields differ, field by field.

A point's temporary folder is removed when it ends, also when it is interrupted (Ctrl-C); one
left by a process that was killed is removed when the next sweep starts
(:func:`remove_stale_folders`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
import shutil
import socket
import tempfile
import time
import traceback
from collections.abc import Callable, Mapping
from numbers import Integral, Real
from pathlib import Path
from typing import Any

#: The record of one point inside its folder.
POINT_FILE = "point.json"
#: Files whose text is searched for the temporary folder's path (rewritten to the point's folder).
TEXT_SUFFIXES = (".json", ".csv", ".txt", ".md", ".yaml", ".yml", ".log", ".tsv")
#: Temporary folders of points start with this, so that their paths cannot be mistaken.
TEMP_PREFIX = "drake-abs-point-"
MAX_NAME = 120
_UNSAFE = re.compile(r"[^A-Za-z0-9._+=,-]")


# ----------------------------------------------------------------------------------- JSON values


def jsonable(value: Any) -> Any:
    """``value`` as plain JSON types: numpy scalars and arrays to Python numbers and (nested)
    lists, tuples and sets to lists, mapping keys to strings, paths to strings, dataclasses to
    dicts. Anything else is recorded as its ``repr()``. Non-finite floats stay floats (Python's
    json writes them as NaN and Infinity, as the experiments' own summaries do)."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, Integral):
        return int(value)
    if isinstance(value, Real):
        return float(value)
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, set | frozenset):
        return [jsonable(v) for v in sorted(value, key=repr)]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return jsonable(dataclasses.asdict(value))
    tolist = getattr(value, "tolist", None)  # numpy arrays and scalars of other kinds
    if callable(tolist):
        return jsonable(tolist())
    return repr(value)


def canonical(values: Mapping[str, Any]) -> str:
    """The values as one canonical JSON text (sorted keys): equal values, equal text."""
    return json.dumps(jsonable(values), sort_keys=True, separators=(",", ":"))


# ----------------------------------------------------------------------------------------- names


def value_text(value: Any) -> str:
    """How one value reads in a folder name or a plot label (``1e-05``, ``true``, ``10+50``)."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list | tuple):
        return "+".join(value_text(v) for v in value) if value else "empty"
    if isinstance(value, Mapping):
        return json.dumps(jsonable(value), sort_keys=True, separators=(",", ":"))
    return str(jsonable(value))


def label(values: Mapping[str, Any], *, without: tuple[str, ...] = ()) -> str:
    """The readable ``key=value, key=value`` text of ``values`` minus the keys ``without``
    (``"default"`` when nothing is left)."""
    parts = [f"{k}={value_text(v)}" for k, v in values.items() if k not in without]
    return ", ".join(parts) or "default"


def _digest(values: Mapping[str, Any]) -> str:
    return hashlib.sha256(canonical(values).encode()).hexdigest()[:10]


def point_name(values: Mapping[str, Any]) -> str:
    """The folder name of a point with ``values`` (see the module doc); deterministic."""
    raw = ",".join(f"{k}={value_text(v)}" for k, v in values.items()) or "default"
    safe = _UNSAFE.sub("_", raw)
    if safe == raw and len(raw) <= MAX_NAME and not raw.startswith("."):
        return raw
    return f"{safe[: MAX_NAME - 11]}~{_digest(values)}"


def point_names(points: list[Mapping[str, Any]]) -> list[str]:
    """The folder names of distinct points, one each: :func:`point_name`, and where two distinct
    points would share one (e.g. the number 1 and the text "1"), each of them gets the digest of
    its values appended."""
    names = [point_name(p) for p in points]
    shared = {n for n in names if names.count(n) > 1}
    return [f"{n}~{_digest(p)}" if n in shared else n for n, p in zip(names, points, strict=True)]


@dataclasses.dataclass(frozen=True)
class PointResult:
    """One point's outcome as the driver knows it: ``status`` is "done" (``summary`` set) or
    "failed" (``error``: type, message, traceback); ``seconds`` is the wall time of its function
    (None if unknown); ``reused`` says it was read from a previous run's ``point.json`` instead
    of computed; ``folder`` is ``out/points/<name>``; ``provenance`` is what its record says
    produced it (None for a record without one); ``recomputed_because`` says why an earlier
    record of the point was not reused (e.g. ``config.eps: 99 != 0.25``), None when there was
    none or it was reused."""

    name: str
    values: dict
    status: str
    summary: dict | None
    error: dict | None
    seconds: float | None
    reused: bool
    folder: Path
    provenance: dict | None = None
    recomputed_because: str | None = None

    @classmethod
    def from_record(
        cls,
        record: dict,
        values: Mapping,
        folder: Path,
        reused: bool,
        recomputed_because: str | None = None,
    ):
        """From a ``point.json`` record (written by :func:`store_point`)."""
        provenance = record.get("provenance")
        return cls(
            name=record["name"], values=dict(values), status=record["status"],
            summary=record.get("summary"), error=record.get("error"),
            seconds=record.get("seconds"), reused=reused, folder=Path(folder),
            provenance=provenance if isinstance(provenance, dict) else None,
            recomputed_because=recomputed_because,
        )  # fmt: skip


# --------------------------------------------------------------------------- running one point


def execute_point(fn: Callable[[dict, Path], Mapping], values: Mapping[str, Any]) -> dict:
    """Run ``fn(values, folder)`` in a new temporary folder (removed afterwards) and return what
    the driver needs: ``status`` ("done" or "failed"), ``summary`` (JSON-safe) or ``error``
    (``type``, ``message``, ``traceback``: the full text of ``traceback.format_exc()``),
    ``seconds`` (wall time of ``fn``), ``files`` (path relative to the folder, in POSIX form ->
    bytes, every file ``fn`` wrote, also when it raised), ``temp_folders`` (the folder's paths,
    to be rewritten), ``host`` and ``provenance`` (of this process, taken before ``fn`` runs:
    :func:`drake_abs.parallel.provenance.provenance`). An exception from ``fn`` is caught here;
    only the death of the process itself escapes."""
    produced_by = _provenance()
    raw = tempfile.mkdtemp(prefix=f"{TEMP_PREFIX}{os.getpid()}-")
    folder = Path(raw).resolve()
    start = time.perf_counter()
    try:
        summary = fn(dict(values), folder)
        if not isinstance(summary, Mapping):
            raise TypeError(
                f"a sweep's fn must return a dict (the point's summary), got {type(summary)!r}"
            )
        result: dict[str, Any] = {"status": "done", "summary": jsonable(summary)}
    except Exception as err:
        result = {"status": "failed", "error": error_record(err, traceback.format_exc())}
    except BaseException:  # interrupted (Ctrl-C, a Ray cancel): the folder goes, then it stops
        shutil.rmtree(folder, ignore_errors=True)
        raise
    result["seconds"] = time.perf_counter() - start
    try:
        result["files"] = {
            p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*"))
            if p.is_file() and not p.is_symlink()
        }
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    result["temp_folders"] = sorted({raw, str(folder)}, key=len, reverse=True)
    result["host"] = socket.gethostname()
    result["provenance"] = produced_by
    return result


def _provenance() -> dict | None:
    """This process's provenance; None should reading it ever fail (it is not meant to)."""
    from drake_abs.parallel.provenance import provenance

    try:
        return provenance()
    except Exception:
        return None


def remove_stale_folders(root: str | Path | None = None) -> list[Path]:
    """Remove the temporary folders of points whose process is gone (a sweep killed while a
    point ran: ``kill -9``, a lost Ray worker) from ``root`` (default: the system's temporary
    folder) and return them. A point's folder is named ``drake-abs-point-<pid>-...`` by the
    process that runs it; folders of running processes (other sweeps) are left alone."""
    root = Path(tempfile.gettempdir() if root is None else root)
    removed = []
    for folder in root.glob(f"{TEMP_PREFIX}*"):
        pid = folder.name[len(TEMP_PREFIX) :].split("-", 1)[0]
        if not pid.isdigit() or not folder.is_dir() or _alive(int(pid)):
            continue
        shutil.rmtree(folder, ignore_errors=True)
        removed.append(folder)
    return removed


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` runs on this machine (one of another user counts as running)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def error_record(err: BaseException, trace: str) -> dict[str, str]:
    """What is recorded of an error: its type's name, its message and the traceback text."""
    return {"type": type(err).__name__, "message": str(err), "traceback": trace}


def lost_point(err: BaseException) -> dict:
    """The result of a point whose task never returned (its worker died more often than the
    retries allow, or its function could not be loaded there): failed, with the error."""
    trace = "".join(traceback.format_exception(err))
    return {"status": "failed", "error": error_record(err, trace), "seconds": math.nan,
            "files": {}, "temp_folders": [], "host": None, "provenance": None}  # fmt: skip


# --------------------------------------------------------------------------------- the records


def _relocate(value: Any, old: list[str], new: str) -> Any:
    """``value`` with every string that is, or starts with, one of the ``old`` folder paths
    rewritten to start with ``new``."""
    if isinstance(value, str):
        for prefix in old:
            if value == prefix or value.startswith((prefix + "/", prefix + os.sep)):
                return new + value[len(prefix) :]
        return value
    if isinstance(value, dict):
        return {k: _relocate(v, old, new) for k, v in value.items()}
    if isinstance(value, list):
        return [_relocate(v, old, new) for v in value]
    return value


def _relocate_bytes(data: bytes, old: list[str], new: str) -> bytes:
    for prefix in old:
        for a, b in ((prefix, new), (json.dumps(prefix)[1:-1], json.dumps(new)[1:-1])):
            data = data.replace(a.encode(), b.encode())
    return data


def write_atomically(path: Path, data: bytes | str) -> None:
    """Write ``path`` through a temporary file in the same folder and ``os.replace``: readers see
    the old file or the new one, never a part."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        # mkstemp makes the file 0600; give it the mode a plain write would (0644 under the
        # usual umask 022), as the point's other files have
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as f:
            f.write(data.encode() if isinstance(data, str) else data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _umask() -> int:
    """This process's umask (read from /proc where there is one, which leaves it unchanged;
    else set and restored)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def store_point(
    folder: Path,
    name: str,
    values: Mapping[str, Any],
    result: dict,
    description: Any,
    config: Any = None,
) -> dict:
    """Write one executed point into ``folder`` (``out/points/<name>``), replacing what was
    there: its files, then ``point.json``. ``result`` is :func:`execute_point`'s; ``config`` the
    point's whole resolved configuration (JSON-able; None when the function cannot tell it).
    Returns the record written to ``point.json`` (name, status, values, fn, config, provenance,
    summary or error, seconds, files, host)."""
    folder = Path(folder)
    (folder / POINT_FILE).unlink(missing_ok=True)  # no "done" record while the files change
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    old, new, root = list(result.get("temp_folders", [])), str(folder), folder.resolve()
    for rel, data in result.get("files", {}).items():
        target = folder / rel
        if rel == POINT_FILE or root not in target.resolve().parents:
            continue  # fn's own point.json, or a path leaving the folder: not written
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(_relocate_bytes(data, old, new) if rel.endswith(TEXT_SUFFIXES) else data)
    record: dict[str, Any] = {
        "name": name,
        "status": result["status"],
        "values": jsonable(values),
        "fn": description,
        "config": jsonable(config),
        "provenance": result.get("provenance"),
    }
    if result["status"] == "done":
        record["summary"] = _relocate(result["summary"], old, new)
    else:
        record["error"] = result["error"]
    seconds = result.get("seconds")
    record["seconds"] = None if seconds is None or math.isnan(seconds) else seconds
    record["files"] = sorted(result.get("files", {}))
    record["host"] = result.get("host")
    write_atomically(folder / POINT_FILE, json.dumps(record, indent=2))
    return record


def read_point(folder: Path) -> dict | None:
    """The record in ``folder/point.json``, or None if there is none or it cannot be read."""
    try:
        record = json.loads((Path(folder) / POINT_FILE).read_text())
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) else None


# ---------------------------------------------------------------------------------- differences

#: Longest text of one value in a reason; longer ones are cut with an ellipsis.
MAX_VALUE_TEXT = 60
_ABSENT = object()


def _shown(value: Any) -> str:
    if value is _ABSENT:
        return "not recorded"
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= MAX_VALUE_TEXT else text[: MAX_VALUE_TEXT - 3] + "..."


def differences(recorded: Any, current: Any, path: str) -> list[str]:
    """How a recorded JSON value differs from the current one, one reason per differing leaf,
    each reading ``PATH: RECORDED != CURRENT`` with dotted paths into dicts and the values as
    JSON (cut to :data:`MAX_VALUE_TEXT` characters): ``config.eps: 99 != 0.25``,
    ``config.solver.tol: not recorded != 1e-08``, ``config.old: 3 != not recorded``. Values
    are compared as canonical JSON text, so a NaN equals a NaN and a tuple its list. Empty when
    they are equal."""
    if isinstance(recorded, Mapping) and isinstance(current, Mapping):
        reasons = []
        for key in dict.fromkeys([*current, *recorded]):
            old, new = recorded.get(key, _ABSENT), current.get(key, _ABSENT)
            if old is _ABSENT or new is _ABSENT:
                reasons.append(f"{path}.{key}: {_shown(old)} != {_shown(new)}")
            else:
                reasons += differences(old, new, f"{path}.{key}")
        return reasons
    same = json.dumps(jsonable(recorded), sort_keys=True) == json.dumps(
        jsonable(current), sort_keys=True
    )
    return [] if same else [f"{path}: {_shown(recorded)} != {_shown(current)}"]
