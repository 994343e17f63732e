"""Sweeps of the experiments: one experiment over seeds x settings of its ``Config``, run by
:func:`drake_abs.parallel.sweep.run_sweep` in this process or on Ray.

- :class:`ExperimentPoint` is the function of a point: it builds the experiment's ``Config``
  (``Config.test_size()`` or ``Config()``), applies the point's values as overrides (checked
  against the fields' types, :mod:`drake_abs.parallel.overrides`), runs the experiment into
  the point's folder and returns its summary. It is picklable (a frozen dataclass holding the
  experiment's name), so Ray workers import the experiment themselves.
- :func:`build_grid` turns ``--seeds 0 1`` and ``--set KEY=V1,V2`` into the points: every
  combination of the settings' values, for every seed (seed-major: all configurations of the
  first seed come first). Values are YAML (``10``, ``1e-4``, ``true``, ``[10, 50]``; a list or
  ``(10, 50)`` is one tuple value), split on top-level commas only.
- :func:`report` is the text the command line prints.
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
from drake_abs.parallel.sweep import SweepResult
from drake_abs.parallel.sweep_points import label


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

    def describe(self) -> dict:
        """What sweep.json and every point.json record as the sweep's function: the experiment,
        its whole base Config (every default a point's values do not override) and the
        drake-abs version. A finished point is reused only when all of it matches: a changed
        default or another release recomputes it."""
        import dataclasses
        import json
        from importlib.metadata import PackageNotFoundError, version

        try:
            ours = version("drake-abs")
        except PackageNotFoundError:  # a checkout that is not installed
            ours = "unknown"
        config = json.loads(json.dumps(dataclasses.asdict(self.base_config()), default=str))
        return {"experiment": self.experiment, "test_size": self.test_size, "config": config,
                "drake_abs_version": ours}  # fmt: skip


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


def report(result: SweepResult) -> str:
    """The sweep in a few lines: the counts, the metric per configuration (mean, min, max over
    seeds), every failed point with where its traceback is, and the gathered files."""
    from drake_abs.parallel.sweep_gather import table

    what = result.description
    if isinstance(what, dict) and "experiment" in what:
        what = what["experiment"] + (" (test size)" if what.get("test_size") else "")
    failed = result.failures
    lines = [
        f"sweep of {what}: {len(result.points)} point{'s' * (len(result.points) != 1)} on "
        f"{result.backend}: {len(result.points) - len(failed)} done, {len(failed)} failed; "
        f"{len(result.computed)} run now, {len(result.reused)} reused from an earlier run"
    ]
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
