"""Sweeps: one function run over a list of points (seeds x configurations), in this process or
as Ray tasks, gathered into the same files either way, resumable and fault-tolerant.

``run_sweep(fn, points, out)`` calls ``fn(values, folder) -> dict`` once per point (a dict of
values, e.g. ``{"seed": 0, "horizons": (10,)}``), each time in a fresh temporary folder on
whichever machine runs it. What a point returns (its summary) and every file it wrote travel back
to this process, which writes them into ``out/points/<name>/`` with a ``point.json`` record; so a
cluster whose nodes share no file system still gathers every file. Then ``out/sweep.json``,
``out/sweep.csv`` and ``out/sweep.png`` are written from the records
(:mod:`drake_abs.parallel.sweep_gather`), by the same code for both backends.

- Provenance: every ``point.json`` records what produced the point: the function's
  description, the point's whole resolved configuration (when ``fn`` has a
  ``resolved_config(values)`` method, as :class:`drake_abs.experiments.sweep.ExperimentPoint`
  has: the experiment's Config with the point's values applied) and the provenance of the
  process that ran it (:func:`drake_abs.parallel.provenance.provenance`: the drake-abs version,
  the git commit and a dirty flag when run from a checkout, the versions of the libraries that
  compute the numbers). ``sweep.json`` records the provenance of the process that gathered it.
- Resume: a point whose ``point.json`` says "done" is reused only when all of it matches what
  this run would record: its values, the function's description, the resolved configuration,
  the drake-abs version and every dependency version. The commit is recorded and shown but
  not compared: the package version is the release key (reuse a point only when its whole
  Config and package version match), so edits on a checkout between releases do not recompute
  finished points; ``resume=False`` (``drake-abs sweep --fresh``) recomputes after such edits.
  A point whose record differs is recomputed, and says why (its
  :class:`~drake_abs.parallel.sweep_points.PointResult`'s ``recomputed_because``, also in
  ``sweep.json``: ``config.eps: 99 != 0.25``, ``numpy: 2.1.0 != 2.2.1``); failed and missing
  points are recomputed.
  :func:`check_sweep` tells, without running anything, what a run would do with every point
  (:class:`PointState`: fresh, stale, missing or unfinished).
- Faults: an exception in ``fn`` is caught where it runs; the point is recorded as failed with
  the full traceback and the rest of the sweep completes (:attr:`SweepResult.failures`). On Ray,
  a point whose worker process dies is retried up to ``max_retries`` times, then recorded as
  failed with Ray's error.
- Ray: one task per point (1 CPU each), results taken as they finish (``ray.wait``), each
  point's record written as it arrives, so an interrupted sweep keeps its finished points.

``fn`` must be picklable for Ray: a module-level function, or an instance of a module-level class
(e.g. :class:`drake_abs.experiments.sweep.ExperimentPoint`), importable on the workers. It may
have a ``describe()`` method returning a JSON-able description (recorded; a changed description
means no reuse); otherwise its qualified name (or ``repr``) describes it. It may have a
``resolved_config(values)`` method returning the point's whole configuration (JSON-able;
recorded and compared the same way).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drake_abs.parallel import provenance as _provenance
from drake_abs.parallel.sweep_gather import gather
from drake_abs.parallel.sweep_points import (
    PointResult,
    canonical,
    differences,
    execute_point,
    jsonable,
    lost_point,
    point_names,
    read_point,
    remove_stale_folders,
    store_point,
)

BACKENDS = ("local", "ray")
_VALUE_TYPES = (bool, int, float, str, type(None), list, tuple, dict)


@dataclass(frozen=True)
class SweepResult:
    """A finished sweep: its folder, every point in the grid's order (see
    :class:`~drake_abs.parallel.sweep_points.PointResult`), the gathered files (name -> path:
    ``json``, ``csv`` and, if there was a numeric metric, ``png``), the metric plotted, and why a
    requested metric could not be plotted (``metric_error``, else None), and the provenance of
    the process that ran the sweep (:func:`drake_abs.parallel.provenance.provenance`)."""

    out: Path
    description: Any
    backend: str
    points: list[PointResult]
    files: dict[str, Path]
    metric: str | None
    metric_error: str | None = None
    seed_key: str = "seed"
    provenance: dict | None = None

    @property
    def failures(self) -> list[PointResult]:
        """The points that failed (their ``error`` holds the traceback)."""
        return [p for p in self.points if p.status != "done"]

    @property
    def computed(self) -> list[PointResult]:
        """The points computed by this run (not reused from an earlier one)."""
        return [p for p in self.points if not p.reused]

    @property
    def reused(self) -> list[PointResult]:
        """The points whose earlier "done" record was used."""
        return [p for p in self.points if p.reused]

    @property
    def recomputed(self) -> list[PointResult]:
        """The points computed although they had an earlier record (stale, or failed), each
        with its ``recomputed_because``."""
        return [p for p in self.points if p.recomputed_because]


#: What a run would do with a point (``PointState.state``), in this order: reuse it; recompute
#: it because its record differs; compute it (no folder); compute it again (it failed, or its
#: record is missing or unreadable, e.g. interrupted while it was stored).
FRESH, STALE, MISSING, UNFINISHED = "fresh", "stale", "missing", "unfinished"


@dataclass(frozen=True)
class PointState:
    """A point of a sweep as a run would find it (:func:`check_sweep`): ``state`` is one of
    ``"fresh"`` (its record matches: reused), ``"stale"`` (done, but its record differs:
    ``reasons``, each ``FIELD: RECORDED != CURRENT``), ``"missing"`` (no folder) or
    ``"unfinished"`` (failed, or no readable ``point.json``: ``reasons`` says which); ``record``
    is its ``point.json`` (None if there is none)."""

    name: str
    values: dict
    folder: Path
    state: str
    reasons: tuple[str, ...] = ()
    record: dict | None = None

    @property
    def reason(self) -> str:
        """The reasons as one text (``"config.eps: 99 != 0.25; numpy: 2.1.0 != 2.2.1"``)."""
        return "; ".join(self.reasons)


def resolved_config(fn: Callable, values: Mapping[str, Any]) -> tuple[Any, str | None]:
    """The point's whole configuration as ``fn.resolved_config(values)`` gives it (JSON-able;
    None when ``fn`` has no such method), and why it could not be built (None when it could)."""
    method = getattr(fn, "resolved_config", None)
    if not callable(method) or isinstance(fn, type):
        return None, None
    try:
        return jsonable(method(dict(values))), None
    except Exception as err:
        return None, f"its configuration cannot be built: {type(err).__name__}: {err}"


def point_state(
    folder: Path,
    name: str,
    values: Mapping[str, Any],
    *,
    description: Any,
    config: Any,
    current: Mapping[str, Any],
    config_error: str | None = None,
) -> PointState:
    """What a run would do with the point ``name`` in ``folder`` (see :class:`PointState`):
    its ``point.json`` is compared with what this run would record: the values, the function's
    ``description``, the resolved ``config`` (None: not known, e.g. ``fn`` has no
    ``resolved_config``; ``config_error``: it could not be built, so the point is never fresh)
    and the ``current`` provenance (:func:`drake_abs.parallel.provenance.differences`: the
    drake-abs version and the dependencies count, the commit does not)."""
    folder = Path(folder)
    record = read_point(folder)

    def state(kind: str, *reasons: str) -> PointState:
        return PointState(name, dict(values), folder, kind, tuple(reasons), record)

    if record is None:
        if not folder.exists():
            return state(MISSING)
        return state(UNFINISHED, "no readable point.json (interrupted while it was stored?)")
    if record.get("status") != "done":
        error = record.get("error") if isinstance(record.get("error"), dict) else {}
        message = (str(error.get("message") or "")).strip().splitlines()
        return state(UNFINISHED, f"{record.get('status')}: {error.get('type')}: "
                                 f"{message[0] if message else ''}".rstrip(": "))  # fmt: skip
    reasons = []
    if record.get("name") != name:
        reasons.append(f"name: {record.get('name')!r} != {name!r}")
    reasons += differences(record.get("values"), jsonable(values), "values")
    reasons += differences(record.get("fn"), description, "fn")
    if config_error is not None:
        reasons.append(config_error)
    elif "config" not in record:
        if config is not None:
            reasons.append("config: not recorded")
    else:
        reasons += differences(record["config"], config, "config")
    reasons += _provenance.differences(record.get("provenance"), current)
    return state(STALE if reasons else FRESH, *reasons)


def check_sweep(
    fn: Callable[[dict, Path], Mapping],
    points: Sequence[Mapping[str, Any]],
    out: str | Path,
) -> list[PointState]:
    """What :func:`run_sweep` with these arguments (and ``resume=True``) would do with every
    point, in the grid's order, without running or writing anything (see :class:`PointState`).
    ``fn``, ``points`` and ``out`` are checked as :func:`run_sweep` checks them."""
    out = _validate(fn, "local", None, None, 0, out)
    points = validate_points(points)
    description, current = describe(fn), _provenance.provenance()
    states = []
    for name, values in zip(point_names(points), points, strict=True):
        config, error = resolved_config(fn, values)
        states.append(point_state(out / "points" / name, name, values, description=description,
                                  config=config, current=current, config_error=error))  # fmt: skip
    return states


def describe(fn: Callable) -> Any:
    """A JSON-able description of ``fn``: ``fn.describe()`` if it has one, else its module and
    qualified name (functions, classes), else its ``repr``."""
    method = getattr(fn, "describe", None)
    if callable(method) and not isinstance(fn, type):
        return jsonable(method())
    qualname = getattr(fn, "__qualname__", None)
    if qualname is not None and hasattr(fn, "__module__"):
        return f"{fn.__module__}.{qualname}"
    return repr(fn)


def _check_values(values: Any, where: str) -> None:
    if isinstance(values, Mapping):
        for k, v in values.items():
            _check_values(v, f"{where}[{k!r}]")
    elif isinstance(values, list | tuple):
        for i, v in enumerate(values):
            _check_values(v, f"{where}[{i}]")
    elif not isinstance(values, _VALUE_TYPES) and not hasattr(values, "tolist"):
        raise ValueError(
            f"points: {where} must be a number, bool, str, None, or a list, tuple or dict of "
            f"those; got {type(values).__name__} {values!r}"
        )


def validate_points(points: Any) -> list[dict]:
    """``points`` as a list of dicts, or a ValueError naming what is wrong: not a non-empty list,
    an entry not a dict, a key not a non-empty str, a value not JSON-like, or a duplicate."""
    if isinstance(points, str | bytes | Mapping) or not isinstance(points, Sequence):
        raise ValueError(
            "points must be a list of dicts of values, e.g. [{'seed': 0}, {'seed': 1}]; "
            f"got {type(points).__name__}"
        )
    if not points:
        raise ValueError("points must hold at least one dict of values; got an empty list")
    seen: dict[str, int] = {}
    out = []
    for i, point in enumerate(points):
        if not isinstance(point, Mapping):
            raise ValueError(
                f"points[{i}] must be a dict of values such as {{'seed': 0}}; "
                f"got {type(point).__name__} {point!r}"
            )
        for key in point:
            if not isinstance(key, str) or not key:
                raise ValueError(f"points[{i}]: keys must be non-empty strings; got {key!r}")
        _check_values(dict(point), f"points[{i}]")
        text = canonical(point)
        if text in seen:
            raise ValueError(f"points[{i}] duplicates points[{seen[text]}]: {dict(point)!r}")
        seen[text] = i
        out.append(dict(point))
    return out


def _validate(fn, backend, address, num_cpus, max_retries, out) -> Path:
    if not callable(fn):
        raise TypeError(
            f"fn must be callable as fn(values: dict, folder: Path) -> dict; got {fn!r}"
        )
    if backend not in BACKENDS:
        raise ValueError(
            f"backend must be one of {', '.join(map(repr, BACKENDS))}; got {backend!r}"
        )
    if backend == "local" and (address is not None or num_cpus is not None):
        raise ValueError("address and num_cpus are for backend='ray'; the local backend has none")
    if address is not None and num_cpus is not None:
        raise ValueError("num_cpus is for a local Ray cluster; a cluster joined at address "
                         "declares its own CPUs")  # fmt: skip
    if isinstance(max_retries, bool) or not isinstance(max_retries, int) or max_retries < 0:
        raise ValueError(f"max_retries must be a whole number >= 0; got {max_retries!r}")
    folder = Path(out).expanduser().resolve()
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"out must be a folder; {str(folder)!r} is a file")
    return folder


def run_sweep(
    fn: Callable[[dict, Path], Mapping],
    points: Sequence[Mapping[str, Any]],
    out: str | Path,
    *,
    backend: str = "local",
    address: str | None = None,
    num_cpus: int | None = None,
    resume: bool = True,
    progress: bool = True,
    max_retries: int = 2,
    metric: str | None = None,
    seed_key: str = "seed",
) -> SweepResult:
    """Run ``fn`` over ``points`` and gather the results into ``out`` (see the module doc).

    Args:
        fn: ``fn(values, folder) -> dict``, picklable; ``values`` is the point's dict (a copy),
            ``folder`` an empty temporary folder for its files; returns the point's summary.
        points: the points, a non-empty list of distinct dicts of values.
        out: the sweep's folder (created): ``points/<name>/``, ``sweep.json``, ``sweep.csv``,
            ``sweep.png``.
        backend: ``"local"`` (one point after another in this process) or ``"ray"``.
        address: Ray only: a cluster to join (None: start a local one on 127.0.0.1, or use the
            Ray this process already initialised); see :func:`drake_abs.parallel.cluster.connect`.
        num_cpus: Ray only: the CPUs of a local cluster started here (default: all).
        resume: reuse the records of points already done in ``out`` whose record matches (see
            the module doc); False recomputes all.
        progress: a progress bar over the points (tqdm, stderr).
        max_retries: Ray only: how often a point whose worker process died is run again.
        metric: the numeric column of sweep.csv to plot (default: the first numeric summary
            column that varies, see :func:`drake_abs.parallel.sweep_gather.choose_metric`).
        seed_key: the value that is a seed: plots average over it.

    Returns:
        The :class:`SweepResult`; failed points are in ``result.failures``, not raised.
    """
    out = _validate(fn, backend, address, num_cpus, max_retries, out)
    for arg, value in (("metric", metric), ("seed_key", seed_key)):
        if value is not None and (not isinstance(value, str) or not value):
            raise ValueError(f"{arg} must be a column name (a non-empty str); got {value!r}")
    points = validate_points(points)
    remove_stale_folders()  # temporary folders of points whose sweep was killed
    names = point_names(points)
    description, current = describe(fn), _provenance.provenance()
    configs = [resolved_config(fn, values) for values in points]
    (out / "points").mkdir(parents=True, exist_ok=True)
    results: list[PointResult | None] = [None] * len(points)
    because: list[str | None] = [None] * len(points)
    todo = []
    for i, (name, values) in enumerate(zip(names, points, strict=True)):
        folder = out / "points" / name
        if not resume:
            todo.append(i)
            continue
        found = point_state(folder, name, values, description=description,
                            config=configs[i][0], current=current,
                            config_error=configs[i][1])  # fmt: skip
        if found.state == FRESH:
            results[i] = PointResult.from_record(found.record, values, folder, reused=True)
        else:
            todo.append(i)
            because[i] = f"{found.state}: {found.reason}" if found.reasons else None

    def finished(i: int, result: dict) -> None:
        folder = out / "points" / names[i]
        record = store_point(folder, names[i], points[i], result, description,
                             config=configs[i][0])  # fmt: skip
        results[i] = PointResult.from_record(record, points[i], folder, reused=False,
                                             recomputed_because=because[i])  # fmt: skip

    bar = _bar(len(points), len(points) - len(todo), progress, description)
    try:
        if todo and backend == "local":
            for i in todo:
                finished(i, execute_point(fn, points[i]))
                bar.update()
        elif todo:
            _run_on_ray(fn, [(i, points[i]) for i in todo], finished, bar, address, num_cpus,
                        max_retries)  # fmt: skip
    finally:
        bar.close()
    recorded = [r for r in results if r is not None]
    gathered = gather(out, recorded, description=description, backend=backend, seed_key=seed_key,
                      metric=metric, provenance=current)  # fmt: skip
    return SweepResult(
        out=out, description=description, backend=backend, points=recorded,
        files=gathered["files"], metric=gathered["metric"],
        metric_error=gathered["metric_error"], seed_key=seed_key, provenance=current,
    )  # fmt: skip


def _bar(total: int, initial: int, enabled: bool, description: Any):
    from tqdm.std import tqdm

    text = description.get("experiment", "sweep") if isinstance(description, dict) else "sweep"
    return tqdm(total=total, initial=initial, desc=f"{text}: points", file=sys.stderr,
                disable=not enabled, dynamic_ncols=True, leave=False)  # fmt: skip


def _run_on_ray(fn, todo, finished, bar, address, num_cpus, max_retries) -> None:
    """Run the points ``todo`` ((index, values) pairs) as Ray tasks; ``finished(i, result)`` is
    called for each as it completes. A Ray cluster started here is stopped afterwards."""
    from drake_abs.parallel.cluster import connect, require_ray, shutdown

    ray = require_ray()
    started = not ray.is_initialized()
    connect(address, num_cpus=num_cpus)
    pending: dict = {}
    try:
        task = ray.remote(num_cpus=1, max_retries=max_retries, retry_exceptions=False)(
            execute_point
        )
        fn_ref = ray.put(fn)
        pending = {task.remote(fn_ref, values): i for i, values in todo}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                i = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except Exception as err:  # the worker died too often, or fn could not load
                    result = lost_point(err)
                finished(i, result)
                bar.update()
    finally:
        for ref in pending:  # interrupted: what is still queued or running is cancelled
            ray.cancel(ref, force=True)
        if started:
            shutdown()
