"""Faults and refusals: one code table shared by the device model, both wire protocols and
the host drivers, so that every link reports the same one-line message."""

from __future__ import annotations

from dataclasses import dataclass

from skinkit.errors import RefusedError, SkinkitError

TRAVEL = 1
CONTINUOUS_FORCE = 2
TIP_FORCE = 3
WATCHDOG = 4
STUCK_SENSOR = 5
ESTOP = 6
NO_CONTACT = 7
PEAK_FORCE = 8
BAD_COMMAND = 9
LINK = 10

NAMES = {
    TRAVEL: "travel limit",
    CONTINUOUS_FORCE: "continuous motor force limit",
    TIP_FORCE: "tip force limit",
    WATCHDOG: "watchdog (host silent)",
    STUCK_SENSOR: "position sensor stuck",
    ESTOP: "emergency stop",
    NO_CONTACT: "no contact while homing",
    PEAK_FORCE: "peak motor force limit",
    BAD_COMMAND: "bad command",
    LINK: "link lost",
}
UNITS = {
    TRAVEL: "m",
    CONTINUOUS_FORCE: "N",
    TIP_FORCE: "N",
    WATCHDOG: "s",
    STUCK_SENSOR: "m",
    PEAK_FORCE: "N",
    NO_CONTACT: "m",
}


@dataclass(frozen=True)
class Fault:
    """What tripped: ``code`` (module constants), ``motor`` (1..3, 0 = none), the offending
    ``value`` and the ``limit`` in SI units, and the device ``time_s`` of the trip
    (relative to the start of the run, or of the device when idle)."""

    code: int
    motor: int = 0
    value: float = float("nan")
    limit: float = float("nan")
    time_s: float = float("nan")

    @property
    def name(self) -> str:
        """The fault's name (``fault code N`` for one this version does not know)."""
        return NAMES.get(self.code, f"fault code {self.code}")

    def message(self) -> str:
        """The fault in one line: name, motor, value and limit in their units."""
        where = f" on motor {self.motor}" if self.motor else ""
        unit = UNITS.get(self.code, "")
        detail = ""
        if self.value == self.value:  # not NaN
            if unit == "m":
                detail = f": {self.value * 1e3:.4f} mm"
                if self.limit == self.limit:
                    detail += f" (limit {self.limit * 1e3:.4f} mm)"
            else:
                detail = f": {self.value:.4g} {unit}"
                if self.limit == self.limit:
                    detail += f" (limit {self.limit:.4g} {unit})"
        when = f" at t={self.time_s:.4f} s" if self.time_s == self.time_s else ""
        return f"{self.name}{where}{when}{detail}"


class DeviceFault(SkinkitError):
    """The device tripped or the link failed; the robot was left de-energised."""

    def __init__(self, message: str, fault: Fault | None = None) -> None:
        self.fault = fault
        super().__init__(message)


class LimitRefused(RefusedError):
    """A programme would exceed a safety limit; refused before any motion."""

    def __init__(self, protocol: str, fault: Fault, setpoint: int | None = None) -> None:
        self.fault = fault
        where = f" (setpoint {setpoint})" if setpoint is not None else ""
        super().__init__(f"protocol {protocol!r} refused before motion: {fault.message()}{where}")
