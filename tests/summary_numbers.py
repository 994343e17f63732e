"""Comparing the numbers of two experiment summaries (JSON-like dicts), for tests that run one
experiment two ways (in this process and on Ray, on a local and a joined cluster): every number
equal to 1e-12 relative, NaN matching NaN, keys containing any of ``skip`` (timings, file paths)
left out."""

from __future__ import annotations

import math


def numbers(value, skip: tuple[str, ...], path: str = ""):
    """(path, number) of every number in ``value``, keys containing any of ``skip`` left out."""
    if isinstance(value, dict):
        for key, item in value.items():
            if not any(t in key for t in skip):
                yield from numbers(item, skip, f"{path}.{key}")
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from numbers(item, skip, f"{path}[{i}]")
    elif isinstance(value, int | float) and not isinstance(value, bool):
        yield path, value


def assert_same_numbers(a: dict, b: dict, *, skip: tuple[str, ...], at_least: int) -> None:
    """The same keys (at least ``at_least`` numbers) and every number equal to 1e-12 relative."""
    x, y = dict(numbers(a, skip)), dict(numbers(b, skip))
    assert x.keys() == y.keys() and len(x) >= at_least, (len(x), len(y))
    differ = [
        (k, x[k], y[k]) for k in x
        if not (x[k] == y[k] or (math.isnan(x[k]) and math.isnan(y[k])))
        and not math.isclose(x[k], y[k], rel_tol=1e-12, abs_tol=0.0)
    ]  # fmt: skip
    assert not differ, differ[:5]
