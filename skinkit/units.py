"""Units at the edges.

Inside skinkit every quantity is SI (m, N, s, Pa, A, kg). Users and files may state other
units (mm, kPa, mN, ...); :func:`to_si` converts them, and refuses a unit of the wrong
dimension with an error naming the field. :class:`Q` tags an array with its unit so that a
record constructor can convert or refuse it.

A unit string is a product of known units with optional integer powers, optionally divided
by another such product: ``"mm"``, ``"1/mm"``, ``"N/mm"``, ``"N s/m"`` (or ``"N*s/m"``),
``"mm/kPa"``, ``"m/s^2"``, ``"m s^-2"``. Each known unit has a dimension (powers of m, kg, s,
A and of the non-SI kinds rad, px, count) and an exact factor to its SI counterpart; a
compound unit's factor is the product of its parts' factors, computed exactly and rounded
once, so ``1/mm`` is exactly 1000 per metre. Two units convert into each other when their
dimensions agree: ``1/s`` and ``Hz`` do, ``N/m`` and ``Pa`` do not.

The dimensionless unit is ``"1"`` (also written ``""``); :func:`unit_suffix` and
:func:`format_quantity` print a dimensionless value bare, without a unit after the number.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache
from typing import Any

import numpy as np

from skinkit.errors import UnitError

#: the base dimensions: SI's m, kg, s, A, and kinds kept apart from pure numbers
#: (an angle, a length on the image plane, a count) so that they are never mixed silently
_BASES = ("m", "kg", "s", "A", "rad", "px", "count")

_NEWTON = {"kg": 1, "m": 1, "s": -2}
_PASCAL = {"kg": 1, "m": -1, "s": -2}

# unit -> (SI counterpart, dimension as base powers, exact factor to the SI counterpart).
# The counterpart is the name an SI value of that kind is written with ("mm" -> "m").
_ATOMS: dict[str, tuple[str, dict[str, int], Fraction]] = {}


def _atom(si: str, dims: dict[str, int], **units: Fraction | float) -> None:
    for name, factor in units.items():
        _ATOMS[name] = (si, dims, Fraction(factor))


# keyword names cannot hold "µ" and "%", so those are added by hand below
_atom("m", {"m": 1}, m=1, cm=Fraction(1, 100), mm=Fraction(1, 1000), um=Fraction(1, 10**6),
      nm=Fraction(1, 10**9))
_atom("s", {"s": 1}, s=1, ms=Fraction(1, 1000), us=Fraction(1, 10**6), min=60)
_atom("Hz", {"s": -1}, Hz=1, kHz=1000)
_atom("N", _NEWTON, N=1, mN=Fraction(1, 1000), kN=1000)
_atom("Pa", _PASCAL, Pa=1, kPa=1000, MPa=10**6, GPa=10**9)
_atom("A", {"A": 1}, A=1, mA=Fraction(1, 1000))
_atom("kg", {"kg": 1}, kg=1, g=Fraction(1, 1000))
# the degree is irrational in radians: its factor is the float pi/180 skinkit has always used
_atom("rad", {"rad": 1}, rad=1, deg=math.pi / 180.0)
_atom("px", {"px": 1}, px=1)
_atom("count", {"count": 1}, count=1)
_ATOMS["µm"] = ("m", {"m": 1}, Fraction(1, 10**6))
_ATOMS["µs"] = ("s", {"s": 1}, Fraction(1, 10**6))
_ATOMS["μm"] = _ATOMS["µm"]   # the Greek letter mu, which keyboards give as often as the micro sign
_ATOMS["μs"] = _ATOMS["µs"]
_ATOMS["%"] = ("1", {}, Fraction(1, 100))

#: spellings of a whole unit that the grammar below does not cover
_ALIASES = {"": "1", "Nm": "N m"}

_POWER = re.compile(r"^(?P<name>[^\^²³]+)(?:\^(?P<power>[-+]?\d+)|(?P<sup>[²³]))?$")
_SUPERSCRIPT = {"²": 2, "³": 3}


@dataclass(frozen=True)
class Unit:
    """A parsed unit: its SI form (``"N s/m"``), dimension and exact factor to SI.

    Attributes:
        text: the unit as written.
        si: the SI unit of the same structure (``"mm/kPa"`` -> ``"m/Pa"``; ``"1"`` when
            dimensionless).
        dims: the dimension as ``(base, power)`` pairs over :data:`_BASES`, zero powers left out.
        factor: SI value of one ``text`` (exact rational; a float only for ``deg``).
    """

    text: str
    si: str
    dims: tuple[tuple[str, int], ...]
    factor: Fraction

    @property
    def scale(self) -> float:
        """``factor`` rounded once to a float."""
        return float(self.factor)


class _UnknownUnit(UnitError):
    """A unit string with a part that is not a known unit; ``what`` names that part."""

    def __init__(self, name: str, whole: str, expected: str | None = None, field: str = "unit") -> None:
        self.name, self.whole = name, whole
        self.what = f"unknown unit {name!r}" + (f" in {whole!r}" if name != whole.strip() else "")
        known = ", ".join(sorted(k for k in _ATOMS if k))
        hint = f"expected {expected!r} or a multiple; " if expected else ""
        super().__init__(field, f"{self.what} ({hint}known units: {known}, and products and "
                         "quotients of them such as 'N/mm' or '1/s')")


def _factors(side: str, sign: int, whole: str) -> list[tuple[str, int]]:
    """``(known unit, power)`` of one side of a quotient (``sign`` -1 for the denominator)."""
    side = side.strip()
    if side.startswith("(") and side.endswith(")"):
        side = side[1:-1]
    out = []
    for token in re.split(r"[\s*·]+", side.replace("**", "^").strip()):
        if not token or token == "1":
            continue
        m = _POWER.match(token)
        name = m["name"] if m else token
        if m is None or name not in _ATOMS:
            raise _UnknownUnit(name, whole)
        power = int(m["power"]) if m["power"] else _SUPERSCRIPT.get(m["sup"] or "", 1)
        out.append((name, sign * power))
    return out


def parse(unit: str) -> Unit:
    """Parse a unit string (module docstring); :class:`UnitError` names an unknown part."""
    if not isinstance(unit, str):
        raise UnitError("unit", f"a unit is text, got {unit!r}")
    return _parse(unit)


@lru_cache(maxsize=512)
def _parse(unit: str) -> Unit:
    text = _ALIASES.get(unit.strip(), unit.strip())
    if text.count("/") > 1:
        raise UnitError("unit", f"{unit!r} has more than one '/'; write the denominator as one "
                        "product, e.g. 'N/(m s)' or 'N m^-1 s^-1'")
    num, _, den = text.partition("/")
    if "/" in text and not den.strip():
        raise UnitError("unit", f"{unit!r} has nothing after '/'")
    parts = _factors(num, 1, unit) + _factors(den, -1, unit)
    factor = Fraction(1)
    dims: dict[str, int] = {}
    si_powers: dict[str, int] = {}   # SI counterparts in order of first appearance
    for name, power in parts:
        si, d, f = _ATOMS[name]
        factor *= f ** power
        for base, k in d.items():
            dims[base] = dims.get(base, 0) + k * power
        if si != "1":
            si_powers[si] = si_powers.get(si, 0) + power
    return Unit(unit, _si_text(si_powers),
                tuple((b, dims[b]) for b in _BASES if dims.get(b)), factor)


def _si_text(powers: dict[str, int]) -> str:
    """``{"N": 1, "s": 1, "m": -1}`` -> ``"N s/m"``; ``"1"`` when nothing is left."""
    def term(name: str, k: int) -> str:
        return name if k == 1 else f"{name}^{k}"
    num = [term(n, k) for n, k in powers.items() if k > 0]
    den = [term(n, -k) for n, k in powers.items() if k < 0]
    if not den:
        return " ".join(num) or "1"
    d = " ".join(den)
    return f"{' '.join(num) or '1'}/{d if len(den) == 1 else f'({d})'}"


def si_unit(unit: str) -> str:
    """The SI unit of ``unit``, of the same structure (``"mm"`` -> ``"m"``, ``"N/mm"`` ->
    ``"N/m"``, ``"1/mm"`` -> ``"1/m"``, ``"%"`` -> ``"1"``); raises for an unknown unit."""
    return parse(unit).si


def is_known(unit: str) -> bool:
    """True when ``unit`` is a known unit or a product/quotient of known units."""
    try:
        parse(unit)
    except UnitError:
        return False
    return True


def same_dimension(a: str, b: str) -> bool:
    """True when ``a`` and ``b`` are units of the same dimension (``"1/s"`` and ``"Hz"``)."""
    return parse(a).dims == parse(b).dims


def to_si(value: Any, unit: str, expected: str, field: str = "value") -> np.ndarray | float:
    """Convert ``value`` given in ``unit`` to the SI unit ``expected``.

    Raises :class:`UnitError` naming ``field`` when ``unit`` is unknown or of another
    dimension than ``expected``.
    """
    try:
        u = parse(unit)
    except _UnknownUnit as exc:
        raise _UnknownUnit(exc.name, exc.whole, expected, field) from None
    except UnitError as exc:
        raise UnitError(field, f"{exc.problem} (expected {expected!r} or a multiple)") from None
    try:
        want = parse(expected)
    except UnitError:
        raise UnitError(field, f"unit {unit!r} is not a unit of {expected!r}") from None
    if u.dims != want.dims:
        raise UnitError(field, f"unit {unit!r} is not a unit of {expected!r}")
    # to SI, whatever multiple ``expected`` is written in (a field declared in "deg" holds rad)
    if u.factor == 1:
        return value
    return np.asarray(value, dtype=float) * u.scale


def from_si(value: Any, unit: str) -> np.ndarray | float:
    """Convert an SI ``value`` to ``unit`` (for display and reports)."""
    try:
        factor = parse(unit).factor
    except UnitError as exc:
        raise UnitError("unit", exc.problem) from None
    return value if factor == 1 else np.asarray(value, dtype=float) / float(factor)


def is_dimensionless_text(unit: str | None) -> bool:
    """True when ``unit`` is written as the dimensionless unit (``"1"``, ``""`` or None)."""
    return unit is None or unit.strip() in ("", "1")


def unit_suffix(unit: str | None) -> str:
    """What follows a number printed for people: ``" kPa"``, and ``""`` for a dimensionless
    value (no ``1`` after a number)."""
    return "" if is_dimensionless_text(unit) else f" {unit.strip()}"   # type: ignore[union-attr]


def format_quantity(value: float, unit: str | None, spec: str = "g") -> str:
    """``value`` formatted with ``spec`` and its unit: ``"12 kPa"``, ``"0.45"`` (dimensionless)."""
    return f"{value:{spec}}{unit_suffix(unit)}"


@dataclass(frozen=True)
class Q:
    """An array tagged with its unit, for record constructors: ``Q(x_mm, "mm")``."""

    value: Any
    unit: str
