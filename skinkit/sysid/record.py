"""Taking force and position from a :class:`~skinkit.schemas.RobotRecord` or plain arrays."""

from __future__ import annotations

from typing import Any

import numpy as np

from skinkit.schemas import RobotRecord
from skinkit.sysid.checks import Signals, SysidError, check_signals

_AXES = {"x": 0, "y": 1, "z": 2}


def axis_index(axis: int | str) -> int:
    """``0/1/2`` or ``"x"/"y"/"z"`` -> column index."""
    if isinstance(axis, str):
        if axis not in _AXES:
            raise SysidError(f"axis must be x, y or z, got {axis!r}")
        return _AXES[axis]
    if axis not in (0, 1, 2):
        raise SysidError(f"axis must be 0, 1 or 2, got {axis!r}")
    return int(axis)


def record_signals(record: RobotRecord, axis: int | str = 2, memory_s: float | None = None,
                   force_limit_N: float | None = None) -> Signals:
    """Checked tip force and position along ``axis`` (default z, the normal) of ``record``."""
    a = axis_index(axis)
    name = record.protocol.name
    for ch in ("tip_force", "tip_position"):
        arr = getattr(record, ch)
        if arr is None:
            raise SysidError(f"record {name!r} has no {ch} channel (channels: "
                             f"{', '.join(record.channels) or 'none'})")
        if np.isnan(arr[:, a]).all():
            raise SysidError(f"record {name!r}: {ch} along axis {'xyz'[a]} is all NaN")
    return check_signals(record.tip_force[:, a], record.tip_position[:, a], time_s=record.time_s,
                         memory_s=memory_s, flags=record.flags, force_limit_N=force_limit_N)


def as_signals(force_N: Any, position_m: Any, rate_hz: float | None, time_s: Any,
               memory_s: float | None, flags: Any, force_limit_N: float | None,
               axis: int | str = 2) -> Signals:
    """Checked signals from arrays, or from a RobotRecord passed as ``force_N``."""
    if isinstance(force_N, RobotRecord):
        if position_m is not None or rate_hz is not None or time_s is not None:
            raise SysidError("with a RobotRecord, do not also give position, rate or times")
        return record_signals(force_N, axis, memory_s, force_limit_N)
    if position_m is None:
        raise SysidError("position_m is required when force_N is an array")
    return check_signals(force_N, position_m, rate_hz=rate_hz, time_s=time_s, memory_s=memory_s,
                         flags=flags, force_limit_N=force_limit_N)
