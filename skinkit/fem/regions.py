"""The regions of a finite-element model's tracked surface, from its ``[geometry]`` table.

Each geometry names the regions where its loading differs (:mod:`skinkit.schemas.regions`):
a probe geometry (``disc``, ``block``: the probe's contact point at the origin) the radial bands
and angular sectors around the probe; the two-pad geometry these and its own ``twopad``
partition (:mod:`skinkit.fem.twopad_regions`). The gap diagnosis tests them without knowing the
geometry.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from skinkit.fem.errors import ModelError
from skinkit.schemas.regions import RegionProvider, polar_partitions


def region_partitions(spec: Mapping[str, Any]) -> RegionProvider:
    """The region provider of the model description ``spec`` (``points (P, 2) [m] -> partitions``,
    skin frame); a bad ``[geometry]`` raises :class:`ModelError` naming the entry."""
    g = spec.get("geometry") or {}
    if not isinstance(g, Mapping):
        raise ModelError("geometry", f"must be a table, got {type(g).__name__}")
    kind = g.get("kind", "disc")
    if kind == "twopad":
        from skinkit.fem.twopad_regions import twopad_regions

        return twopad_regions(g)
    if kind in ("disc", "block"):
        return polar_partitions          # around the origin: the probe's contact point
    raise ModelError("geometry.kind", f"must be 'disc', 'block' or 'twopad', got {kind!r}")
