"""Where a map drawn through tracked points may be filled: the triangles of a triangulation
through the points that lie among them, not across a gap where there are none.

A triangulation through points tracked around a probe spans the probe's footprint (no skin is
seen there) and any other hole or concave bay of the point set; colouring those triangles would
show an interpolated residual where nothing was measured. :func:`hole_triangles` marks them:

* a triangle with an edge longer than :data:`EDGE_FACTOR` times the typical spacing of the
  points (the median distance from a point to its nearest neighbour) bridges a gap;
* when the points surround the origin (the probe's axis in the skin frame), a triangle whose
  centroid lies nearer the origin than the innermost point is inside the footprint.
"""

from __future__ import annotations

import numpy as np

#: an edge this many times the points' typical spacing bridges a gap with no point
EDGE_FACTOR = 2.5


def spacing(xy: np.ndarray) -> float:
    """Median distance [unit of ``xy``] from each of the ``(P, 2)`` points to its nearest other
    point (0 for fewer than two points)."""
    xy = np.asarray(xy, float)
    if len(xy) < 2:
        return 0.0
    d = np.linalg.norm(xy[:, None, :] - xy[None, :, :], axis=-1)   # P is at most a few thousand
    np.fill_diagonal(d, np.inf)
    return float(np.median(d.min(axis=1)))


def surrounds_origin(xy: np.ndarray) -> bool:
    """Whether the ``(P, 2)`` points lie all around the origin: no angular gap of half a turn or
    more between neighbouring directions, seen from it."""
    xy = np.asarray(xy, float)
    r = np.linalg.norm(xy, axis=1)
    a = np.sort(np.arctan2(xy[r > 0, 1], xy[r > 0, 0]))
    if a.size < 3:
        return False
    gaps = np.diff(np.concatenate([a, a[:1] + 2 * np.pi]))
    return bool(gaps.max() < np.pi)


def hole_triangles(xy: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: True for each of the ``(n, 3)`` vertex-index ``triangles`` through the
    ``(P, 2)`` points ``xy`` that spans a gap with no point (module docstring)."""
    xy = np.asarray(xy, float)
    tri = np.asarray(triangles, int)
    if tri.size == 0:
        return np.zeros(0, bool)
    v = xy[tri]                                                       # (n, 3, 2)
    edges = np.linalg.norm(v - np.roll(v, 1, axis=1), axis=-1).max(axis=1)
    h = spacing(xy)
    out = edges > EDGE_FACTOR * h if h > 0 else np.zeros(len(tri), bool)
    if surrounds_origin(xy):
        inner = float(np.linalg.norm(xy, axis=1).min())
        out |= np.linalg.norm(v.mean(axis=1), axis=1) < inner
    return out


__all__ = ["EDGE_FACTOR", "hole_triangles", "spacing", "surrounds_origin"]
