"""The conformance kit for robot drivers (``skinkit.drivers``): the stable API a driver author
checks a driver's declarations with, without connecting to anything.

:func:`check_driver` ``(driver)`` -> :class:`~skinkit.plugin.conformance.report.Report`:

- ``interface``: the members of :class:`skinkit.interfaces.Driver` and a name;
- ``wire cost``: ``wire_bits_per_sample``, when declared, a positive finite number [bit];
- ``line rate option``: ``line_rate_option``, when declared, a keyword ``connect`` accepts;
- ``emergency stop``: ``emergency_stop`` takes no argument (it is called from any thread, as is).
"""

from __future__ import annotations

import inspect
import math
from typing import Any

from skinkit import registry
from skinkit.interfaces import Driver, missing_members
from skinkit.plugin.conformance.report import Report


def _accepts(fn: Any, keyword: str) -> bool:
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return True  # a builtin or C callable: nothing to say
    return any(p.kind is p.VAR_KEYWORD or (p.name == keyword and p.kind is not p.POSITIONAL_ONLY)
               for p in params)


def check_driver(driver: Any) -> Report:
    """Check ``driver`` (a plugin object or the name of an installed one); see the module."""
    drv = registry.create("skinkit.drivers", driver) if isinstance(driver, str) else driver
    if isinstance(drv, type):
        drv = drv()
    report = Report("driver", str(getattr(drv, "name", "?")))
    missing = missing_members(drv, Driver)
    if not report.add("interface", not missing, f"missing {', '.join(missing)}" if missing else ""):
        return report
    bits = getattr(drv, "wire_bits_per_sample", None)
    if bits is not None:
        number = isinstance(bits, (int, float)) and not isinstance(bits, bool)
        ok = number and math.isfinite(bits) and bits > 0
        report.add("wire cost", ok, f"wire_bits_per_sample = {bits!r}")
    option = getattr(drv, "line_rate_option", None)
    if option is not None:
        ok = isinstance(option, str) and _accepts(drv.connect, option)
        report.add("line rate option", ok, f"line_rate_option = {option!r}")
    try:
        required = [p for p in inspect.signature(drv.emergency_stop).parameters.values()
                    if p.default is p.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    except (TypeError, ValueError):
        required = []
    report.add("emergency stop", not required,
               f"needs {', '.join(p.name for p in required)}" if required else "")
    return report


__all__ = ["check_driver"]
