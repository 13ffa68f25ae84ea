"""Shape, dtype and unit checks shared by the record types.

A shape is a tuple of ints (fixed extent) and strings (named extents such as ``"N"``
that must agree across the fields of one record). Errors name the field.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from skinkit.errors import SchemaError
from skinkit.units import Q, format_quantity, to_si


def _fmt(shape: tuple[int | str, ...]) -> str:
    return "(" + ", ".join(str(s) for s in shape) + (",)" if len(shape) == 1 else ")")


def as_array(
    value: Any,
    field: str,
    shape: tuple[int | str, ...],
    unit: str,
    dims: dict[str, int],
    dtype: Any = float,
    finite: bool = False,
) -> np.ndarray:
    """Coerce ``value`` to an array of ``dtype`` with SI ``unit`` and check its ``shape``.

    ``value`` may be a :class:`skinkit.units.Q` in another unit of the same dimension.
    Named extents are bound in ``dims`` on first sight and checked afterwards.
    ``finite`` refuses NaN and infinities.
    """
    if isinstance(value, Q):
        value = to_si(value.value, value.unit, unit, field)
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise SchemaError(field, f"cannot be read as {np.dtype(dtype).name} array ({exc})") from None
    if arr.ndim != len(shape):
        raise SchemaError(
            field, f"expected {len(shape)}-d array of shape {_fmt(shape)}, got shape {arr.shape}"
        )
    for axis, (want, got) in enumerate(zip(shape, arr.shape, strict=True)):
        if isinstance(want, str):
            bound = dims.setdefault(want, got)
            if bound != got:
                raise SchemaError(
                    field,
                    f"axis {axis} has length {got} but {want}={bound} elsewhere in the record "
                    f"(expected shape {_fmt(shape)})",
                )
        elif want != got:
            raise SchemaError(field, f"expected shape {_fmt(shape)}, got {arr.shape}")
    if finite and arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise SchemaError(field, f"{bad} non-finite value(s) (NaN or inf) where finite values are required")
    return arr


def check_unit(field: str, given: str | None, expected: str) -> None:
    """Refuse a stated unit that is not the field's SI unit (used when reading files)."""
    if given is not None and given != expected:
        raise SchemaError(field, f"unit {given!r} where {expected!r} is required")


def as_float(value: Any, field: str, unit: str, lo: float | None = None, hi: float | None = None,
             allow_nan: bool = False) -> float:
    """A scalar in SI ``unit``, optionally bounded (inclusive)."""
    if isinstance(value, Q):
        value = to_si(value.value, value.unit, unit, field)
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise SchemaError(field, f"expected a number in {unit!r}, got {value!r}") from None
    if np.isnan(x):
        if allow_nan:
            return x
        raise SchemaError(field, "is NaN")
    if lo is not None and x < lo:
        raise SchemaError(field, f"{format_quantity(x, unit)} is below its minimum {lo:g}")
    if hi is not None and x > hi:
        raise SchemaError(field, f"{format_quantity(x, unit)} is above its maximum {hi:g}")
    return x
