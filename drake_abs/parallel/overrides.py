"""Overriding fields of an experiment's ``Config`` (a frozen dataclass) by name, with each value
checked against the field's type and converted where that loses nothing.

The type of a field is its annotation when that is ``int``, ``float``, ``bool``, ``str``, a
tuple of these (``tuple[int, ...]`` or a fixed ``tuple[float, float]``) or one of these or None;
otherwise the type of its default value. Conversions: an int to a float field; a whole float
(``10.0``) or a numeric text to an int field; a numeric text (``"1e-4"``, which YAML reads as
text) to a float field; a list to a tuple field (items converted the same way) and a single item
to a one-item tuple. Booleans are only ``true``/``false``: never a number, never a number's
field. A whole-number setting is never negative (every one is a count, a size, a number of steps
or a seed). Anything else is a ValueError that names the field and the type it expects. A
Config's own checks (its ``__post_init__``, e.g. counts that must be >= 1) run when the values
are applied (:func:`apply_overrides`), which a sweep does for every point before any runs.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from numbers import Integral, Real
from typing import Any

_SCALARS = (bool, int, float, str)


def field_names(cls: type) -> list[str]:
    """The fields of a Config dataclass, in declaration order."""
    return [f.name for f in dataclasses.fields(cls)]


def _hints(cls: type) -> dict[str, Any]:
    try:
        return typing.get_type_hints(cls)
    except Exception:  # an annotation that cannot be resolved: fall back to the defaults
        return {}


def expected_type(cls: type, name: str, default: Any) -> Any:
    """The type a field's value must have: a scalar type, ``("tuple", item_type | None)``
    (any length), ``("fixed", (types...))``, ``("optional", inner)`` or None (anything; a
    field whose default is None and whose annotation says nothing usable)."""
    hint = _hints(cls).get(name)
    spec = _from_hint(hint) if hint is not None else None
    if spec is not None:
        return spec
    if isinstance(default, _SCALARS):
        return type(default)
    if isinstance(default, tuple):
        kinds = {type(v) for v in default}
        return ("tuple", kinds.pop() if len(kinds) == 1 and kinds <= set(_SCALARS) else None)
    return None if default is None else type(default)


def _from_hint(hint: Any) -> Any:
    if hint in _SCALARS:
        return hint
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis and args[0] in _SCALARS:
            return ("tuple", args[0])
        if args and Ellipsis not in args and all(a in _SCALARS for a in args):
            return ("fixed", tuple(args))
        return ("tuple", None)
    if origin in (typing.Union, types.UnionType) and type(None) in args:
        rest = [a for a in args if a is not type(None)]
        inner = _from_hint(rest[0]) if len(rest) == 1 else None
        return ("optional", inner)
    return None


def _describe(spec: Any) -> str:
    if isinstance(spec, type):
        return {bool: "true or false", int: "a whole number", float: "a number",
                str: "text"}.get(spec, spec.__name__)  # fmt: skip
    kind, inner = spec
    if kind == "tuple":
        return "a list such as [1, 2]" + (f" of {_describe(inner)}s" if inner else "")
    if kind == "fixed":
        return f"a list of {len(inner)} items ({', '.join(_describe(t) for t in inner)})"
    return f"{_describe(inner) if inner else 'a value'} or null"


def coerce(name: str, value: Any, spec: Any) -> Any:
    """``value`` converted to ``spec`` (:func:`expected_type`), or a ValueError naming ``name``."""
    bad = ValueError(f"{name}: expected {_describe(spec) if spec else 'a value'}, got {value!r}")
    if spec is None:
        return value
    if spec is bool:
        if isinstance(value, bool):
            return value
        raise bad
    if isinstance(value, bool) and spec in (int, float, str):
        raise bad
    if spec is int:
        negative = ValueError(
            f"{name}: expected a whole number >= 0 (counts, sizes, steps and seeds are never "
            f"negative), got {value!r}"
        )
        if isinstance(value, Integral):
            number = int(value)
        elif isinstance(value, Real) and float(value).is_integer():
            number = int(value)
        elif isinstance(value, str):
            try:
                number = int(value.strip(), 10)
            except ValueError:
                raise bad from None
        else:
            raise bad
        if number < 0:
            raise negative
        return number
    if spec is float:
        if isinstance(value, Real):
            return float(value)
        if isinstance(value, str):
            try:
                return float(value)
            except ValueError:
                raise bad from None
        raise bad
    if spec is str:
        if isinstance(value, str):
            return value
        raise bad
    if isinstance(spec, type):  # a default of another type (e.g. a dataclass): as it is
        if isinstance(value, spec):
            return value
        raise bad
    kind, inner = spec
    if kind == "optional":
        return None if value is None else coerce(name, value, inner)
    items = list(value) if isinstance(value, list | tuple) else [value]
    if kind == "fixed":
        if len(items) != len(inner):
            raise bad
        return tuple(
            coerce(f"{name}[{i}]", v, t) for i, (v, t) in enumerate(zip(items, inner, strict=True))
        )
    return tuple(coerce(f"{name}[{i}]", v, inner) for i, v in enumerate(items))


def check_field(cls: type, name: str) -> None:
    """A ValueError listing the fields unless ``name`` is one of ``cls``'s."""
    names = field_names(cls)
    if name not in names:
        raise ValueError(f"unknown setting {name!r}; the settings are: {', '.join(names)}")


def _resolve(config: Any, name: str) -> tuple[Any, str]:
    """For a dotted name ``"a.b.c"``, the dataclass value ``config.a.b`` and ``"c"``; for a plain
    name, ``(config, name)``. ValueError naming the part that is not a settings group."""
    *path, last = name.split(".")
    owner = config
    for i, part in enumerate(path):
        check_field(type(owner), part)
        owner = getattr(owner, part)
        if not dataclasses.is_dataclass(owner):
            where = ".".join(path[: i + 1])
            raise ValueError(f"{where!r} is not a group of settings, so {name!r} names nothing")
    return owner, last


def field_spec(config: Any, name: str) -> Any:
    """The :func:`expected_type` of field ``name`` of ``config``'s class (from the annotation,
    else from the field's default, else from ``config``'s value); ValueError for an unknown
    field. A dotted name (``settings.shac.actor_lr``) names a field of a nested settings
    dataclass."""
    config, name = _resolve(config, name)
    cls = type(config)
    check_field(cls, name)
    f = next(f for f in dataclasses.fields(cls) if f.name == name)
    default = f.default if f.default is not dataclasses.MISSING else getattr(config, name)
    return expected_type(cls, name, default)


def has_field(config: Any, name: str) -> bool:
    """Whether ``name`` (plain or dotted) names a field of ``config``."""
    try:
        owner, last = _resolve(config, name)
    except ValueError:
        return False
    return last in field_names(type(owner))


def coerce_field(config: Any, name: str, value: Any) -> Any:
    """``value`` checked and converted for field ``name`` of ``config`` (:func:`field_spec`)."""
    return coerce(name, value, field_spec(config, name))


def apply_overrides(config: Any, values: Mapping[str, Any]) -> Any:
    """``dataclasses.replace(config, **values)`` with every value checked and converted; a dotted
    name (``settings.shac.actor_lr``) replaces a field of a nested settings dataclass."""
    plain = {name: v for name, v in values.items() if "." not in name}
    changes = {name: coerce_field(config, name, v) for name, v in plain.items()}
    nested: dict[str, dict[str, Any]] = {}
    for name, v in values.items():
        if "." in name:
            head, rest = name.split(".", 1)
            _resolve(config, name)  # names the bad part now
            nested.setdefault(head, {})[rest] = v
    for head, inner in nested.items():
        if head in changes:
            raise ValueError(f"{head!r} is set both whole and by its fields; set one or the other")
        changes[head] = apply_overrides(getattr(config, head), inner)
    return dataclasses.replace(config, **changes)
