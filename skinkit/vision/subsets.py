"""Subset bookkeeping shared by trackers: input checks, validity, NCC integer search, ISU.

A subset of side ``S`` around point ``(x, y)`` is the ``S x S`` block of pixels whose first
column is ``round(x) - S // 2`` (and likewise for rows); its centre is at
``round(x) - S // 2 + (S - 1) / 2``. Pixel coordinates have their origin at the centre of the
top-left pixel, ``x`` along columns.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from skinkit.vision import VisionError

#: fraction of the NCC peak that defines the integer-shift uncertainty (thesis 5.4)
ISU_FRACTION = 0.85
#: fraction of a subset that must be usable (mask) for a point to be tracked
MIN_USABLE = 0.75


@dataclass
class TrackResult:
    """What a tracker returns for N points.

    Attributes:
        displacement_px: ``(N, 2)`` displacement ``(dx, dy)`` of each point [px]; NaN if invalid.
        quality: ``(N,)`` correlation quality in [-1, 1] (peak NCC or final ZNCC) [1].
        valid: ``(N,)`` bool.
        reason: N strings, empty where valid, else why not.
        isu_px: ``(N,)`` integer-shift uncertainty: pixels of the NCC map within 85 % of its
            peak (thesis 5.4) [px]; NaN where not computed.
        extra: tracker-specific per-point arrays (e.g. ``"affine"`` ``(N, 2, 2)``).
    """

    displacement_px: np.ndarray
    quality: np.ndarray
    valid: np.ndarray
    reason: list[str]
    isu_px: np.ndarray
    extra: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def empty(cls, n: int) -> TrackResult:
        """All points invalid with NaN outputs, to be filled in."""
        return cls(np.full((n, 2), np.nan), np.full(n, np.nan), np.zeros(n, bool), [""] * n,
                   np.full(n, np.nan))

    def invalidate(self, i: int, why: str) -> None:
        """Mark point ``i`` invalid with reason ``why`` (its displacement NaN)."""
        self.valid[i] = False
        self.displacement_px[i] = np.nan
        self.reason[i] = why


def as_gray(image: Any, name: str) -> np.ndarray:
    """A ``(H, W)`` float64 copy of a grey image, refusing anything else with a clear message."""
    arr = np.asarray(image)
    if arr.ndim != 2:
        raise VisionError(f"{name}: expected a (H, W) grey image, got shape {arr.shape}")
    if arr.dtype.kind not in "uif":
        raise VisionError(f"{name}: pixel type {arr.dtype} is not numeric")
    out = arr.astype(np.float64)
    if not np.all(np.isfinite(out)):
        raise VisionError(f"{name}: holds NaN or infinite pixels")
    return out


def check_inputs(reference: Any, current: Any, points: Any, subset_px: int,
                 mask: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Validate tracker inputs; returns float images, ``(N, 2)`` points and the bool mask."""
    ref = as_gray(reference, "reference image")
    cur = as_gray(current, "current image")
    if ref.shape != cur.shape:
        raise VisionError(f"image sizes differ: reference {ref.shape[1]}x{ref.shape[0]}, "
                          f"current {cur.shape[1]}x{cur.shape[0]} (width x height)")
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise VisionError(f"points: expected an (N, 2) array of (x, y) pixels, got shape {pts.shape}")
    if int(subset_px) != subset_px or subset_px < 8:
        raise VisionError(f"subset_px must be an integer >= 8, got {subset_px}")
    m = None
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != ref.shape:
            raise VisionError(f"mask shape {m.shape} differs from the image shape {ref.shape}")
        m = m.astype(bool)
    return ref, cur, pts, m


def subset_origin(p: np.ndarray, subset_px: int) -> tuple[int, int]:
    """Top-left pixel ``(col, row)`` of the subset around point ``p`` ``(x, y)``."""
    return int(np.rint(p[0])) - subset_px // 2, int(np.rint(p[1])) - subset_px // 2


def subset_centre(p: np.ndarray, subset_px: int) -> np.ndarray:
    """``(2,)`` pixel coordinates of the subset centre for point ``p``."""
    c0, r0 = subset_origin(p, subset_px)
    return np.array([c0 + (subset_px - 1) / 2, r0 + (subset_px - 1) / 2])


def edge_reason(p: np.ndarray, shape_hw: tuple[int, int], subset_px: int, margin: int = 0) -> str:
    """Why a subset around ``p`` cannot be used in an image of this shape ('' if it can)."""
    h, w = shape_hw
    if not np.all(np.isfinite(p)):
        return "point coordinates are not finite"
    if p[0] < -0.5 or p[1] < -0.5 or p[0] > w - 0.5 or p[1] > h - 0.5:
        return f"point ({p[0]:.1f}, {p[1]:.1f}) is outside the {w}x{h} image"
    c0, r0 = subset_origin(p, subset_px)
    if c0 - margin < 0 or r0 - margin < 0 or c0 + subset_px + margin > w or r0 + subset_px + margin > h:
        return (f"point ({p[0]:.1f}, {p[1]:.1f}) is too close to the image edge for a "
                f"{subset_px}-px subset (needs {subset_px // 2 + margin} px of margin)")
    return ""


@dataclass
class IntegerMatch:
    """Result of the NCC integer search for one subset."""

    shift: np.ndarray  # (2,) integer (dx, dy) [px]
    peak: float  # peak NCC [1]
    isu_px: float  # pixels within ISU_FRACTION of the peak [px]
    on_border: bool  # peak on the border of the search window (shift may exceed the window)


def ncc_integer(ref: np.ndarray, cur: np.ndarray, c0: int, r0: int, subset_px: int,
                search_px: int, guess: tuple[int, int] = (0, 0)) -> IntegerMatch | None:
    """Integer shift of the subset at ``(c0, r0)`` by normalised cross-correlation.

    The current image is searched within ``+-search_px`` of ``guess``; the window is clipped to
    the image. Returns None when no shift fits in the image.
    """
    h, w = cur.shape
    s = subset_px
    tmpl = ref[r0:r0 + s, c0:c0 + s].astype(np.float32)
    x_lo = max(0, c0 + guess[0] - search_px)
    y_lo = max(0, r0 + guess[1] - search_px)
    x_hi = min(w, c0 + guess[0] + search_px + s)
    y_hi = min(h, r0 + guess[1] + search_px + s)
    if x_hi - x_lo < s or y_hi - y_lo < s:
        return None
    if float(np.std(tmpl)) == 0.0:
        return IntegerMatch(np.zeros(2, int), 0.0, float("inf"), False)
    region = cur[y_lo:y_hi, x_lo:x_hi].astype(np.float32)
    score = cv2.matchTemplate(region, tmpl, cv2.TM_CCOEFF_NORMED)
    score = np.nan_to_num(score, nan=-1.0)
    iy, ix = np.unravel_index(int(np.argmax(score)), score.shape)
    peak = float(score[iy, ix])
    isu = float(np.count_nonzero(score >= ISU_FRACTION * peak)) if peak > 0 else float("inf")
    border = (ix == 0 and x_lo > 0) or (iy == 0 and y_lo > 0) or \
        (ix == score.shape[1] - 1 and x_hi < w) or (iy == score.shape[0] - 1 and y_hi < h)
    shift = np.array([x_lo + ix - c0, y_lo + iy - r0], dtype=int)
    return IntegerMatch(shift, peak, isu, bool(border))


def usable_fraction(mask: np.ndarray | None, c0: int, r0: int, subset_px: int) -> float:
    """Fraction of the subset at ``(c0, r0)`` that the mask marks usable (1 without a mask)."""
    if mask is None:
        return 1.0
    return float(np.mean(mask[r0:r0 + subset_px, c0:c0 + subset_px]))
