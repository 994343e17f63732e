"""Argument checks shared by the core: finite values and explicit shapes, with errors that name
the argument and the expected form."""

from __future__ import annotations

import numbers

import numpy as np


def as_finite_array(value, name: str, *, ndim: tuple[int, ...] | None = None) -> np.ndarray:
    """Return ``value`` as a float64 array, raising ``ValueError`` naming ``name`` when it is not
    numeric, complex (its imaginary part would be dropped), not finite, or has a number of
    dimensions outside ``ndim``."""
    try:
        complex_values = np.iscomplexobj(value)
    except (TypeError, ValueError):  # not array-like: reported below
        complex_values = False
    if complex_values:
        raise ValueError(
            f"{name} must be a real numeric array; got complex values (the imaginary part would "
            "be dropped)"
        )
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(
            f"{name} must be a real numeric array; got {type(value).__name__}"
        ) from err
    if ndim is not None and arr.ndim not in ndim:
        forms = " or ".join(f"{n}-D" for n in ndim)
        raise ValueError(f"{name} must be {forms}; got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(
            f"{name} contains NaN or inf (first at index {tuple(int(i) for i in bad)}: "
            f"{arr[tuple(bad)]}); all entries must be finite"
        )
    return arr


def check_finite_batch(arr: np.ndarray, name: str, *, batched: bool = True, what: str = "") -> None:
    """Raise ``ValueError`` unless every entry of ``arr`` (B, n) is finite, naming the first bad
    entry by its row (the batch index) and column, its value, and how many there are: ``x must
    be finite; x[2, 4] is nan (batch row 2, column 4)``. With ``batched`` False, ``arr`` is one
    row given as a vector, named by its column alone (``x[4] is nan``). ``what`` starts the
    message (e.g. ``"ComplementarityPlant: the discrete state "``)."""
    finite = np.isfinite(arr)
    if finite.all():
        return
    bad = np.argwhere(~finite)
    row, col = (int(i) for i in bad[0])
    where = f"{name}[{row}, {col}]" if batched else f"{name}[{col}]"
    at = f" (batch row {row}, column {col})" if batched else ""
    more = f"; {len(bad)} non-finite entries in all" if len(bad) > 1 else ""
    raise ValueError(f"{what}{name} must be finite; {where} is {arr[row, col]}{at}{more}")


def check_counts(config, names: tuple[str, ...]) -> None:
    """Raise ``ValueError`` naming the field unless each field ``names`` of ``config`` (e.g. an
    experiment's Config) is a count: an integer >= 1, or for a tuple field a non-empty tuple of
    integers >= 1 (e.g. sample sizes)."""
    for name in names:
        value = getattr(config, name)
        if isinstance(value, tuple):
            if not value:
                raise ValueError(f"{name} must hold at least one whole number >= 1; got ()")
            for i, item in enumerate(value):
                as_count(item, f"{name}[{i}]", minimum=1)
        else:
            as_count(value, name, minimum=1)


def as_real_number(value, name: str, *, minimum: float | None = None) -> float:
    """Return ``value`` as a ``float``, raising ``ValueError`` naming ``name`` unless it is a
    real number (int, float or a numpy real scalar; not a bool, a string or a complex number)
    that is finite and, given ``minimum``, at least ``minimum``."""
    real = isinstance(value, numbers.Real) and not isinstance(value, bool)
    if not real or not np.isfinite(float(value)):
        raise ValueError(f"{name} must be a finite real number; got {value!r}")
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be a finite real number >= {minimum:g}; got {value!r}")
    return float(value)


def check_shape(arr: np.ndarray, expected: tuple[int, ...], name: str, form: str) -> None:
    """Raise ``ValueError`` when ``arr.shape != expected``; ``form`` spells the expected shape in
    symbols, e.g. ``"(dx, dx)"``."""
    if arr.shape != expected:
        raise ValueError(f"{name} must have shape {form} = {expected}; got {arr.shape}")


def as_count(value, name: str, *, minimum: int = 0) -> int:
    """Return ``value`` as an ``int``, raising ``ValueError`` naming ``name`` unless it is an
    integer (or an integral float) >= ``minimum``; booleans and strings are rejected."""
    integral = isinstance(value, numbers.Integral) or (
        isinstance(value, float) and value.is_integer()
    )
    if isinstance(value, bool) or not integral or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


def batch_of_states(x, u, nx: int, nu: int) -> tuple[np.ndarray, np.ndarray, bool]:
    """States x (B, nx) and inputs u (B, nu) of one batched step, checked: one state (nx,)
    becomes a batch of one, inputs (nu,) are shared by the batch. Returns (x, u, batched), where
    ``batched`` is False for one unbatched state. ``ValueError`` names the argument and the
    expected shape, or the first entry that is not finite (row and column,
    :func:`check_finite_batch`)."""
    x = np.asarray(x, dtype=float)
    batched = x.ndim != 1
    x = np.atleast_2d(x)
    if x.ndim != 2 or x.shape[1] != nx:
        raise ValueError(f"x must have shape (B, nx) = (B, {nx}) or (nx,); got {x.shape}")
    u = np.asarray(u, dtype=float)
    u_batched = u.ndim != 1
    try:
        u = np.broadcast_to(u, (x.shape[0], nu)) if u.shape != (x.shape[0], nu) else u
    except ValueError:
        raise ValueError(
            f"u must have shape (B, nu) = ({x.shape[0]}, {nu}) or (nu,); got {u.shape}"
        ) from None
    check_finite_batch(x, "x", batched=batched)
    check_finite_batch(u if u_batched else u[:1], "u", batched=batched and u_batched)
    return x, u, batched
