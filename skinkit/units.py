"""Units at the edges.

Inside skinkit every quantity is SI (m, N, s, Pa, A, kg). Users and files may state other
units (mm, kPa, mN, ...); :func:`to_si` converts them, and refuses a unit of the wrong
dimension with an error naming the field. :class:`Q` tags an array with its unit so that a
record constructor can convert or refuse it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from skinkit.errors import UnitError

# unit -> (dimension, factor to SI). Dimensions are SI unit strings themselves.
_UNITS: dict[str, tuple[str, float]] = {
    # length
    "m": ("m", 1.0), "cm": ("m", 1e-2), "mm": ("m", 1e-3), "um": ("m", 1e-6),
    "µm": ("m", 1e-6), "nm": ("m", 1e-9),
    # time
    "s": ("s", 1.0), "ms": ("s", 1e-3), "us": ("s", 1e-6), "min": ("s", 60.0),
    # frequency
    "Hz": ("Hz", 1.0), "kHz": ("Hz", 1e3),
    # force
    "N": ("N", 1.0), "mN": ("N", 1e-3), "kN": ("N", 1e3),
    # torque
    "N m": ("N m", 1.0), "N*m": ("N m", 1.0), "Nm": ("N m", 1.0), "N mm": ("N m", 1e-3),
    "mN m": ("N m", 1e-3),
    # pressure / stress / modulus
    "Pa": ("Pa", 1.0), "kPa": ("Pa", 1e3), "MPa": ("Pa", 1e6), "GPa": ("Pa", 1e9),
    # current
    "A": ("A", 1.0), "mA": ("A", 1e-3),
    # mass
    "kg": ("kg", 1.0), "g": ("kg", 1e-3),
    # lumped mechanics
    "N/m": ("N/m", 1.0), "kN/m": ("N/m", 1e3), "N/mm": ("N/m", 1e3),
    "N s/m": ("N s/m", 1.0), "N/A": ("N/A", 1.0),
    # compliances and rates (instrument effects, elastic supports)
    "m/N": ("m/N", 1.0), "mm/N": ("m/N", 1e-3), "um/N": ("m/N", 1e-6), "µm/N": ("m/N", 1e-6),
    "m/Pa": ("m/Pa", 1.0), "mm/kPa": ("m/Pa", 1e-6), "um/kPa": ("m/Pa", 1e-9), "mm/Pa": ("m/Pa", 1e-3),
    "N/s": ("N/s", 1.0), "mN/s": ("N/s", 1e-3), "m/s": ("m/s", 1.0), "mm/s": ("m/s", 1e-3),
    # angle
    "rad": ("rad", 1.0), "deg": ("rad", np.pi / 180.0),
    # image plane
    "px": ("px", 1.0),
    # dimensionless
    "1": ("1", 1.0), "": ("1", 1.0), "%": ("1", 1e-2),
    # counts / flags
    "count": ("count", 1.0),
}


def si_unit(unit: str) -> str:
    """The SI unit of ``unit``'s dimension (``"mm"`` -> ``"m"``); raises for an unknown unit."""
    try:
        return _UNITS[unit][0]
    except KeyError:
        raise UnitError("unit", f"unknown unit {unit!r}") from None


def is_known(unit: str) -> bool:
    """True when ``unit`` is in skinkit's unit table."""
    return unit in _UNITS


def to_si(value: Any, unit: str, expected: str, field: str = "value") -> np.ndarray | float:
    """Convert ``value`` given in ``unit`` to the SI unit ``expected``.

    Raises :class:`UnitError` naming ``field`` when ``unit`` is unknown or of another
    dimension than ``expected``.
    """
    if unit not in _UNITS:
        raise UnitError(field, f"unknown unit {unit!r} (expected {expected!r} or a multiple)")
    dim, factor = _UNITS[unit]
    if dim != _UNITS.get(expected, (expected, 1.0))[0]:
        raise UnitError(field, f"unit {unit!r} is not a unit of {expected!r}")
    if factor == 1.0:
        return value
    return np.asarray(value, dtype=float) * factor


def from_si(value: Any, unit: str) -> np.ndarray | float:
    """Convert an SI ``value`` to ``unit`` (for display and reports)."""
    if unit not in _UNITS:
        raise UnitError("unit", f"unknown unit {unit!r}")
    factor = _UNITS[unit][1]
    return value if factor == 1.0 else np.asarray(value, dtype=float) / factor


@dataclass(frozen=True)
class Q:
    """An array tagged with its unit, for record constructors: ``Q(x_mm, "mm")``."""

    value: Any
    unit: str
