"""The stable API for authors of surface profilers (``skinkit.profilers``).

Everything in ``__all__`` is public and kept stable; the engine modules it re-exports from
(:mod:`skinkit.vision.camera`, :mod:`~skinkit.vision.matching`,
:mod:`~skinkit.vision.tracking3d`, :mod:`~skinkit.vision.triangulation`,
:mod:`~skinkit.vision.subsets`) may change. Pixel coordinates are ``(x, y)`` with the origin at
the centre of the top-left pixel; world points are in metres, in the rig's frame.

Views (what a profiler needs from the rig):

- :func:`project` world points ``(N, 3)`` [m] -> pixels ``(N, 2)`` through a camera model;
- :func:`triangulate` pixels ``(N, C, 2)`` seen by any >= 2 cameras -> :class:`Triangulated`;
- :func:`camera_order` rig index of each named camera of an image sequence;
- :func:`seed_matches` SIFT correspondences between two views that obey the rig's epipolar
  geometry.

Subsets (a profiler matching patches between views): :func:`subset_origin`,
:func:`edge_reason`, :func:`ncc_integer` and :class:`IntegerMatch`, as in
:mod:`skinkit.plugin.trackers`; refuse bad input with :class:`VisionError`.

A profiler is checked with :func:`skinkit.plugin.conformance.profilers.check_profiler`.
"""

from __future__ import annotations

from skinkit.vision import VisionError
from skinkit.vision.camera import project
from skinkit.vision.matching import seed_matches
from skinkit.vision.subsets import IntegerMatch, edge_reason, ncc_integer, subset_origin
from skinkit.vision.tracking3d import camera_order
from skinkit.vision.triangulation import Triangulated, triangulate

__all__ = [
    "IntegerMatch",
    "Triangulated",
    "VisionError",
    "camera_order",
    "edge_reason",
    "ncc_integer",
    "project",
    "seed_matches",
    "subset_origin",
    "triangulate",
]
