"""Saving a learned policy and loading it back: ``STEM.npz`` (the parameters theta and any array
fields of the policy) beside ``STEM.json`` (what the policy is, the task it acts in, the config
that made it, the library version).

``STEM.json`` holds::

    {"format": "drake-abs policy", "format_version": 1,
     "kind": "LinearPolicy",                  # a known policy class (POLICY_KINDS)
     "fields": {"nx": 11, "nu": 3, ...},      # its constructor fields (dataclass fields)
     "array_fields": [],                      # fields stored in the npz as "field:NAME"
     "n_params": 36,
     "task": "hopper" | null,                 # the task the policy acts in, by name
     "acts_on": "observation" | "state",      # the task's observation (an ObservationPolicy of
                                              # the saved kind) or the full state x
     "arrays": "STEM.npz",                    # beside the JSON
     "config": {...} | null,
     "library": {"drake-abs": "0.1.0", "numpy": "2.5.5"}}

Only known classes are rebuilt (:data:`POLICY_KINDS`:
:class:`~drake_abs.policy.policies.LinearPolicy`, :class:`~drake_abs.policy.policies.MLPPolicy`,
:class:`~drake_abs.policy.ars_v2.NormalizedLinearPolicy`, and any registered with
:func:`register_policy_kind`); nothing is imported by a name read from a file, and a file naming
another kind is refused (``ValueError`` naming the kind).

This module is generic (the policy layer imports no task). A policy of a task's observation
(:class:`drake_abs.tasks.adapters.ObservationPolicy`) is saved as its inner policy plus the
task's name; :func:`load_policy` rebuilds the full-state policy through ``wrap(task_name,
inner)``. :func:`drake_abs.tasks.saved_policies.load_policy` is that loader for the locomotion
tasks (it builds the task).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.engine.protocols import Policy
from drake_abs.policy.ars_v2 import NormalizedLinearPolicy
from drake_abs.policy.policies import LinearPolicy, MLPPolicy
from drake_abs.policy.policy_files import read_npz_arrays

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "POLICY_KINDS",
    "SavedPolicy",
    "json_ready",
    "load_policy",
    "policy_paths",
    "register_policy_kind",
    "save_policy",
    "saved_policy_files",
]

#: The ``format`` entry of every saved policy's JSON.
FORMAT = "drake-abs policy"
#: The version of that format this module writes (and the newest it reads).
FORMAT_VERSION = 1

#: The policy classes that are saved and rebuilt, by kind (the class name).
POLICY_KINDS: dict[str, type] = {
    "LinearPolicy": LinearPolicy,
    "MLPPolicy": MLPPolicy,
    "NormalizedLinearPolicy": NormalizedLinearPolicy,  # ARS's; its mean and std go to the npz
}

_ARRAY_PREFIX = "field:"


def register_policy_kind(cls: type) -> type:
    """Let :func:`save_policy` and :func:`load_policy` handle the policy class ``cls`` (a frozen
    dataclass whose constructor fields are numbers, strings, None, tuples of them or numpy
    arrays). Returns ``cls``, so it can decorate the class."""
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise ValueError(f"cls must be a dataclass policy class; got {cls!r}")
    for attribute in ("act", "jacobians", "vjp"):
        if not callable(getattr(cls, attribute, None)):
            raise ValueError(
                f"cls must be a Policy class (with {attribute}); {cls.__name__} is not"
            )
    known = POLICY_KINDS.get(cls.__name__)
    if known is not None and known is not cls:
        raise ValueError(f"a different class of kind {cls.__name__!r} is registered already")
    POLICY_KINDS[cls.__name__] = cls
    return cls


@dataclasses.dataclass(frozen=True)
class SavedPolicy:
    """A loaded policy.

    Attributes:
        policy: the policy of the state the task's stepper steps (for a task-observation policy
            the rebuilt ``ObservationPolicy``; otherwise the saved policy itself):
            ``policy.act(theta, x (M, nx)) -> u (M, nu)``.
        theta: (P,) its parameters.
        task_name: the task it acts in (``"hopper"``, ...) or None.
        config: the config saved with it (a dict) or None.
        inner: the saved policy class's instance (for a task-observation policy, the policy of
            the observation, ``inner.act(theta, o (M, n_obs))``; else ``policy``).
        kind: its kind (class name).
        acts_on: ``"observation"`` (inner takes the task's observation) or ``"state"``.
        path: the JSON file it was read from.
        metadata: the whole JSON record.
        task: the task object, when the loader built one (:mod:`drake_abs.tasks.saved_policies`).
    """

    policy: Policy
    theta: np.ndarray
    task_name: str | None
    config: dict | None
    inner: Policy
    kind: str
    acts_on: Literal["observation", "state"]
    path: Path
    metadata: dict
    task: Any = None


def policy_paths(path_stem: str | Path) -> tuple[Path, Path]:
    """(``STEM.json``, ``STEM.npz``) of ``path_stem``: a stem, or either file's path (a trailing
    ``.json`` or ``.npz`` is taken off; any other dot stays part of the stem)."""
    if not isinstance(path_stem, str | Path) or not str(path_stem):
        raise ValueError(f"path_stem must be a file path (str or Path); got {path_stem!r}")
    text = str(Path(path_stem).expanduser())
    for suffix in (".json", ".npz"):
        if text.endswith(suffix):
            text = text[: -len(suffix)]
    return Path(text + ".json"), Path(text + ".npz")


def json_ready(value, name: str = "config"):
    """``value`` as plain JSON data: dataclasses as dicts, tuples as lists, numpy scalars and
    arrays as numbers and lists, paths as strings (``ValueError`` naming ``name`` for anything
    else)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise ValueError(f"{name} must have string keys; got the key {key!r}")
            out[key] = json_ready(item, f"{name}[{key!r}]")
        return out
    if isinstance(value, list | tuple):
        return [json_ready(item, f"{name}[{i}]") for i, item in enumerate(value)]
    raise ValueError(
        f"{name} must be JSON data (numbers, strings, lists, dicts, dataclasses, numpy values); "
        f"got {type(value).__name__}"
    )


def _library() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    try:
        ours = version("drake-abs")
    except PackageNotFoundError:  # a checkout that is not installed
        ours = "unknown"
    return {"drake-abs": ours, "numpy": np.__version__}


def _known_kind(policy) -> str | None:
    kind = type(policy).__name__
    return kind if POLICY_KINDS.get(kind) is type(policy) else None


def _task_name(task) -> str | None:
    if task is None:
        return None
    name = task if isinstance(task, str) else getattr(task, "name", None)
    if not isinstance(name, str) or not name:
        raise ValueError(
            f"task must be a task's name (e.g. 'hopper') or a task with a name; got {task!r}"
        )
    return name


def save_policy(
    path_stem: str | Path,
    policy: Policy,
    theta,
    *,
    task=None,
    config=None,
) -> dict[str, Path]:
    """Write ``STEM.npz`` (theta and the policy's array fields) and ``STEM.json`` (its kind and
    constructor fields, the task, the config, the library version); the folder is created.

    Args:
        path_stem: the files' path without suffix (a ``.json`` or ``.npz`` suffix is taken off).
        policy: a policy of a known kind (:data:`POLICY_KINDS`), or an observation policy of
            one (an object with ``inner`` and ``observation``, e.g. ``task.policy(inner)``;
            its inner policy is saved, and ``task`` is then required).
        theta: (P,) the parameters, P = ``policy.n_params``; finite.
        task: the task the policy acts in: its name (``"hopper"``) or the task (anything with a
            ``name``; a task with an ``observation`` must have the policy's). None: no task.
        config: JSON data stored with it (a dict or a dataclass, e.g. the experiment's Config).

    Returns:
        ``{"json": Path, "npz": Path}``, the files written.
    """
    json_path, npz_path = policy_paths(path_stem)
    task_name = _task_name(task)
    kind = _known_kind(policy)
    if kind is not None:
        inner, acts_on = policy, "state"
    elif hasattr(policy, "inner") and hasattr(policy, "observation"):
        inner, acts_on = policy.inner, "observation"
        kind = _known_kind(inner)
        if kind is None:
            raise ValueError(
                f"policy.inner must be one of the known kinds {sorted(POLICY_KINDS)}; got "
                f"{type(inner).__name__}"
            )
        if task_name is None:
            raise ValueError(
                "task is required for a policy of an observation (an ObservationPolicy): give the "
                "task or its name (e.g. 'hopper'), so that loading can rebuild its observation"
            )
        observation = getattr(task, "observation", None)
        if observation is not None and observation != policy.observation:
            raise ValueError(
                f"policy observes {policy.observation!r}, not the task's observation "
                f"{observation!r}: task must be the task the policy acts in"
            )
    else:
        raise ValueError(
            f"policy must be one of the known kinds {sorted(POLICY_KINDS)}, or an "
            f"ObservationPolicy of one; got {type(policy).__name__}"
        )
    theta = as_finite_array(theta, "theta", ndim=(1,))
    if theta.shape != (inner.n_params,):
        raise ValueError(f"theta must have shape (P,) = ({inner.n_params},); got {theta.shape}")
    fields, arrays = {}, {}
    for field in dataclasses.fields(inner):
        if not field.init:
            continue
        value = getattr(inner, field.name)
        if isinstance(value, np.ndarray):
            arrays[_ARRAY_PREFIX + field.name] = value
        else:
            fields[field.name] = json_ready(value, f"policy field {field.name}")
    record = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "kind": kind,
        "fields": fields,
        "array_fields": sorted(key[len(_ARRAY_PREFIX) :] for key in arrays),
        "n_params": int(inner.n_params),
        "task": task_name,
        "acts_on": acts_on,
        "arrays": npz_path.name,
        "config": json_ready(config, "config"),
        "library": _library(),
    }
    text = json.dumps(record, indent=1)
    json_path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(npz_path, theta=theta, **arrays)
    json_path.write_text(text + "\n")
    return {"json": json_path, "npz": npz_path}


def _as_tuples(value):
    """JSON lists back to tuples (the policies' sequence fields are tuples)."""
    if isinstance(value, list):
        return tuple(_as_tuples(item) for item in value)
    return value


def _read_record(json_path: Path) -> dict:
    if not json_path.is_file():
        raise FileNotFoundError(f"no saved policy {str(json_path)!r} (STEM.json)")
    try:
        record = json.loads(json_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"path: {str(json_path)!r} is not a JSON file ({err})") from None
    if not isinstance(record, dict) or record.get("format") != FORMAT:
        raise ValueError(
            f"path: {str(json_path)!r} is not a saved policy (its 'format' is not {FORMAT!r})"
        )
    version = record.get("format_version")
    if not isinstance(version, int) or not 1 <= version <= FORMAT_VERSION:
        raise ValueError(
            f"path: {str(json_path)!r} has format_version {version!r}; this version of drake-abs "
            f"reads 1 to {FORMAT_VERSION}"
        )
    return record


def _arrays_name(record: dict, json_path: Path) -> str:
    """The record's ``arrays`` entry: the bare name of an ``.npz`` file beside the JSON (a path,
    or a name that leaves the folder, is refused: a saved policy reads no other file)."""
    name = record.get("arrays")
    if (
        not isinstance(name, str)
        or not name.endswith(".npz")
        or name in (".npz", "..npz")
        or Path(name).name != name
        or "\\" in name
    ):
        raise ValueError(
            f"{str(json_path)!r}: 'arrays' must be the name of the .npz file beside it, such as "
            f"{json_path.stem + '.npz'!r} (no folder); got {name!r}"
        )
    return name


def _rebuild(record: dict, arrays, json_path: Path) -> Policy:
    kind = record.get("kind")
    cls = POLICY_KINDS.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise ValueError(
            f"unknown policy kind {kind!r} in {str(json_path)!r}: only the known kinds "
            f"{sorted(POLICY_KINDS)} are rebuilt (register_policy_kind adds one)"
        )
    fields = record.get("fields")
    if not isinstance(fields, dict):
        raise ValueError(f"{str(json_path)!r}: 'fields' must be a dict of {kind}'s fields")
    allowed = {f.name for f in dataclasses.fields(cls) if f.init}
    kwargs = {name: _as_tuples(value) for name, value in fields.items()}
    for name in record.get("array_fields", []):
        key = _ARRAY_PREFIX + name
        if key not in arrays:
            raise ValueError(f"{str(json_path)!r}: the array field {name!r} is not in its npz")
        kwargs[name] = np.array(arrays[key])
    unknown = sorted(set(kwargs) - allowed)
    if unknown:
        raise ValueError(f"{str(json_path)!r}: {kind} has no field(s) {unknown}")
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as err:
        raise ValueError(
            f"{str(json_path)!r}: cannot rebuild {kind} from its fields: {err}"
        ) from err


def load_policy(
    path: str | Path,
    *,
    wrap: Callable[[str, Policy], Policy] | None = None,
) -> SavedPolicy:
    """Load a policy written by :func:`save_policy`.

    Args:
        path: ``STEM.json``, ``STEM.npz`` or ``STEM``.
        wrap: ``wrap(task_name, inner) -> policy``, the full-state policy of a policy saved for a
            task's observation (``acts_on == "observation"``); needed only for those (for the
            locomotion tasks use :func:`drake_abs.tasks.saved_policies.load_policy`, which
            passes ``lambda name, inner: locomotion_task(name).policy(inner)``).

    Raises:
        FileNotFoundError: no such file.
        ValueError: not a saved policy, an unknown kind (named), an arrays file that is damaged
            or not beside the JSON, an ``n_params`` that is not the policy's, a theta of the
            wrong size, or a task-observation policy without ``wrap``.
    """
    json_path, _ = policy_paths(path)
    record = _read_record(json_path)
    npz_path = json_path.parent / _arrays_name(record, json_path)
    if not npz_path.is_file():
        raise FileNotFoundError(
            f"{str(json_path)!r} names its arrays file {str(npz_path)!r}, which does not exist"
        )
    arrays = read_npz_arrays(npz_path, "saved policy's arrays file")
    if "theta" not in arrays:
        raise ValueError(f"{str(npz_path)!r} has no 'theta'")
    raw = arrays["theta"]
    if raw.dtype.kind not in "iuf":
        raise ValueError(
            f"{str(npz_path)!r}: theta must be an array of real numbers; got dtype {raw.dtype}"
        )
    theta = raw.astype(float)
    inner = _rebuild(record, arrays, json_path)
    if theta.shape != (inner.n_params,) or not np.all(np.isfinite(theta)):
        raise ValueError(
            f"{str(npz_path)!r}: theta must be finite with shape ({inner.n_params},), the "
            f"{record['kind']}'s n_params; got {theta.shape}"
        )
    n_params = record.get("n_params")
    if isinstance(n_params, bool) or not isinstance(n_params, int) or n_params != inner.n_params:
        raise ValueError(
            f"{str(json_path)!r}: n_params must be the {record['kind']}'s number of parameters, "
            f"{inner.n_params}; the file says {n_params!r}"
        )
    task_name = record.get("task")
    acts_on = record.get("acts_on", "state")
    if acts_on not in ("observation", "state"):
        raise ValueError(f"{str(json_path)!r}: acts_on must be 'observation' or 'state'")
    policy = inner
    if acts_on == "observation":
        if wrap is None:
            raise ValueError(
                f"{str(json_path)!r} holds a policy of task {task_name!r}'s observation: give "
                "wrap (task name, inner policy) -> policy, or load it with "
                "drake_abs.tasks.saved_policies.load_policy, which builds the task"
            )
        policy = wrap(task_name, inner)
    return SavedPolicy(
        policy=policy, theta=theta, task_name=task_name, config=record.get("config"),
        inner=inner, kind=record["kind"], acts_on=acts_on, path=json_path.resolve(),
        metadata=record,
    )  # fmt: skip


def saved_policy_files(folder: str | Path, pattern: str = "*.json") -> list[Path]:
    """The saved policies' JSON files in ``folder`` (not its subfolders) matching ``pattern``,
    sorted by name; other JSON files (logs, summaries) are left out."""
    folder = Path(folder).expanduser()
    if not folder.is_dir():
        raise ValueError(f"folder must be an existing folder; got {str(folder)!r}")
    out = []
    for path in sorted(folder.glob(pattern)):
        if path.suffix != ".json" or not path.is_file():
            continue
        try:
            record = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            continue
        if isinstance(record, dict) and record.get("format") == FORMAT:
            out.append(path)
    return out
