"""The robot record: what the microrobot measured during one protocol."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from skinkit.errors import SchemaError
from skinkit.schemas._fields import as_array
from skinkit.schemas.protocol import Protocol

# Bits of RobotRecord.flags. Drivers set them per sample; the store keeps them.
FLAG_SATURATED = 1 << 0  #: a motor force or current was at its limit
FLAG_LIMIT = 1 << 1  #: a travel or force safety limit tripped
FLAG_ESTOP = 1 << 2  #: emergency stop active
FLAG_SAMPLES_LOST = 1 << 3  #: samples were lost on the link before this one
FLAG_CAMERA_TRIGGER = 1 << 4  #: a camera trigger was issued at this sample
FLAG_CONTACT = 1 << 5  #: probe in contact with the skin (contact detection)
FLAG_NAMES = {
    FLAG_SATURATED: "saturated",
    FLAG_LIMIT: "limit",
    FLAG_ESTOP: "estop",
    FLAG_SAMPLES_LOST: "samples_lost",
    FLAG_CAMERA_TRIGGER: "camera_trigger",
    FLAG_CONTACT: "contact",
}


@dataclass
class RobotRecord:
    """Time series recorded by the robot (or imported from another device), in SI units.

    Every channel is optional except ``time_s``; a present channel has shape ``(N, 3)``.
    Motor channels are per motor (columns = motors 1, 2, 3); tip channels are in the robot
    frame (columns = x, y, z; z along the probe's normal indentation). A column that a
    device did not measure is NaN.

    Attributes:
        time_s: ``(N,)`` sample times [s], strictly increasing.
        motor_position: ``(N, 3)`` [m].
        motor_current: ``(N, 3)`` [A].
        motor_force: ``(N, 3)`` [N].
        tip_position: ``(N, 3)`` [m].
        tip_force: ``(N, 3)`` [N] (force applied by the probe to the skin).
        tip_torque: ``(N, 3)`` [N m].
        flags: ``(N,)`` uint32 bit set, see ``FLAG_*`` in this module.
        protocol: the protocol this record belongs to.
    """

    #: channel name -> SI unit; order is the order in files
    CHANNELS: ClassVar[dict[str, str]] = {
        "motor_position": "m",
        "motor_current": "A",
        "motor_force": "N",
        "tip_position": "m",
        "tip_force": "N",
        "tip_torque": "N m",
    }

    time_s: Any
    motor_position: Any = None
    motor_current: Any = None
    motor_force: Any = None
    tip_position: Any = None
    tip_force: Any = None
    tip_torque: Any = None
    flags: Any = None
    protocol: Protocol = field(default_factory=lambda: Protocol("unnamed", kind="external"))

    def __post_init__(self) -> None:
        dims: dict[str, int] = {}
        self.time_s = as_array(self.time_s, "RobotRecord.time_s", ("N",), "s", dims, finite=True)
        n = dims["N"]
        if n >= 2 and not np.all(np.diff(self.time_s) > 0):
            i = int(np.argmin(np.diff(self.time_s) > 0))
            raise SchemaError(
                "RobotRecord.time_s",
                f"must be strictly increasing; sample {i + 1} (t={self.time_s[i + 1]:.6g} s) "
                f"does not follow sample {i} (t={self.time_s[i]:.6g} s)",
            )
        for name, unit in self.CHANNELS.items():
            value = getattr(self, name)
            if value is not None:
                setattr(self, name, as_array(value, f"RobotRecord.{name}", ("N", 3), unit, dims))
        if self.flags is None:
            self.flags = np.zeros(n, dtype=np.uint32)
        else:
            flags = np.asarray(self.flags)
            if flags.dtype.kind == "f" or (flags.size and flags.min() < 0):
                raise SchemaError("RobotRecord.flags", "must be non-negative integers (a bit set)")
            self.flags = as_array(flags, "RobotRecord.flags", ("N",), "count", dims, dtype=np.uint32)
        if not isinstance(self.protocol, Protocol):
            raise SchemaError("RobotRecord.protocol",
                              f"must be a Protocol, got {type(self.protocol).__name__}")

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.time_s.shape[0])

    @property
    def channels(self) -> list[str]:
        """Names of the channels present (not None)."""
        return [c for c in self.CHANNELS if getattr(self, c) is not None]

    @property
    def rate_hz(self) -> float:
        """Sampling rate from the median sample interval [Hz]; NaN with fewer than 2 samples."""
        if self.n_samples < 2:
            return float("nan")
        return float(1.0 / np.median(np.diff(self.time_s)))

    def is_uniform(self, rtol: float = 1e-3) -> bool:
        """True when every sample interval is within ``rtol`` of the median interval."""
        if self.n_samples < 3:
            return True
        dt = np.diff(self.time_s)
        return bool(np.all(np.abs(dt - np.median(dt)) <= rtol * np.median(dt)))

    def slice(self, start: int, stop: int) -> RobotRecord:
        """Samples ``start:stop`` as a new record with the same protocol."""
        kw = {c: getattr(self, c)[start:stop] for c in self.channels}
        return RobotRecord(time_s=self.time_s[start:stop], flags=self.flags[start:stop],
                           protocol=self.protocol, **kw)
