"""A measurement protocol: a named trajectory or force programme with its parameters."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

from skinkit import jsonio
from skinkit.errors import SchemaError
from skinkit.units import is_known

ProtocolKind = Literal["trajectory", "force", "calibration", "external"]
_KINDS = ("trajectory", "force", "calibration", "external")


@dataclass(frozen=True)
class Protocol:
    """What the robot was asked to do.

    Attributes:
        name: protocol name, e.g. ``"normal_indentation"`` or ``"stochastic_full_scale"``.
        kind: ``"trajectory"`` (position controlled), ``"force"`` (open-loop force programme),
            ``"calibration"``, or ``"external"`` (a record imported from another device).
        parameters: name -> value (numbers in the unit given in ``units``, or strings).
        units: parameter name -> unit string (SI; e.g. ``{"amplitude": "m"}``).
        duration_s: planned duration in seconds, if known.
        description: free text.
    """

    name: str
    kind: ProtocolKind = "trajectory"
    parameters: dict[str, Any] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    duration_s: float | None = None
    description: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise SchemaError("Protocol.name", f"must be a non-empty string, got {self.name!r}")
        if "/" in self.name:
            raise SchemaError("Protocol.name", f"must not contain '/', got {self.name!r}")
        if self.kind not in _KINDS:
            raise SchemaError("Protocol.kind", f"must be one of {_KINDS}, got {self.kind!r}")
        for key, value in self.parameters.items():
            if not isinstance(key, str):
                raise SchemaError("Protocol.parameters", f"key {key!r} is not a string")
            if isinstance(value, bool) or isinstance(value, str):
                continue
            if isinstance(value, (int, float)):
                if not math.isfinite(value):
                    raise SchemaError(f"Protocol.parameters[{key!r}]", f"is not finite ({value})")
                continue
            if isinstance(value, (list, tuple)) and all(isinstance(v, (int, float)) for v in value):
                continue
            raise SchemaError(
                f"Protocol.parameters[{key!r}]",
                f"must be a number, string or list of numbers, got {type(value).__name__}",
            )
        for key, unit in self.units.items():
            if key not in self.parameters:
                raise SchemaError("Protocol.units", f"unit given for unknown parameter {key!r}")
            if not is_known(unit):
                raise SchemaError(f"Protocol.units[{key!r}]", f"unknown unit {unit!r}")
        if self.duration_s is not None and not (self.duration_s >= 0):
            raise SchemaError("Protocol.duration_s", f"must be >= 0, got {self.duration_s!r}")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        return {
            "name": self.name,
            "kind": self.kind,
            "parameters": {k: list(v) if isinstance(v, tuple) else v
                           for k, v in self.parameters.items()},
            "units": dict(self.units),
            "duration_s": self.duration_s,
            "description": self.description,
        }

    def to_json(self) -> str:
        """The protocol as canonical JSON (sorted keys)."""
        return jsonio.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Protocol:
        """Inverse of :meth:`to_dict`; unknown keys are refused."""
        allowed = {"name", "kind", "parameters", "units", "duration_s", "description"}
        extra = set(data) - allowed
        if extra:
            raise SchemaError("Protocol", f"unknown key(s) {sorted(extra)}")
        if "name" not in data:
            raise SchemaError("Protocol.name", "is missing")
        return cls(**data)
