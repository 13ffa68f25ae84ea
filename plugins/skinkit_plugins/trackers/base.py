"""The loop every subset tracker shares: checks, NCC integer search, then a subpixel step."""

from __future__ import annotations

from typing import Any

import numpy as np

from skinkit.plugin.trackers import (
    MIN_USABLE,
    IntegerMatch,
    TrackResult,
    check_inputs,
    edge_reason,
    ncc_integer,
    subset_origin,
    usable_fraction,
)


class SubsetTracker:
    """Tracks each point against the reference frame (no drift between frames).

    Subclasses implement :meth:`subpixel`. ``search_px`` bounds the integer search around
    ``guess_px`` (per-point initial displacement, e.g. from a previous frame or an affine
    registration); ``min_quality`` rejects matches whose correlation is below it.
    """

    name = "subset"

    def __init__(self, search_px: int = 24, min_quality: float = 0.5) -> None:
        self.search_px = int(search_px)
        self.min_quality = float(min_quality)

    def prepare(self, ref: np.ndarray, cur: np.ndarray) -> Any:
        """Per image-pair precomputation (e.g. spline coefficients)."""
        return None

    def subpixel(self, state: Any, ref: np.ndarray, cur: np.ndarray, p: np.ndarray,
                 c0: int, r0: int, s: int, match: IntegerMatch,
                 mask: np.ndarray | None) -> tuple[np.ndarray, float, str, dict[str, Any]]:
        """Return (displacement of ``p`` [px], quality, reason or '', extras)."""
        raise NotImplementedError

    def track(self, reference: np.ndarray, current: np.ndarray, points: np.ndarray,
              subset_px: int = 64, mask: np.ndarray | None = None,
              guess_px: np.ndarray | None = None) -> TrackResult:
        """Displacements of ``points`` ``(N, 2)`` [px] from ``reference`` to ``current``."""
        ref, cur, pts, m = check_inputs(reference, current, points, subset_px, mask)
        s = int(subset_px)
        n = len(pts)
        out = TrackResult.empty(n)
        guesses = np.zeros((n, 2)) if guess_px is None else np.asarray(guess_px, dtype=float)
        state = self.prepare(ref, cur) if n else None
        for i, p in enumerate(pts):
            why = edge_reason(p, ref.shape, s)
            if why:
                out.invalidate(i, why)
                continue
            c0, r0 = subset_origin(p, s)
            if usable_fraction(m, c0, r0, s) < MIN_USABLE:
                out.invalidate(i, f"subset is less than {MIN_USABLE:.0%} usable under the mask")
                continue
            g = guesses[i]
            if not np.all(np.isfinite(g)):
                out.invalidate(i, "initial guess is not finite")
                continue
            match = ncc_integer(ref, cur, c0, r0, s, self.search_px,
                                (int(np.rint(g[0])), int(np.rint(g[1]))))
            if match is None:
                out.invalidate(i, "search window lies outside the current image")
                continue
            out.isu_px[i] = match.isu_px
            out.quality[i] = match.peak
            if match.on_border:
                out.invalidate(i, f"NCC peak on the border of the +-{self.search_px}-px search window")
                continue
            sx, sy = int(match.shift[0]), int(match.shift[1])
            h, w = cur.shape
            if c0 + sx < 0 or r0 + sy < 0 or c0 + sx + s > w or r0 + sy + s > h:
                out.invalidate(i, "displaced subset leaves the current image")
                continue
            disp, quality, why, extra = self.subpixel(state, ref, cur, p, c0, r0, s, match, m)
            out.quality[i] = quality
            for key, val in extra.items():
                arr = out.extra.setdefault(key, np.full((n, *np.shape(val)), np.nan))
                arr[i] = val
            if not why and not quality >= self.min_quality:
                why = f"correlation {quality:.2f} below {self.min_quality:.2f}"
            if why:
                out.invalidate(i, why)
                continue
            out.displacement_px[i] = disp
            out.valid[i] = True
        return out
