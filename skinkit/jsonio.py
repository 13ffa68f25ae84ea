"""Strict JSON out of skinkit: every file and every ``--json`` output parses with a strict reader.

Python's :mod:`json` writes ``NaN`` and ``Infinity`` by default, which JSON does not have and
strict readers (JavaScript's ``JSON.parse``, Go, jq) refuse. Here a non-finite number is written
as ``null``; where its meaning matters the writer puts the reason in a sibling key. NumPy
scalars and arrays become plain numbers and lists.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from typing import IO, Any

import numpy as np


def plain(obj: Any, default: Callable[[Any], Any] | None = None) -> Any:
    """``obj`` as plain JSON values: dicts (string keys), lists, str, int, finite float, bool,
    None. Non-finite floats become None; NumPy scalars and arrays plain numbers and lists; any
    other object goes through ``default`` (``TypeError`` without one, as :func:`json.dumps`)."""
    if obj is None or isinstance(obj, (str, bool, int)) and not isinstance(obj, np.bool_):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {k if isinstance(k, str) else str(k): plain(v, default) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v, default) for v in obj]
    if isinstance(obj, np.ndarray):
        return plain(obj.tolist(), default)
    if isinstance(obj, np.generic):
        return plain(obj.item(), default)
    if default is None:
        raise TypeError(f"Object of type {type(obj).__name__} is not JSON serializable")
    return plain(default(obj), default)


def dumps(obj: Any, *, default: Callable[[Any], Any] | None = None, **kwargs: Any) -> str:
    """:func:`json.dumps` of :func:`plain` ``(obj)``: strict JSON (``allow_nan=False``)."""
    kwargs.pop("allow_nan", None)
    return json.dumps(plain(obj, default), allow_nan=False, **kwargs)


def dump(obj: Any, fp: IO[str], *, default: Callable[[Any], Any] | None = None, **kwargs: Any) -> None:
    """:func:`json.dump` of :func:`plain` ``(obj)`` to ``fp``: strict JSON."""
    kwargs.pop("allow_nan", None)
    json.dump(plain(obj, default), fp, allow_nan=False, **kwargs)


def loads_strict(text: str) -> Any:
    """Parse ``text`` as strict JSON: ``NaN``, ``Infinity`` and ``-Infinity`` are refused."""
    def refuse(name: str) -> Any:
        raise ValueError(f"not strict JSON: {name}")

    return json.loads(text, parse_constant=refuse)
