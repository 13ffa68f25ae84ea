"""The vision building blocks trackers (``skinkit.trackers``) and surface profilers
(``skinkit.profilers``) are written with, gathered from the engine modules
(:mod:`skinkit.vision.subsets`, :mod:`~skinkit.vision.matching`,
:mod:`~skinkit.vision.tracking3d`, :mod:`~skinkit.vision.triangulation`,
:mod:`~skinkit.vision.camera`).

Plugins import the declared, stable API instead: :mod:`skinkit.plugin.trackers` and
:mod:`skinkit.plugin.profilers`; this engine-side module may change. Pixel coordinates
are ``(x, y)`` with the origin at the centre of the top-left pixel, ``x`` along columns; world
points are in metres.

Subsets (what every subset tracker shares):

- :class:`TrackResult` what a tracker returns for N points (``displacement_px`` ``(N, 2)``,
  ``quality``, ``valid``, ``reason``, ``isu_px``); ``TrackResult.empty(n)`` to fill in;
- :func:`check_inputs` the checks and grey conversion of ``track``'s arguments, refusing bad
  input with a :class:`VisionError`; :func:`as_gray` for one image;
- :func:`subset_origin` / :func:`subset_centre` the first pixel / centre of the subset of
  side ``S`` around a point; :func:`edge_reason` why a subset does not fit in the image
  (``""`` when it does); :func:`usable_fraction` the share of a subset a mask keeps, to compare
  with :data:`MIN_USABLE`;
- :func:`ncc_integer` the NCC integer search, returning an :class:`IntegerMatch` (shift, peak,
  integer-shift uncertainty at :data:`ISU_FRACTION` of the peak).

Views (what a profiler needs from the rig):

- :func:`project` world points ``(N, 3)`` -> pixels ``(N, 2)`` through a camera model;
- :func:`triangulate` pixels ``(N, C, 2)`` seen by any >= 2 cameras -> :class:`Triangulated`;
- :func:`camera_order` rig index of each named camera of an image sequence;
- :func:`seed_matches` SIFT correspondences between two views that obey the rig's epipolar
  geometry.
"""

from __future__ import annotations

from skinkit.vision import VisionError
from skinkit.vision.camera import project
from skinkit.vision.matching import seed_matches
from skinkit.vision.subsets import (
    ISU_FRACTION,
    MIN_USABLE,
    IntegerMatch,
    TrackResult,
    as_gray,
    check_inputs,
    edge_reason,
    ncc_integer,
    subset_centre,
    subset_origin,
    usable_fraction,
)
from skinkit.vision.tracking3d import camera_order
from skinkit.vision.triangulation import Triangulated, triangulate

__all__ = [
    "ISU_FRACTION",
    "MIN_USABLE",
    "IntegerMatch",
    "TrackResult",
    "Triangulated",
    "VisionError",
    "as_gray",
    "camera_order",
    "check_inputs",
    "edge_reason",
    "ncc_integer",
    "project",
    "seed_matches",
    "subset_centre",
    "subset_origin",
    "triangulate",
    "usable_fraction",
]
