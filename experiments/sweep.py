"""Sweeps of the experiments: one experiment over seeds x settings of its ``Config``, run by
:func:`drake_abs.parallel.sweep.run_sweep` in this process or on Ray.

- :class:`ExperimentPoint` is the function of a point: it builds the experiment's ``Config``
  (``Config.test_size()`` or ``Config()``), applies the point's values as overrides (checked
  against the fields' types, :mod:`drake_abs.parallel.overrides`), runs the experiment into
  the point's folder and returns its summary. It is picklable (a frozen dataclass holding the
  experiment's name), so Ray workers import the experiment themselves. Every point records its
  whole resolved Config (:meth:`ExperimentPoint.resolved_config`) and what produced it
  (:mod:`drake_abs.parallel.provenance`); a finished point is reused only when all of it
  matches (:mod:`drake_abs.parallel.sweep`).
- :func:`build_grid` turns ``--seeds 0 1`` and ``--set KEY=V1,V2`` into the points: every
  combination of the settings' values, for every seed (seed-major: all configurations of the
  first seed come first). Values are YAML (``10``, ``1e-4``, ``true``, ``[10, 50]``; a list or
  ``(10, 50)`` is one tuple value), split on top-level commas only.
- :func:`report` is the text the command line prints after a sweep, :func:`check_report` the
  one of ``drake-abs sweep --check`` (what a run would do with every point, running nothing).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drake_abs.experiments.catalog import experiment_module
from drake_abs.parallel.overrides import (
    apply_overrides,
    coerce_field,
    field_names,
    field_spec,
    has_field,
)
from drake_abs.parallel.provenance import short_commit
from drake_abs.parallel.sweep import FRESH, MISSING, STALE, UNFINISHED, PointState, SweepResult
from drake_abs.parallel.sweep_points import jsonable, label


class GridError(ValueError):
    """A bad seed or setting; ``argument`` is the command-line option it came from (``--seeds``
    or ``--set``), so the command line can report it the way argparse does."""

    def __init__(self, argument: str, message: str):
        super().__init__(message)
        self.argument = argument


@dataclass(frozen=True)
class ExperimentPoint:
    """``fn`` of an experiment sweep: ``point(values, folder)`` runs experiment ``experiment``
    (dashed name) with ``values`` overriding its Config (the test-size one if ``test_size``)
    and writes its files into ``folder``; returns the experiment's summary. The experiment's own
    progress bars are off while it runs (the sweep shows one bar over the points)."""

    experiment: str
    test_size: bool = False

    def __post_init__(self):
        experiment_module(self.experiment)  # refuses an unknown name here, not on a worker

    def base_config(self) -> Any:
        """The experiment's ``Config.test_size()`` or ``Config()``."""
        cls = experiment_module(self.experiment).Config
        return cls.test_size() if self.test_size else cls()

    def config(self, values: dict) -> Any:
        """The Config of a point: the base one with ``values`` applied (ValueError for an unknown
        field or a value of the wrong type)."""
        return apply_overrides(self.base_config(), values)

    def __call__(self, values: dict, folder: Path) -> dict:
        from drake_abs.experiments import outputs

        module = experiment_module(self.experiment)
        config = self.config(values)
        previous = outputs.progress_enabled()
        outputs.set_progress(False)
        try:
            return module.run(config, out=folder)
        finally:
            outputs.set_progress(previous)

    def resolved_config(self, values: dict) -> dict:
        """The whole Config of a point as every point.json records it (JSON types): every field,
        the defaults the point's values do not override included, so that a changed default
        recomputes the point (the version and dependencies are recorded apart:
        :mod:`drake_abs.parallel.provenance`)."""
        return jsonable(self.config(values))

    def describe(self) -> dict:
        """What sweep.json and every point.json record as the sweep's function: the experiment
        and whether it starts from the test size. The rest of what a point is reused for, its
        whole Config and the versions, is recorded per point (:meth:`resolved_config`,
        :mod:`drake_abs.parallel.sweep`)."""
        return {"experiment": self.experiment, "test_size": self.test_size}


# -------------------------------------------------------------------------------------- the grid


def split_top_level(text: str) -> list[str]:
    """``text`` split on the commas that are outside brackets and quotes:
    ``"[1,2],[3]"`` -> ``["[1,2]", "[3]"]``."""
    parts, depth, quote, start = [], 0, None, 0
    for i, ch in enumerate(text):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch in "[({":
            depth += 1
        elif ch in "])}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return parts


def _parse_value(key: str, text: str, setting: str, base: Any) -> Any:
    import yaml

    t = text.strip()
    if not t:
        raise GridError("--set", f"{setting!r}: an empty value for {key}")
    if field_spec(base, key) is str and t[0] not in "'\"":
        value: Any = t  # a text field takes the text as written (no YAML yes/no/null surprises)
    else:
        if t[0] == "(" and t[-1] == ")":
            t = f"[{t[1:-1]}]"  # (10, 50) reads as a tuple
        try:
            value = yaml.safe_load(t)
        except yaml.YAMLError as err:
            first = str(err).splitlines()[0]
            raise GridError(
                "--set", f"{setting!r}: {text!r} is not a YAML value ({first})"
            ) from None
    try:
        return coerce_field(base, key, value)
    except ValueError as err:
        raise GridError("--set", f"{setting!r}: {err}") from None


def parse_setting(setting: str, base: Any) -> tuple[str, list[Any]]:
    """``KEY=V1,V2,...`` as (KEY, [values]), each value checked against field KEY of ``base``
    (a Config); GridError (``--set``) naming what is wrong."""
    key, sep, rest = setting.partition("=")
    key = key.strip()
    if not sep or not key:
        raise GridError("--set", f"expected KEY=V1,V2,... such as samples=8,16; got {setting!r}")
    if not has_field(base, key):
        raise GridError(
            "--set",
            f"{setting!r}: unknown setting {key!r}; the settings are: "
            + ", ".join(field_names(type(base))),
        )
    values = [_parse_value(key, text, setting, base) for text in split_top_level(rest)]
    for i, v in enumerate(values):
        if v in values[:i]:
            raise GridError("--set", f"{setting!r}: the value {v!r} is given twice")
    return key, values


def build_grid(
    experiment: str,
    *,
    seeds: list[int] | None = None,
    settings: list[str] | tuple[str, ...] = (),
    test_size: bool = False,
    seed_key: str = "seed",
) -> list[dict]:
    """The points of a sweep of ``experiment``: every combination of the ``settings``
    (``KEY=V1,V2`` texts) for every one of ``seeds`` (None: the Config's own seed, no seed
    key), seed-major. Values are checked against the Config's fields; GridError names the
    option (``--seeds`` or ``--set``) of a bad one: an unknown field, a wrong type, a repeated
    key or value, seeds for an experiment whose Config has no ``seed``, or a point whose
    Config refuses its values (e.g. a count of 0: every point's Config is built here, before
    any point runs)."""
    base = ExperimentPoint(experiment, test_size).base_config()
    parsed = [parse_setting(s, base) for s in settings]
    keys = [k for k, _ in parsed]
    for i, k in enumerate(keys):
        if k in keys[:i]:
            raise GridError("--set", f"{k} is set twice; give all its values in one KEY=V1,V2")
    seed_values: list[Any] = [None]
    if seeds is not None:
        if seed_key not in field_names(type(base)):
            raise GridError(
                "--seeds",
                f"{experiment} has no {seed_key!r} setting, so it cannot be run over seeds "
                f"(its settings: {', '.join(field_names(type(base)))})",
            )
        if seed_key in keys:
            raise GridError("--seeds", f"give the seeds with --seeds or with --set {seed_key}=..., "
                            "not both")  # fmt: skip
        if not seeds:
            raise GridError("--seeds", "expected at least one seed")
        try:
            seed_values = [coerce_field(base, seed_key, s) for s in seeds]
        except ValueError as err:
            raise GridError("--seeds", str(err)) from None
        if len(set(seed_values)) != len(seed_values):
            raise GridError("--seeds", f"a seed is given twice: {list(seeds)}")
    points = []
    for seed in seed_values:
        for combo in itertools.product(*(values for _, values in parsed)):
            point = {} if seeds is None else {seed_key: seed}
            point.update(zip(keys, combo, strict=True))
            points.append(point)
    for point in points:  # every point's Config is built (and checked) before any runs
        try:
            apply_overrides(base, point)
        except (ValueError, TypeError) as err:
            raise GridError(
                "--set" if keys else "--seeds",
                f"the point {point} is not a valid configuration: {err}",
            ) from None
    return points


# ---------------------------------------------------------------------------------------- report


#: At most this many points are listed by name where a report lists recomputed points.
MAX_LISTED = 20


def _what(description: Any) -> str:
    if isinstance(description, dict) and "experiment" in description:
        return description["experiment"] + (" (test size)" if description.get("test_size") else "")
    return str(description)


def produced_by(provenance: Any) -> str:
    """A provenance record in one line: ``drake-abs 0.2.0, commit d80ba48 (dirty)``."""
    version = provenance.get("drake_abs_version") if isinstance(provenance, dict) else None
    return f"drake-abs {version or 'unknown'}, commit {short_commit(provenance)}"


def report(result: SweepResult) -> str:
    """The sweep in a few lines: the counts, what produced it (drake-abs version and commit;
    reused points recorded at another commit are counted), every point recomputed although it
    had a record and why, the metric per configuration (mean, min, max over seeds), every failed
    point with where its traceback is, and the gathered files."""
    from drake_abs.parallel.sweep_gather import table

    what = _what(result.description)
    failed = result.failures
    lines = [
        f"sweep of {what}: {len(result.points)} point{'s' * (len(result.points) != 1)} on "
        f"{result.backend}: {len(result.points) - len(failed)} done, {len(failed)} failed; "
        f"{len(result.computed)} run now, {len(result.reused)} reused from an earlier run"
    ]
    if result.provenance is not None:
        now = short_commit(result.provenance)
        elsewhere: dict[str, int] = {}
        for p in result.reused:
            commit = short_commit(p.provenance)
            if commit != now:
                elsewhere[commit] = elsewhere.get(commit, 0) + 1
        line = f"run by {produced_by(result.provenance)}"
        if elsewhere:
            counts = ", ".join(f"{c}: {n} point{'s' * (n != 1)}" for c, n in elsewhere.items())
            line += f"; reused points computed at other commits: {counts}"
        lines.append(line)
    recomputed = result.recomputed
    if recomputed:
        lines.append(f"recomputed {len(recomputed)} point{'s' * (len(recomputed) != 1)} whose "
                     "earlier record could not be reused:")  # fmt: skip
        lines += [f"  {p.name}: {p.recomputed_because}" for p in recomputed[:MAX_LISTED]]
        if len(recomputed) > MAX_LISTED:
            lines.append(f"  and {len(recomputed) - MAX_LISTED} more (recomputed_because in "
                         "sweep.json)")  # fmt: skip
    if result.metric:
        _, rows = table(result.points)
        groups: dict[str, list[float]] = {}
        for p, row in zip(result.points, rows, strict=True):
            value = row.get(result.metric)
            bucket = groups.setdefault(label(p.values, without=(result.seed_key,)), [])
            if isinstance(value, int | float) and math.isfinite(value):
                bucket.append(float(value))
        width = max(len(k) for k in groups)
        lines.append(f"{result.metric} per configuration (mean, min, max over points):")
        for name, v in groups.items():
            stats = (f"{sum(v) / len(v):.4g}  {min(v):.4g}  {max(v):.4g}  (n={len(v)})"
                     if v else "no value")  # fmt: skip
            lines.append(f"  {name:{width}s}  {stats}")
    for p in failed:
        error = p.error or {}
        message = (error.get("message") or "").strip().splitlines()
        lines.append(
            f"FAILED {p.name}: {error.get('type')}: {message[0] if message else ''}\n"
            f"  traceback in {p.folder / 'point.json'}"
        )
    lines += [f"{key}: {path}" for key, path in result.files.items()]
    return "\n".join(lines)


def check_report(states: list[PointState], *, description: Any, out: Path, provenance: dict) -> str:
    """The text of ``drake-abs sweep --check``: for every point, what a run would do with it
    (:class:`~drake_abs.parallel.sweep.PointState`: fresh, stale with the reasons, missing,
    unfinished with the reason; a fresh point recorded at another commit than the current one
    names it), then the counts and what the current code is (version, commit)."""
    counts = {kind: 0 for kind in (FRESH, STALE, MISSING, UNFINISHED)}
    now = short_commit(provenance)
    width = max(len(s.name) for s in states)
    lines = [f"sweep of {_what(description)} in {out}:"]
    for s in states:
        counts[s.state] += 1
        text = f"  {s.state:10s}  {s.name:{width}s}"
        if s.reasons:
            text += f"  {s.reason}"
        elif s.state == FRESH:
            recorded = short_commit((s.record or {}).get("provenance"))
            if recorded != now:
                text += f"  (recorded at commit {recorded})"
        lines.append(text.rstrip())
    total = len(states)
    lines.append(
        f"{total} point{'s' * (total != 1)}: "
        + ", ".join(f"{n} {kind}" for kind, n in counts.items())
        + f"; current code: {produced_by(provenance)}"
    )
    if counts[FRESH] == total:
        lines.append("every point is fresh: a run would reuse them all")
    else:
        lines.append(f"a run would compute {total - counts[FRESH]} of them (the stale, missing "
                     "and unfinished ones)")  # fmt: skip
    return "\n".join(lines)
