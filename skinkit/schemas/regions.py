"""Regions of the tracked surface: named partitions of the points' reference positions.

A model's geometry says which regions of the surface matter (around a probe: distance and
direction from it; between two pads: bands along the pull, the skin beside and behind the pads).
It says so as :class:`RegionPartition` records, one label per reference point, which the gap
diagnosis's ``region`` axis tests cell by cell (:mod:`skinkit.gap.where`) without knowing the
geometry. A *region provider* is any callable ``points (P, 2) [m] -> [RegionPartition, ...]``
(skin frame: x, y in the surface plane) whose partitions each label all P points.

:func:`polar_partitions` are the partitions around a centre (radial bands and angular sectors),
what a probe geometry supplies and what the diagnosis uses when no provider is given.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from skinkit.errors import SchemaError

#: points (P, 2) [m] -> the partitions of those points
RegionProvider = Callable[[np.ndarray], Sequence["RegionPartition"]]


@dataclass(frozen=True)
class RegionPartition:
    """One named partition of the tracked surface into regions.

    ``name``: the partition (the gap report's ``partition`` of its cells, e.g. ``"sector"``);
    ``cells``: the regions' labels in the order they are reported (unique, non-empty);
    ``labels``: ``(P,)`` per reference point the label of its region, one of ``cells``, or None
    for a point in no region of this partition. Checked on construction: a bad record raises
    :class:`SchemaError` naming ``regions.<name>``.
    """

    name: str
    cells: tuple[str, ...]
    labels: tuple[str | None, ...]

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise SchemaError("regions", f"a partition needs a non-empty name, got {self.name!r}")
        where = f"regions.{self.name}"
        object.__setattr__(self, "cells", tuple(self.cells))
        object.__setattr__(self, "labels", tuple(self.labels))
        if not all(isinstance(c, str) and c for c in self.cells):
            raise SchemaError(where, f"cell labels must be non-empty strings, got {list(self.cells)}")
        if len(set(self.cells)) != len(self.cells):
            raise SchemaError(where, f"cell labels must be unique, got {list(self.cells)}")
        known = set(self.cells)
        bad = sorted({str(lab) for lab in self.labels if lab is not None and lab not in known})
        if bad:
            raise SchemaError(where, f"labels points with {bad[:3]}, which are not among its cells "
                              f"{list(self.cells)}")

    @classmethod
    def from_codes(cls, name: str, cells: Sequence[str], code: np.ndarray) -> RegionPartition:
        """The partition whose point i lies in ``cells[code[i]]`` (in none where ``code[i]`` is −1);
        ``code`` ``(P,)`` int."""
        cells = tuple(cells)
        return cls(name, cells, tuple(None if c < 0 else cells[c] for c in np.asarray(code, dtype=int)))

    def codes(self, n_points: int) -> np.ndarray:
        """``(P,)`` int: per point the index of its cell in ``cells``, −1 for none. Raises
        :class:`SchemaError` when the partition does not label exactly ``n_points`` points."""
        if len(self.labels) != n_points:
            raise SchemaError(f"regions.{self.name}",
                              f"labels {len(self.labels)} points, but the tracked surface has "
                              f"{n_points} reference points: a partition labels every point given to it")
        index = {c: i for i, c in enumerate(self.cells)}
        return np.array([-1 if lab is None else index[lab] for lab in self.labels], dtype=int)


def polar_partitions(points: np.ndarray, centre: Sequence[float] = (0.0, 0.0), radial_bands: int = 4,
                     sectors: int = 12) -> list[RegionPartition]:
    """Radial bands (``radius``) and angular sectors (``sector``) of ``points`` ``(P, 2)`` [m]
    around ``centre`` ``(x, y)`` [m]; [] when no point has a finite position.

    Bands: ``radial_bands`` of equal width between the nearest and the farthest point, edges
    rounded to 0.1 mm (``"r 1.5-2.9 mm"``). Sectors: ``sectors`` of 360/``sectors`` degrees
    counter-clockwise from +x (``"sector 30-60 deg"``); a point on a sector's edge goes to the
    sector above, a point at the centre to none.
    """
    ref = np.asarray(points, dtype=float).reshape(-1, 2) - np.asarray(centre, dtype=float)[:2]
    r = np.hypot(ref[:, 0], ref[:, 1])
    onpts = np.isfinite(r)
    if not onpts.any():
        return []
    # bands of equal width between the nearest and farthest point, edges on 0.1 mm (readable
    # labels; quantile edges would cut through the rings a regular layout puts points on)
    lo, hi = float(r[onpts].min()), float(r[onpts].max())
    edges = np.unique(np.round(np.linspace(lo, hi, radial_bands + 1), 4))
    edges[0], edges[-1] = min(edges[0], lo), max(edges[-1], hi)
    nb = max(edges.size - 1, 1)
    code = np.full(r.size, -1)
    code[onpts] = np.clip(np.searchsorted(edges, r[onpts] + 1e-10, side="right") - 1, 0, nb - 1)
    top = edges.size - 1
    labels = [f"r {1e3 * edges[i]:.1f}-{1e3 * edges[min(i + 1, top)]:.1f} mm" for i in range(nb)]
    parts = [RegionPartition.from_codes("radius", labels, code)]
    width = 360.0 / sectors
    # points on a sector's edge (grids put many there) go to the sector above, consistently
    ang = (np.degrees(np.arctan2(ref[:, 1], ref[:, 0])) + 1e-7) % 360.0
    sector = np.floor(np.nan_to_num(ang) / width).astype(int) % sectors
    code = np.where(onpts & (r > 1e-9), sector, -1)
    labels = [f"sector {i * width:g}-{(i + 1) * width:g} deg" for i in range(sectors)]
    parts.append(RegionPartition.from_codes("sector", labels, code))
    return parts


__all__ = ["RegionPartition", "RegionProvider", "polar_partitions"]
