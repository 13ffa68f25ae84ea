"""Instrument effects: linear transforms between what the skin saw and what was recorded
(``[[instrument]]`` entries, ``docs/guide/effects.md``), differentiated analytically by the forward
model. Each entry's ``parameter`` is the effect parameter itself, value 0 is no effect exactly.

``indenter-tilt`` and ``tracking-bias`` apply to finite-element models (a probe axis and 3D
points exist only there); ``force-offset``, ``force-drift`` and ``robot-compliance`` to any model.
"""

from __future__ import annotations

from typing import Any

from skinkit.plugin.effects import BaseEffect, Declared, declare

_AXES = ("x", "y", "z")


class IndenterTilt(BaseEffect):
    """The probe's axis is misaligned: the drive acts along directions turned by ``angle`` [rad]
    (null 0) about the in-plane axis at ``azimuth`` [rad] from x. One ``tilt`` entry with
    ``parameter = "indenter-tilt.angle"`` and ``azimuth_parameter = "indenter-tilt.azimuth"``."""

    name = "indenter-tilt"
    kinds = ("fe",)
    touches = {"fe": frozenset({"instrument"})}

    def _declared(self) -> list[Declared]:
        return [declare("angle", 3.0, 0.0, "deg", -15.0, 15.0),
                declare("azimuth", 0.0, 0.0, "deg", -180.0, 180.0)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, [{"kind": "tilt", "parameter": f"{self.name}.angle", "value": v["angle"],
                                     "azimuth": v["azimuth"], "azimuth_parameter": f"{self.name}.azimuth"}])


class _ForceBias(BaseEffect):
    """Three ``bias`` entries on ``tip_force`` components 0, 1, 2 (parameters ``<effect>.x|y|z``)."""

    kinds = ("fe", "lumped")
    basis = "constant"

    def _entries(self, v: dict[str, float]) -> list[dict[str, Any]]:
        return [{"kind": "bias", "parameter": f"{self.name}.{a}", "value": v[a], "channel": "tip_force",
                 "component": i, "basis": self.basis} for i, a in enumerate(_AXES)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, self._entries(v))

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, self._entries(v))


class ForceOffset(_ForceBias):
    """A constant offset of the recorded tip force, ``x``, ``y``, ``z`` [N] (null 0): recorded =
    true + offset. On a force-driven model the skin saw recorded − offset."""

    name = "force-offset"
    touches = {"fe": frozenset({"instrument"}), "lumped": frozenset({"instrument"})}
    basis = "constant"

    def _declared(self) -> list[Declared]:
        return [declare(a, 20.0, 0.0, "mN", -1000.0, 1000.0) for a in _AXES]


class ForceDrift(_ForceBias):
    """A linear drift of the recorded tip force, ``x``, ``y``, ``z`` [N/s] (null 0): recorded =
    true + rate · t, t [s] the record's time. The typical 0.5 mN/s drifts by 15 mN over a 30 s
    protocol, about 9 force-noise levels (σ ≈ 1.7 mN), where 0.2 mN/s would stay below 5."""

    name = "force-drift"
    touches = {"fe": frozenset({"instrument"}), "lumped": frozenset({"instrument"})}
    basis = "time"

    def _declared(self) -> list[Declared]:
        return [declare(a, 0.5, 0.0, "mN/s", -10.0, 10.0) for a in _AXES]


class RobotCompliance(BaseEffect):
    """A series compliance between the motor and the tip, ``compliance`` [m/N] (null 0): the
    recorded tip position is the true one plus compliance · tip force. One ``series`` entry on
    ``tip_position`` with source ``tip_force``."""

    name = "robot-compliance"
    kinds = ("fe", "lumped")
    touches = {"fe": frozenset({"instrument"}), "lumped": frozenset({"instrument"})}

    def _declared(self) -> list[Declared]:
        return [declare("compliance", 1.0, 0.0, "mm/N", 0.0, 10.0)]

    def _entries(self, v: dict[str, float]) -> list[dict[str, Any]]:
        return [{"kind": "series", "parameter": f"{self.name}.compliance", "value": v["compliance"],
                 "channel": "tip_position", "source": "tip_force"}]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, self._entries(v))

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, self._entries(v))


class TrackingBias(BaseEffect):
    """A calibration error of the 3D points: a relative ``scale`` error [1] and a ``rotation`` [rad]
    about the normal through the session origin (both null 0). Two ``similarity`` entries on
    ``points`` (``mode = "scale"`` and ``"rotation"``)."""

    name = "tracking-bias"
    kinds = ("fe",)
    touches = {"fe": frozenset({"instrument"})}

    def _declared(self) -> list[Declared]:
        return [declare("scale", 1.0, 0.0, "%", -10.0, 10.0),
                declare("rotation", 0.5, 0.0, "deg", -5.0, 5.0)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.add_instrument(model, [
            {"kind": "similarity", "parameter": f"{self.name}.{m}", "value": v[m], "channel": "points",
             "mode": mode} for m, mode in (("scale", "scale"), ("rotation", "rotation"))])


__all__ = ["ForceDrift", "ForceOffset", "IndenterTilt", "RobotCompliance", "TrackingBias"]
