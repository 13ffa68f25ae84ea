"""Text for terminal tables: numbers rounded to their significance, data escaped from markup.

Rich reads ``[m]`` as a style tag and drops it, so every string that comes from data (units,
names, paths) goes through :func:`text`. Numbers go through :func:`number` (one value) or
:func:`numbers` (a vector, rounded against its largest entry, so that the round-off of a
zero component prints as ``0`` and not ``-3.52e-16``); neither ever prints ``-0``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np
from rich.markup import escape

#: significant digits of a reported number unless a caller says otherwise
DIGITS = 4


def text(value: Any) -> str:
    """``str(value)`` with rich markup escaped (``[m]`` stays ``[m]``)."""
    return escape(str(value))


def number(value: Any, digits: int = DIGITS, ref: float | None = None) -> str:
    """``value`` to ``digits`` significant digits, positional between 1e-3 and 1e6.

    Args:
        value: a number (ints and bools print as they are).
        digits: significant digits.
        ref: the magnitude that sets the significance (e.g. the largest entry of the vector
            ``value`` belongs to); a value below ``ref * 10**-digits`` prints as ``0``.
            Default: the value itself.
    """
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    try:
        x = float(value)
    except (TypeError, ValueError):
        return text(value)
    if not math.isfinite(x):
        return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    scale = abs(x) if ref is None else abs(float(ref))
    if x == 0 or abs(x) < scale * 10.0 ** -digits:
        return "0"
    # round to the significant digits first: the string then shows no noise digits
    x = float(f"{x:.{digits - 1}e}")
    if 1e-3 <= abs(x) < 1e6:
        s = np.format_float_positional(x, precision=digits, unique=True, fractional=False,
                                       trim="-")
    else:
        s = np.format_float_scientific(x, precision=digits - 1, unique=True, trim="-",
                                       exp_digits=1)
    return "0" if s in ("-0", "0.", "-0.") else s


def numbers(values: Iterable[Any], digits: int = DIGITS, sep: str = ", ") -> str:
    """A vector's entries, each rounded against the largest magnitude among them."""
    vals = [float(v) for v in np.asarray(list(values), dtype=float).ravel()]
    finite = [abs(v) for v in vals if math.isfinite(v)]
    ref = max(finite, default=0.0)
    return sep.join(number(v, digits, ref) for v in vals)


def value(v: Any, digits: int = DIGITS) -> str:
    """Any metadata value: numbers and numeric sequences rounded, everything escaped."""
    if isinstance(v, (bool, int, float, np.number)):
        return number(v, digits)
    if isinstance(v, (list, tuple, np.ndarray)):
        try:
            return "[" + numbers(v, digits) + "]"
        except (TypeError, ValueError):
            return text(v)
    if isinstance(v, bytes):
        v = v.decode("utf-8", "replace")
    return text(v)
