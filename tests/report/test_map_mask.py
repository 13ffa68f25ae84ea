"""Residual maps are filled only among the tracked points: the triangles a triangulation lays
across the probe's footprint (no points there) or across a gap are masked."""

from __future__ import annotations

import numpy as np
from matplotlib.tri import Triangulation

from skinkit.inverse.map_mask import hole_triangles, surrounds_origin


def _ring(inner: float = 4.0, outer: float = 10.0, step: float = 1.0) -> np.ndarray:
    """Points on a 1 mm grid between two radii [mm] around the origin (the probe's axis)."""
    g = np.arange(-outer, outer + step / 2, step)
    xy = np.array([(x, y) for x in g for y in g])
    r = np.linalg.norm(xy, axis=1)
    return xy[(r >= inner) & (r <= outer)]


def test_the_footprint_is_not_filled():
    xy = _ring()
    tri = Triangulation(xy[:, 0], xy[:, 1])
    hole = hole_triangles(xy, tri.triangles)
    centroids = xy[tri.triangles].mean(axis=1)
    inside = np.linalg.norm(centroids, axis=1) < 3.5
    assert inside.any() and hole[inside].all()          # every triangle over the probe: masked
    kept = centroids[~hole]
    assert np.linalg.norm(kept, axis=1).min() > 3.5     # what is kept lies among the points
    assert (~hole).sum() > 0.8 * len(xy)                # the ring itself stays filled


def _areas(xy: np.ndarray, tris: np.ndarray) -> np.ndarray:
    a, b, c = (xy[tris[:, k]] for k in range(3))
    u, v = b - a, c - a
    return 0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])


def test_a_full_grid_keeps_its_area():
    g = np.arange(-5.0, 5.5, 1.0)
    xy = np.array([(x, y) for x in g for y in g])
    xy[:, 0] += 1e-3 * np.sin(7 * xy[:, 1])   # a regular grid's Delaunay triangulation is not unique
    tri = Triangulation(xy[:, 0], xy[:, 1])
    hole = hole_triangles(xy, tri.triangles)
    area = _areas(xy, tri.triangles)
    # at most the slivers along the hull's straight edges are left out, never an area
    assert area[hole].sum() < 1e-3 * area.sum()


def test_points_to_one_side_do_not_surround_the_origin():
    xy = _ring() + [30.0, 0.0]
    assert not surrounds_origin(xy)
    assert surrounds_origin(_ring())
