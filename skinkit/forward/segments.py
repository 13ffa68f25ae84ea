"""Splitting a session's records into segments (placeholder: filled in by the segments work)."""

from __future__ import annotations

from skinkit.errors import SchemaError
from skinkit.schemas import Observations


def split(observations: Observations, how: str) -> Observations:
    """``observations`` with every protocol split into segments ``how`` (``"cycles"``)."""
    raise SchemaError("--segments", f"{how!r} is not implemented yet")
