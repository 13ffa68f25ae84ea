"""Reading the values of a model file: quantities with units (``"1.5 mm"``), bounded
quantities, whole numbers, flags, tables and strings, each refused with an error naming its entry.

Quantities are numbers in SI units or strings ``"<number> <unit>"`` (``"1.5 mm"``,
``"20 kPa"``, ``"30 deg"``); a unit of the wrong dimension is an error naming the entry.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit.errors import UnitError
from skinkit.fem.errors import ModelError
from skinkit.units import is_known, si_unit, to_si


def quantity(value: Any, unit: str, entry: str) -> float:
    """A scalar in SI ``unit`` from a number (already SI) or a ``"<number> <unit>"`` string."""
    if isinstance(value, bool):
        raise ModelError(entry, f"expected a quantity in {unit}, got {value!r}")
    if isinstance(value, (int, float)):
        return _finite(float(value), unit, entry)
    if isinstance(value, str):
        parts = value.strip().split(None, 1)
        try:
            x = float(parts[0])
        except (ValueError, IndexError):
            raise ModelError(entry, f"expected '<number> <unit>', got {value!r}") from None
        if len(parts) < 2:
            if unit == "1":
                return _finite(x, unit, entry)
            # a number in quotes without a unit is a unit left out, not a request for SI: 1.5 m
            # where "1.5 mm" was meant is a silent factor of 1000
            si = si_unit(unit) if is_known(unit) else unit
            raise ModelError(entry, f"{value!r} has no unit; write '{value.strip()} <unit>' with a unit "
                             f"of {si!r}, or a bare number (no quotes) for SI {si}")
        u = parts[1].strip()
        if not is_known(u):
            raise ModelError(entry, f"unknown unit {u!r} in {value!r}")
        try:
            return _finite(float(to_si(x, u, unit, entry)), unit, entry)
        except UnitError:
            raise ModelError(entry, f"inconsistent units: {u!r} is not a unit of {si_unit(unit)!r}") from None
    raise ModelError(entry, f"expected a quantity in {unit}, got {value!r}")


def _finite(x: float, unit: str, entry: str) -> float:
    if not math.isfinite(x):
        raise ModelError(entry, f"must be a finite quantity in {unit}, got {x}")
    return x


def bounded(value: Any, unit: str, entry: str, lo: float, hi: float, *, lo_open: bool = True) -> float:
    """A quantity in SI ``unit`` that must lie in ``(lo, hi]`` (``[lo, hi]`` if not ``lo_open``);
    the error names the entry and the accepted range."""
    x = quantity(value, unit, entry)
    if (x <= lo if lo_open else x < lo) or x > hi:
        raise ModelError(entry, f"must be in {'(' if lo_open else '['}{lo:g}, {hi:g}] {unit}, got {x:g}")
    return x


def integer(value: Any, entry: str, lo: int, hi: int) -> int:
    """A whole number in ``[lo, hi]`` (a float with an integral value is accepted)."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ModelError(entry, f"expected a whole number in [{lo}, {hi}], got {value!r}")
    if not lo <= value <= hi:
        raise ModelError(entry, f"must be a whole number in [{lo}, {hi}], got {value}")
    return value


def flag(value: Any, entry: str) -> bool:
    """A TOML boolean (``true`` / ``false``)."""
    if not isinstance(value, bool):
        raise ModelError(entry, f"expected true or false, got {value!r}")
    return value


def table(value: Any, entry: str) -> dict[str, Any]:
    """A TOML table (mapping), copied."""
    if not isinstance(value, Mapping):
        raise ModelError(entry, f"expected a table, got {value!r}")
    return dict(value)


def text(value: Any, entry: str) -> str:
    """A non-empty string."""
    if not isinstance(value, str) or not value.strip():
        raise ModelError(entry, f"expected a non-empty string, got {value!r}")
    return value


def vector(value: Any, unit: str, entry: str, n: int = 3) -> np.ndarray:
    """A length-``n`` vector of quantities."""
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ModelError(entry, f"expected a list of {n} quantities, got {value!r}")
    return np.array([quantity(v, unit, f"{entry}[{i}]") for i, v in enumerate(value)])


#: accepted grading exponents (``geometry.grading``, ``inner_grading``, ``layer_grading``,
#: ``pad_grading``): 1 is uniform; beyond 10 the finest element is a sliver of the coarsest
GRADING_RANGE = (1.0, 10.0)


def grading(g: Mapping[str, Any], key: str, default: float = 1.0) -> float:
    """A grading exponent of ``[geometry]`` in :data:`GRADING_RANGE` (default: ``default``)."""
    return bounded(g.get(key, default), "1", f"geometry.{key}", *GRADING_RANGE, lo_open=False)
