"""The stable API for authors of 2D subset trackers (``skinkit.trackers``).

Everything in ``__all__`` is public and kept stable; the engine modules it re-exports from
(:mod:`skinkit.vision.subsets`) may change. Pixel coordinates are ``(x, y)`` with the origin at
the centre of the top-left pixel, ``x`` along columns.

- :class:`TrackResult` what a tracker returns for N points (``displacement_px`` ``(N, 2)``,
  ``quality`` ``(N,)``, ``valid`` ``(N,)``, ``reason`` one string per point, ``isu_px``);
  ``TrackResult.empty(n)`` to fill in;
- :func:`check_inputs` the checks and grey conversion of ``track``'s arguments, refusing bad
  input with a :class:`VisionError`; :func:`as_gray` for one image;
- :func:`subset_origin` / :func:`subset_centre` the first pixel / centre of the subset of
  side ``S`` around a point; :func:`edge_reason` why a subset does not fit in the image
  (``""`` when it does); :func:`usable_fraction` the share of a subset a mask keeps, to compare
  with :data:`MIN_USABLE`;
- :func:`ncc_integer` the NCC integer search, returning an :class:`IntegerMatch` (shift, peak,
  integer-shift uncertainty at :data:`ISU_FRACTION` of the peak).

A tracker is checked with :func:`skinkit.plugin.conformance.trackers.check_tracker`.
"""

from __future__ import annotations

from skinkit.vision import VisionError
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

__all__ = [
    "ISU_FRACTION",
    "MIN_USABLE",
    "IntegerMatch",
    "TrackResult",
    "VisionError",
    "as_gray",
    "check_inputs",
    "edge_reason",
    "ncc_integer",
    "subset_centre",
    "subset_origin",
    "usable_fraction",
]
