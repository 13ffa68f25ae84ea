"""``gn``: inverse-compositional Gauss-Newton subset tracking with B-spline interpolation.

The zero-normalised sum of squared differences (ZNSSD) between the reference subset and
the current image warped by a shape function is minimised (Pan et al. 2013, IC-GN). The
current image is interpolated with cubic (or quintic) B-splines, which keeps the
interpolation bias of a well-sampled speckle far below 0.01 px. Shape functions:
``"affine"`` (translation, stretch, shear, rotation: what the phase method cannot follow)
or ``"translation"``. The NCC integer shift is the starting point.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.ndimage import map_coordinates, spline_filter

from skinkit.plugin.trackers import IntegerMatch, VisionError
from skinkit_plugins.trackers.base import SubsetTracker


def _warp_matrix(p: np.ndarray, affine: bool) -> np.ndarray:
    """3x3 homogeneous warp of local subset coordinates for parameters ``p``."""
    if affine:
        u, v, ux, uy, vx, vy = p
        return np.array([[1 + ux, uy, u], [vx, 1 + vy, v], [0, 0, 1.0]])
    return np.array([[1.0, 0, p[0]], [0, 1.0, p[1]], [0, 0, 1.0]])


class GaussNewtonTracker(SubsetTracker):
    """IC-GN with ZNSSD.

    Args:
        shape: ``"affine"`` or ``"translation"``.
        order: B-spline order for the current image (3 or 5).
        max_iter: Gauss-Newton iterations per point.
        tol_px: stop when the update moves every subset corner by less than this [px].
        search_px, min_quality: as for every subset tracker (quality is the final ZNCC).
    """

    name = "gn"

    def __init__(self, shape: str = "affine", order: int = 3, max_iter: int = 40,
                 tol_px: float = 1e-4, search_px: int = 24, min_quality: float = 0.5) -> None:
        super().__init__(search_px, min_quality)
        if shape not in ("affine", "translation"):
            raise VisionError(f"gn tracker shape must be 'affine' or 'translation', got {shape!r}")
        if order not in (3, 5):
            raise VisionError(f"gn tracker spline order must be 3 or 5, got {order}")
        self.shape = shape
        self.order = int(order)
        self.max_iter = int(max_iter)
        self.tol_px = float(tol_px)

    def prepare(self, ref: np.ndarray, cur: np.ndarray) -> Any:
        """Spline coefficients of ``cur`` and the gradients of ``ref`` (each (H, W))."""
        gy, gx = np.gradient(ref)
        return spline_filter(cur, order=self.order, mode="mirror"), gx, gy

    def subpixel(self, state: Any, ref: np.ndarray, cur: np.ndarray, p: np.ndarray,
                 c0: int, r0: int, s: int, match: IntegerMatch,
                 mask: np.ndarray | None) -> tuple[np.ndarray, float, str, dict[str, Any]]:
        """Gauss-Newton step: (displacement of ``p`` (2,) [px], correlation quality, reason or '', extras)."""
        coef, gx_all, gy_all = state
        affine = self.shape == "affine"
        centre = np.array([c0 + (s - 1) / 2, r0 + (s - 1) / 2])
        xi = np.arange(s) - (s - 1) / 2
        ex, ey = np.meshgrid(xi, xi)
        sel = np.ones((s, s), bool) if mask is None else mask[r0:r0 + s, c0:c0 + s]
        ex, ey = ex[sel], ey[sel]
        f = ref[r0:r0 + s, c0:c0 + s][sel]
        gx = gx_all[r0:r0 + s, c0:c0 + s][sel]
        gy = gy_all[r0:r0 + s, c0:c0 + s][sel]
        fm = f.mean()
        df = np.sqrt(np.sum((f - fm) ** 2))
        if df == 0:
            return np.full(2, np.nan), 0.0, "reference subset has no texture", {}
        if affine:
            J = np.stack([gx, gy, gx * ex, gx * ey, gy * ex, gy * ey], axis=1)
            prm = np.array([match.shift[0], match.shift[1], 0, 0, 0, 0], dtype=float)
        else:
            J = np.stack([gx, gy], axis=1)
            prm = np.array(match.shift, dtype=float)
        H = J.T @ J
        try:
            Hinv = np.linalg.inv(H)
        except np.linalg.LinAlgError:
            return np.full(2, np.nan), 0.0, "reference subset gradient is degenerate", {}
        M = _warp_matrix(prm, affine)
        half = (s - 1) / 2
        h, w = cur.shape
        converged = False
        znssd = np.nan
        for _ in range(self.max_iter):
            wx = M[0, 0] * ex + M[0, 1] * ey + M[0, 2] + centre[0]
            wy = M[1, 0] * ex + M[1, 1] * ey + M[1, 2] + centre[1]
            if wx.min() < 0 or wy.min() < 0 or wx.max() > w - 1 or wy.max() > h - 1:
                why = "displaced subset leaves the current image"
                return np.full(2, np.nan), float(match.peak), why, {}
            g = map_coordinates(coef, [wy, wx], order=self.order, prefilter=False, mode="mirror")
            gm = g.mean()
            dg = np.sqrt(np.sum((g - gm) ** 2))
            if dg == 0:
                return np.full(2, np.nan), 0.0, "current subset has no texture", {}
            r = (f - fm) - (df / dg) * (g - gm)
            znssd = float(np.sum(r**2) / df**2)
            dp = -Hinv @ (J.T @ r)
            M = M @ np.linalg.inv(_warp_matrix(dp, affine))
            move = np.hypot(dp[0], dp[1])
            if affine:
                move += half * np.sqrt(np.sum(dp[2:] ** 2))
            if move < self.tol_px:
                converged = True
                break
        quality = 1.0 - znssd / 2.0
        if not converged:
            why = f"Gauss-Newton did not converge in {self.max_iter} iterations"
            return np.full(2, np.nan), quality, why, {}
        loc = p - centre
        moved = M[:2, :2] @ loc + M[:2, 2]
        extra = {"gradient": M[:2, :2] - np.eye(2)} if affine else {}
        return moved - loc, quality, "", extra


class TranslationGaussNewtonTracker(GaussNewtonTracker):
    """``gn-translation``: the same IC-GN with a pure-translation shape function."""

    name = "gn-translation"

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("shape", "translation")
        super().__init__(**kwargs)
