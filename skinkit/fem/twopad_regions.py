"""Regions of the two-pad extension geometry's surface (:mod:`skinkit.fem.twopad`).

Pulling one glued pad away from a fixed one loads the skin unevenly: nearly uniaxially between
the pads, in shear beside them, in compression and lateral spread behind the moving pad, barely
behind the fixed one, and with a stress concentration at every glued edge. A model that misses
one of these (anisotropy across the pull, a compliant bond, a layer that slides) misses it in
its own region, so the gap diagnosis tests these regions of the tracked surface as the
``twopad`` partition of its ``region`` axis (:class:`skinkit.schemas.regions.RegionPartition`).

Frame as the geometry's: x along the pull, y across it in the surface plane, origin midway
between the pads; the fixed pad spans x in ``[-(gap/2 + pad), -gap/2]``, the moving pad
``[gap/2, gap/2 + pad]``, both y in ``[-pad/2, pad/2]``.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import partial
from typing import Any

import numpy as np

from skinkit.fem.errors import ModelError
from skinkit.fem.twopad import GAP, PAD_SIZE
from skinkit.schemas.regions import RegionPartition, RegionProvider, polar_partitions

#: bands of equal width along the pull between the pads
BANDS = 4
#: width of the pad-edge region as a fraction of the pad's side: 2 mm for 8 mm pads, of the order
#: of the skin layer's thickness, over which a glued edge's stress concentration decays
EDGE_FRACTION = 0.25

BESIDE_PLUS, BESIDE_MINUS = "beside +y", "beside -y"
BEHIND_MOVING, BEHIND_FIXED, PAD_EDGES = "behind moving pad", "behind fixed pad", "pad edges"


def twopad_partition(points: np.ndarray, pad_size: float = PAD_SIZE, gap: float = GAP, bands: int = BANDS,
                     edge: float | None = None) -> RegionPartition:
    """The ``twopad`` partition of ``points`` ``(P, 2)`` [m] (x along the pull, y across).

    Cells, in this order: ``between pads k/n (x a to b mm)`` — ``bands`` bands of equal width
    along x between the pads' facing edges less the edge regions, band 1 nearest the fixed pad;
    ``beside +y`` and ``beside -y`` — across the pull from the pads' band (|y| > pad/2) within
    the pads' span along x; ``behind moving pad`` (x beyond its outer edge, any y),
    ``behind fixed pad`` (likewise at −x); ``pad edges`` — on a pad or within ``edge`` [m] of its
    outline (default :data:`EDGE_FRACTION` of ``pad_size``), which takes precedence. A point
    without a finite position is in no cell. ``pad_size``, ``gap`` [m]: as the model's geometry.
    """
    a, g = float(pad_size), float(gap)
    d = EDGE_FRACTION * a if edge is None else float(edge)
    if not (a > 0 and g > 0 and d >= 0):
        raise ModelError("geometry", f"two-pad regions need pad_size and gap > 0 and edge >= 0 [m], "
                         f"got {a}, {g}, {d}")
    if int(bands) != bands or bands < 1:
        raise ModelError("regions.bands", f"must be a whole number at least 1, got {bands!r}")
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    x, y = pts[:, 0], pts[:, 1]
    fin = np.isfinite(x) & np.isfinite(y)
    h, e = 0.5 * g, 0.5 * g + a                   # facing and outer edges' |x|
    c = 0.5 * (h + e)                              # pad centres' |x|
    with np.errstate(invalid="ignore"):
        # distance to the nearer pad's square footprint (0 inside it)
        dy = np.maximum(np.abs(y) - 0.5 * a, 0.0)
        dx = np.maximum(np.abs(np.abs(x) - c) - 0.5 * a, 0.0)
        near = fin & (np.hypot(dx, dy) <= d)
        free = fin & ~near
        # between the pads, what the edge regions leave: the bands share it (none when they
        # cover the whole gap)
        lo, hi = -h + d, h - d
        n = int(bands) if hi > lo else 0
        edges = np.linspace(lo, hi, n + 1)
        cells = [f"between pads {k + 1}/{n} (x {1e3 * edges[k]:.1f} to {1e3 * edges[k + 1]:.1f} mm)"
                 for k in range(n)]
        cells += [BESIDE_PLUS, BESIDE_MINUS, BEHIND_MOVING, BEHIND_FIXED, PAD_EDGES]
        code = np.full(x.size, -1)
        between = free & (np.abs(y) <= 0.5 * a) & (np.abs(x) < h)
        if n:
            # a point on a band's edge goes to the band above, as on a radial band's
            code[between] = np.clip(np.searchsorted(edges, x[between], side="right") - 1, 0, n - 1)
        beside = free & (np.abs(y) > 0.5 * a) & (np.abs(x) <= e)
        code[beside & (y > 0)] = n
        code[beside & (y < 0)] = n + 1
        code[free & (x > e)] = n + 2
        code[free & (x < -e)] = n + 3
        code[near] = n + 4
    return RegionPartition.from_codes("twopad", cells, code)


def twopad_partitions(points: np.ndarray, pad_size: float = PAD_SIZE,
                      gap: float = GAP) -> list[RegionPartition]:
    """Every region partition of the two-pad surface ``points`` ``(P, 2)`` [m]: the radial bands
    and sectors around the midpoint between the pads, which every gap report has had, and
    ``twopad`` (:func:`twopad_partition`)."""
    return [*polar_partitions(points), twopad_partition(points, pad_size, gap)]


def twopad_regions(geometry: Mapping[str, Any]) -> RegionProvider:
    """The region provider of a ``[geometry] kind = "twopad"`` table: its ``pad_size`` and
    ``gap`` (defaults as :func:`skinkit.fem.twopad.twopad_from_spec`); a bad value raises
    :class:`ModelError` naming ``geometry.<key>``."""
    from skinkit.fem.values import quantity

    a = quantity(geometry.get("pad_size", PAD_SIZE), "m", "geometry.pad_size")
    return partial(twopad_partitions, pad_size=a, gap=quantity(geometry.get("gap", GAP), "m", "geometry.gap"))
