"""Gathering a sweep's points into ``sweep.json``, ``sweep.csv`` and ``sweep.png``.

The same function gathers every sweep, whichever backend computed its points, from the points'
records alone (:class:`~drake_abs.parallel.sweep_points.PointResult`), so a sweep computed on Ray
gathers into the same files as one computed in this process.

- ``sweep.json``: the function's description, the provenance of the process that gathered it
  (:mod:`drake_abs.parallel.provenance`), the grid (keys, seeds, configurations), and every
  point: name, folder, values, status, summary or error (with its traceback), seconds, whether
  it was reused, why an earlier record of it was not (``recomputed_because``), and the
  provenance its ``point.json`` records.
- ``sweep.csv``: one row per point, in the grid's order: ``point`` (its folder name), the values'
  columns, ``status``, ``error`` (type and message of a failed point), then the summaries'
  scalar leaves (int, float, bool, str) with dotted keys (``curves.exact.variance.0``): nested
  dicts are followed, lists of up to :data:`MAX_LIST_ITEMS` scalars get one column per item,
  longer lists and lists of records stay in ``sweep.json`` only. Columns are in order of first
  appearance over the points; a summary key that clashes with a fixed column is prefixed
  ``summary.``.
- ``sweep.png``: one numeric column (the metric) against the configurations (the values without
  the seed): the mean over seeds with min-max bars and every point as a dot.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from drake_abs.parallel.sweep_points import PointResult, jsonable, label, write_atomically

#: Lists of scalars up to this length are spread over columns of sweep.csv.
MAX_LIST_ITEMS = 10
_SCALAR = bool | int | float | str


def flatten(summary: Mapping[str, Any]) -> dict[str, Any]:
    """The scalar leaves of a summary with dotted keys (see the module doc for lists)."""
    out: dict[str, Any] = {}

    def walk(value: Any, key: str) -> None:
        if isinstance(value, _SCALAR):
            out[key] = value
        elif isinstance(value, Mapping):
            for k, v in value.items():
                walk(v, f"{key}.{k}" if key else str(k))
        elif (
            isinstance(value, list)
            and len(value) <= MAX_LIST_ITEMS
            and all(v is None or isinstance(v, _SCALAR) for v in value)
        ):
            for i, v in enumerate(value):
                if v is not None:
                    out[f"{key}.{i}"] = v

    walk(summary, "")
    return out


def _cell(value: Any) -> Any:
    return value if value is None or isinstance(value, _SCALAR) else json.dumps(value)


def table(points: Sequence[PointResult]) -> tuple[list[str], list[dict[str, Any]]]:
    """The columns and rows of sweep.csv (one row per point; a missing cell is absent)."""
    value_keys = list(dict.fromkeys(k for p in points for k in p.values))
    fixed = ["point", *value_keys, "status", "error"]
    leaves = [flatten(p.summary) if p.summary else {} for p in points]
    rename = {k: f"summary.{k}" if k in fixed else k for f in leaves for k in f}
    columns = fixed + list(dict.fromkeys(rename[k] for f in leaves for k in f))
    rows = []
    for p, f in zip(points, leaves, strict=True):
        row = {"point": p.name, "status": p.status}
        row.update({k: _cell(v) for k, v in p.values.items()})
        if p.error:
            first = (p.error.get("message") or "").splitlines()
            row["error"] = f"{p.error.get('type')}: {first[0] if first else ''}".rstrip(": ")
        row.update({rename[k]: v for k, v in f.items()})
        rows.append(row)
    return columns, rows


def numeric_columns(columns: list[str], rows: list[dict], skip: int = 0) -> list[str]:
    """The columns (after the first ``skip``) whose every present cell is an int or a float
    (not a bool), with at least one present."""
    out = []
    for c in columns[skip:]:
        cells = [r[c] for r in rows if r.get(c) is not None]
        if cells and all(isinstance(v, int | float) and not isinstance(v, bool) for v in cells):
            out.append(c)
    return out


def choose_metric(columns: list[str], rows: list[dict], fixed: int) -> str | None:
    """The default metric: the first numeric summary column that is not part of an echoed
    configuration (``config.``) and differs between points; else the first one not under
    ``config.``; else the first numeric one."""
    numeric = numeric_columns(columns, rows, fixed)
    own = [c for c in numeric if not c.startswith("config.")]
    for c in own:
        if len({r[c] for r in rows if r.get(c) is not None}) > 1:
            return c
    return (own or numeric or [None])[0]


def write_csv(path: Path, columns: list[str], rows: list[dict]) -> Path:
    """Write the table (floats in Python's shortest round-trip form)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_atomically(path, buffer.getvalue())
    return path


def plot_metric(
    path: Path, points: Sequence[PointResult], rows: list[dict], metric: str, seed_key: str
) -> Path | None:
    """Plot ``metric`` per configuration (mean over seeds, min-max bars, every point a dot);
    None (nothing written) when no point has a finite value of it."""
    groups: dict[str, list[float]] = {}
    for p, row in zip(points, rows, strict=True):
        value = row.get(metric)
        key = label(p.values, without=(seed_key,))
        groups.setdefault(key, [])
        if isinstance(value, int | float) and math.isfinite(value):
            groups[key].append(float(value))
    groups = {k: v for k, v in groups.items() if v}
    if not groups:
        return None
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    names = list(groups)
    x = list(range(len(names)))
    means = [sum(v) / len(v) for v in groups.values()]
    lo = [m - min(v) for m, v in zip(means, groups.values(), strict=True)]
    hi = [max(v) - m for m, v in zip(means, groups.values(), strict=True)]
    fig = Figure(figsize=(max(6.0, 0.9 * len(names) + 2.0), 4.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for i, v in enumerate(groups.values()):
        ax.plot([i] * len(v), v, "o", color="0.6", ms=3, zorder=1)
    ax.errorbar(x, means, yerr=[lo, hi], fmt="s", color="tab:blue", capsize=4, zorder=2,
                label="mean; bars: min to max")  # fmt: skip
    every = [y for v in groups.values() for y in v]
    if min(every) > 0 and max(every) > 100 * min(every):
        ax.set_yscale("log")
    seeds = any(seed_key in p.values for p in points)
    ax.set_xlim(-0.5, len(names) - 0.5)
    ax.set(
        xticks=x, ylabel=metric, xlabel="configuration",
        title=f"{metric}: mean and range over {seed_key}s" if seeds else f"{metric}",
    )  # fmt: skip
    ax.set_xticklabels(names, rotation=30 if max(map(len, names)) > 12 else 0, ha="right"
                       if max(map(len, names)) > 12 else "center", fontsize=8)  # fmt: skip
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return path


def gather(
    out: Path,
    points: Sequence[PointResult],
    *,
    description: Any,
    backend: str,
    seed_key: str = "seed",
    metric: str | None = None,
    provenance: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Write ``out/sweep.csv``, ``out/sweep.png`` (when there is a numeric metric) and
    ``out/sweep.json``. ``metric`` names a numeric column of sweep.csv (default:
    :func:`choose_metric`); ``provenance`` is recorded in sweep.json as the gathering process's
    (:func:`drake_abs.parallel.provenance.provenance`). Returns ``files`` (name -> path),
    ``metric`` (the one plotted, or None) and ``metric_error`` (why the requested metric could
    not be plotted, or None)."""
    out = Path(out)
    columns, rows = table(points)
    keys = list(dict.fromkeys(k for p in points for k in p.values))
    fixed = 3 + len(keys)  # point, the values, status, error
    metric_error = None
    if metric is None:
        metric = choose_metric(columns, rows, fixed)
    elif metric not in (numeric := numeric_columns(columns, rows, fixed)):
        shown = ", ".join(numeric[:20]) if numeric else "none"
        more = f" and {len(numeric) - 20} more (see sweep.csv)" if len(numeric) > 20 else ""
        metric_error = f"{metric!r} is not a numeric column of the summaries: {shown}{more}"
        metric = None
    files = {"csv": write_csv(out / "sweep.csv", columns, rows)}
    stale = out / "sweep.png"
    png = plot_metric(stale, points, rows, metric, seed_key) if metric else None
    if png is None:
        stale.unlink(missing_ok=True)  # no plot of an earlier gathering left behind
    else:
        files["png"] = png
    files["json"] = out / "sweep.json"
    seeds = list(dict.fromkeys(json.dumps(p.values[seed_key]) for p in points
                               if seed_key in p.values))  # fmt: skip
    document = {
        "fn": description,
        "provenance": jsonable(provenance),
        "backend": backend,
        "grid": {
            "points": len(points),
            "keys": keys,
            "seed_key": seed_key,
            "seeds": [json.loads(s) for s in seeds],
            "configurations": list(
                dict.fromkeys(label(p.values, without=(seed_key,)) for p in points)
            ),
        },
        "metric": metric,
        "metric_error": metric_error,
        "counts": {
            "done": sum(p.status == "done" for p in points),
            "failed": sum(p.status != "done" for p in points),
            "reused": sum(p.reused for p in points),
        },
        "files": {k: str(v) for k, v in files.items()},
        "points": [_point_entry(p, out) for p in points],
    }
    write_atomically(files["json"], json.dumps(document, indent=2))
    return {"files": files, "metric": metric, "metric_error": metric_error}


def _point_entry(p: PointResult, out: Path) -> dict[str, Any]:
    entry = {
        "name": p.name,
        "folder": p.folder.relative_to(out).as_posix(),
        "values": jsonable(p.values),
        "status": p.status,
    }
    entry.update({"summary": p.summary} if p.status == "done" else {"error": p.error})
    entry.update({"seconds": p.seconds, "reused": p.reused})
    entry.update({"recomputed_because": p.recomputed_because, "provenance": p.provenance})
    return entry
