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

#: what :meth:`SubsetTracker.subpixel_many` returns for K points: displacements ``(K, 2)``
#: [px], qualities ``(K,)`` [1], K reasons ('' where valid) and extras (name -> ``(K, ...)``)
SubpixelBatch = tuple[np.ndarray, np.ndarray, list[str], dict[str, np.ndarray]]


class SubsetTracker:
    """Tracks each point against the reference frame (no drift between frames).

    Subclasses implement :meth:`subpixel` (one point) and may override :meth:`subpixel_many`
    (all points reaching the subpixel step at once) with a vectorised equivalent.
    ``search_px`` bounds the integer search around ``guess_px`` (per-point initial
    displacement, e.g. from a previous frame or an affine registration); ``min_quality``
    rejects matches whose correlation is below it.
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

    def subpixel_many(self, state: Any, ref: np.ndarray, cur: np.ndarray, pts: np.ndarray,
                      origins: np.ndarray, s: int, matches: list[IntegerMatch],
                      mask: np.ndarray | None) -> SubpixelBatch:
        """The subpixel step for K points at once.

        Args:
            state: what :meth:`prepare` returned.
            ref, cur: ``(H, W)`` float images.
            pts: ``(K, 2)`` points ``(x, y)`` [px].
            origins: ``(K, 2)`` int subset origins ``(c0, r0)`` [px].
            s: subset side [px].
            matches: K integer matches, each on the search window's interior and with the
                displaced subset inside ``cur``.
            mask: ``(H, W)`` bool usable pixels, or None.

        Returns:
            ``(displacement (K, 2) [px], quality (K,), K reasons ('' where valid), extras)``,
            extras mapping a name to a ``(K, ...)`` array, NaN for points without a value.

        This default calls :meth:`subpixel` point by point (the reference behaviour);
        trackers override it with a vectorised equivalent.
        """
        k = len(pts)
        disp = np.full((k, 2), np.nan)
        quality = np.full(k, np.nan)
        reasons = [""] * k
        extras: dict[str, np.ndarray] = {}
        for j in range(k):
            c0, r0 = int(origins[j, 0]), int(origins[j, 1])
            disp[j], quality[j], reasons[j], extra = self.subpixel(
                state, ref, cur, pts[j], c0, r0, s, matches[j], mask)
            for key, val in extra.items():
                arr = extras.setdefault(key, np.full((k, *np.shape(val)), np.nan))
                arr[j] = val
        return disp, quality, reasons, extras

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
        todo: list[int] = []  # points that reach the subpixel step
        origins: list[tuple[int, int]] = []
        matches: list[IntegerMatch] = []
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
            todo.append(i)
            origins.append((c0, r0))
            matches.append(match)
        if todo:
            self._store_subpixel(out, todo, self.subpixel_many(
                state, ref, cur, pts[todo], np.array(origins, dtype=int).reshape(-1, 2), s,
                matches, m))
        return out

    def _store_subpixel(self, out: TrackResult, todo: list[int], batch: SubpixelBatch) -> None:
        """Write the subpixel results of points ``todo`` into ``out``, rejecting low quality."""
        disp, quality, reasons, extras = batch
        n = len(out.valid)
        for key, vals in extras.items():
            arr = out.extra.setdefault(key, np.full((n, *np.shape(vals)[1:]), np.nan))
            arr[todo] = vals
        for j, i in enumerate(todo):
            out.quality[i] = quality[j]
            why = reasons[j]
            if not why and not quality[j] >= self.min_quality:
                why = f"correlation {quality[j]:.2f} below {self.min_quality:.2f}"
            if why:
                out.invalidate(i, why)
                continue
            out.displacement_px[i] = disp[j]
            out.valid[i] = True


def subset_stack(img: np.ndarray, cols: np.ndarray, rows: np.ndarray, s: int) -> np.ndarray:
    """``(K, s, s)`` copies of the subsets of ``img`` whose first pixel is ``(cols[k], rows[k])``.

    The subsets must lie inside ``img`` (``(H, W)``); ``cols`` and ``rows`` are ``(K,)`` ints.
    """
    ar = np.arange(s)
    r = np.asarray(rows, dtype=int)[:, None] + ar
    c = np.asarray(cols, dtype=int)[:, None] + ar
    return img[r[:, :, None], c[:, None, :]]


def solve_each(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a[k]^-1 b[k]`` for a stack ``a`` ``(K, n, n)``, ``b`` ``(K, n, m)``; NaN where ``a[k]``
    is singular (one singular matrix would otherwise fail the whole stack)."""
    try:
        return np.linalg.solve(a, b)
    except np.linalg.LinAlgError:
        pass
    b = np.broadcast_to(b, a.shape[:-2] + b.shape[-2:])
    out = np.full(b.shape, np.nan)
    for k in range(len(out)):
        try:
            out[k] = np.linalg.solve(a[k], b[k])
        except np.linalg.LinAlgError:
            continue
    return out
