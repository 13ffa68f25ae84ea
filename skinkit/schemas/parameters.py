"""Named model parameters with units, bounds and a free/fixed flag."""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from skinkit.errors import SchemaError
from skinkit.units import format_quantity, is_known, si_unit, to_si


@dataclass(frozen=True)
class Parameter:
    """One parameter. Given in any known unit, it is stored in the SI unit of its dimension.

    Attributes:
        name: identifier, unique within a set (e.g. ``"skin.mu"``).
        value: value in ``unit``.
        unit: SI unit (``"Pa"``, ``"1"``, ``"s"``...).
        lower, upper: inclusive bounds in ``unit`` (``-inf``/``inf`` when unbounded).
        free: True when an identification may change it.
    """

    name: str
    value: float
    unit: str = "1"
    lower: float = -math.inf
    upper: float = math.inf
    free: bool = True

    def __post_init__(self) -> None:
        f = f"Parameter[{self.name!r}]"
        if not isinstance(self.name, str) or not self.name:
            raise SchemaError("Parameter.name", f"must be a non-empty string, got {self.name!r}")
        if not is_known(self.unit):
            raise SchemaError(f"{f}.unit", f"unknown unit {self.unit!r}")
        si = si_unit(self.unit)
        vals = {}
        for key in ("value", "lower", "upper"):
            raw = getattr(self, key)
            try:
                x = float(raw)
            except (TypeError, ValueError):
                raise SchemaError(f"{f}.{key}", f"expected a number, got {raw!r}") from None
            vals[key] = float(to_si(x, self.unit, si, f"{f}.{key}"))
        if math.isnan(vals["value"]) or not math.isfinite(vals["value"]):
            raise SchemaError(f"{f}.value", f"must be finite, got {vals['value']}")
        if vals["lower"] > vals["upper"]:
            raise SchemaError(f, f"lower bound {vals['lower']:g} is above upper bound {vals['upper']:g}")
        if not vals["lower"] <= vals["value"] <= vals["upper"]:
            raise SchemaError(f"{f}.value", f"{format_quantity(vals['value'], si)} is outside its bounds "
                              f"[{vals['lower']:g}, {vals['upper']:g}]")
        object.__setattr__(self, "unit", si)
        for key, x in vals.items():
            object.__setattr__(self, key, x)
        object.__setattr__(self, "free", bool(self.free))

    def __str__(self) -> str:
        """For people: ``"skin.mu = 1e+04 Pa"``, ``"skin.k1 = 0.5 (fixed)"`` (a dimensionless
        value bare, without a unit after it)."""
        return f"{self.name} = {self.describe()}"

    def describe(self, spec: str = "g") -> str:
        """The value with its unit, formatted with ``spec``, and ``(fixed)`` when not free."""
        return format_quantity(self.value, self.unit, spec) + ("" if self.free else " (fixed)")


#: the sibling keys that say why a bound is None
_REASONS = ("lower_reason", "upper_reason")
UNBOUNDED = "unbounded"


def bound_entries(lower: float, upper: float) -> dict[str, Any]:
    """``lower`` and ``upper`` as JSON entries: an infinite bound is None with a sibling
    ``<side>_reason`` = ``"unbounded"``."""
    out: dict[str, Any] = {}
    for side, x in (("lower", lower), ("upper", upper)):
        infinite = math.isinf(x)
        out[side] = None if infinite else x
        if infinite:
            out[f"{side}_reason"] = UNBOUNDED
    return out


class ParameterSet:
    """An ordered set of :class:`Parameter` with a vector view of the free ones.

    ``pset["skin.mu"]`` is the value [SI]; ``pset.free_vector()`` the free values in order;
    ``pset.with_free_vector(x)`` a copy with them replaced (bounds checked).
    """

    def __init__(self, parameters: Iterable[Parameter]) -> None:
        self._params: dict[str, Parameter] = {}
        for p in parameters:
            if not isinstance(p, Parameter):
                raise SchemaError("ParameterSet", f"holds a {type(p).__name__}, not a Parameter")
            if p.name in self._params:
                raise SchemaError("ParameterSet", f"duplicate parameter name {p.name!r}")
            self._params[p.name] = p

    def __getitem__(self, name: str) -> float:
        return self.param(name).value

    def param(self, name: str) -> Parameter:
        """The parameter ``name``; KeyError naming the ones there are."""
        try:
            return self._params[name]
        except KeyError:
            raise KeyError(f"no parameter {name!r} (have {list(self._params)})") from None

    def __contains__(self, name: object) -> bool:
        return name in self._params

    def __iter__(self) -> Iterator[Parameter]:
        return iter(self._params.values())

    def __len__(self) -> int:
        return len(self._params)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ParameterSet) and list(self) == list(other)

    def __repr__(self) -> str:
        inner = ", ".join(f"{p.name}={p.describe()}" for p in self)
        return f"ParameterSet({inner})"

    @property
    def names(self) -> list[str]:
        """Every parameter's name, in order."""
        return list(self._params)

    @property
    def free_names(self) -> list[str]:
        """The free parameters' names, in order."""
        return [p.name for p in self if p.free]

    def values(self) -> dict[str, float]:
        """name -> SI value, for every parameter."""
        return {p.name: p.value for p in self}

    def free_vector(self) -> np.ndarray:
        """``(n_free,)`` values of the free parameters, in order [SI]."""
        return np.array([p.value for p in self if p.free], dtype=float)

    def free_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of the free parameters, each ``(n_free,)``."""
        free = [p for p in self if p.free]
        return (np.array([p.lower for p in free], dtype=float),
                np.array([p.upper for p in free], dtype=float))

    def with_free_vector(self, x: Any) -> ParameterSet:
        """A copy with the free values replaced by ``x`` (``(n_free,)``), bounds checked."""
        x = np.asarray(x, dtype=float).ravel()
        names = self.free_names
        if x.shape != (len(names),):
            raise SchemaError("ParameterSet.free_vector", f"expected {len(names)} values, got {x.size}")
        return self.with_values(dict(zip(names, x.tolist(), strict=True)))

    def with_values(self, values: Mapping[str, float]) -> ParameterSet:
        """A copy with some values replaced (SI), bounds checked."""
        unknown = set(values) - set(self._params)
        if unknown:
            raise SchemaError("ParameterSet", f"unknown parameter(s) {sorted(unknown)}")
        return ParameterSet(replace(p, value=values.get(p.name, p.value)) for p in self)

    def to_list(self) -> list[dict[str, Any]]:
        """JSON-ready list of dicts. An infinite bound is None, with ``lower_reason`` /
        ``upper_reason`` ``"unbounded"`` beside it (strict JSON has no infinity)."""
        return [{"name": p.name, "value": p.value, "unit": p.unit, **bound_entries(p.lower, p.upper),
                 "free": p.free} for p in self]

    @classmethod
    def from_list(cls, items: Iterable[Mapping[str, Any]]) -> ParameterSet:
        """Inverse of :meth:`to_list`."""
        out = []
        for i, d in enumerate(items):
            if not isinstance(d, Mapping) or "name" not in d or "value" not in d:
                raise SchemaError(f"ParameterSet[{i}]", "needs at least 'name' and 'value'")
            extra = set(d) - {"name", "value", "unit", "lower", "upper", "free", *_REASONS}
            if extra:
                raise SchemaError(f"ParameterSet[{i}]", f"unknown key(s) {sorted(extra)}")
            out.append(Parameter(
                name=d["name"], value=d["value"], unit=d.get("unit", "1"),
                lower=-math.inf if d.get("lower") is None else d["lower"],
                upper=math.inf if d.get("upper") is None else d["upper"],
                free=d.get("free", True)))
        return cls(out)
