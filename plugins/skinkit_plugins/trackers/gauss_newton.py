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
from skinkit_plugins.trackers.base import SubpixelBatch, SubsetTracker, solve_each, subset_stack

#: subsets refined together: bounds the stacks' memory (512 subsets of 64 px: ~100 MB of Jacobians)
CHUNK = 512


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


    def subpixel_many(self, state: Any, ref: np.ndarray, cur: np.ndarray, pts: np.ndarray,
                      origins: np.ndarray, s: int, matches: list[IntegerMatch],
                      mask: np.ndarray | None) -> SubpixelBatch:
        """:meth:`subpixel` for K points at once (stacked solves, one interpolation per
        iteration); see :meth:`SubsetTracker.subpixel_many` for the arguments and shapes."""
        k = len(pts)
        disp = np.full((k, 2), np.nan)
        quality = np.full(k, np.nan)
        reasons = [""] * k
        grad = np.full((k, 2, 2), np.nan)
        for a in range(0, k, CHUNK):
            b = min(a + CHUNK, k)
            disp[a:b], quality[a:b], reasons[a:b], grad[a:b] = _IcgnBatch(
                self, state, ref, origins[a:b], s, matches[a:b], mask).run(cur.shape, pts[a:b])
        # like the per-point path: the gradient exists once some point converged
        affine = self.shape == "affine"
        extras = {"gradient": grad} if affine and np.isfinite(grad).any() else {}
        return disp, quality, reasons, extras


class _IcgnBatch:
    """IC-GN on a stack of K subsets, each with the per-subset path's steps and criteria;
    masked pixels carry weight 0 where the per-subset path drops them."""

    def __init__(self, trk: GaussNewtonTracker, state: Any, ref: np.ndarray, origins: np.ndarray,
                 s: int, matches: list[IntegerMatch], mask: np.ndarray | None) -> None:
        coef, gx_all, gy_all = state
        self.trk, self.coef, self.s = trk, coef, s
        self.affine = trk.shape == "affine"
        n = self.n = len(origins)
        c0, r0 = origins[:, 0], origins[:, 1]
        self.centre = np.column_stack([c0 + (s - 1) / 2, r0 + (s - 1) / 2])  # (K, 2) [px]
        xi = np.arange(s) - (s - 1) / 2
        self.ex, self.ey = (a.ravel() for a in np.meshgrid(xi, xi))  # (P,) local coordinates
        self.sel = None if mask is None else subset_stack(mask, c0, r0, s).reshape(n, -1)
        self.wt = None if mask is None else self.sel.astype(float)  # (K, P) 0/1 weights
        self.cnt = None if mask is None else self.wt.sum(axis=1)
        f = subset_stack(ref, c0, r0, s).reshape(n, -1)
        gx = subset_stack(gx_all, c0, r0, s).reshape(n, -1)
        gy = subset_stack(gy_all, c0, r0, s).reshape(n, -1)
        self.fz = self._zero_mean(f, np.arange(n))
        self.df = np.sqrt(np.sum(self.fz**2, axis=1))
        ex, ey = self.ex, self.ey
        parts = [gx, gy, gx * ex, gx * ey, gy * ex, gy * ey] if self.affine else [gx, gy]
        self.JT = np.stack(parts, axis=1)  # (K, 6 or 2, P) steepest-descent images
        self.peak = np.array([m.peak for m in matches], dtype=float)
        self.M = np.tile(np.eye(3), (n, 1, 1))  # (K, 3, 3) warps, starting at the integer shift
        self.M[:, :2, 2] = np.array([m.shift for m in matches], dtype=float).reshape(n, 2)

    def _zero_mean(self, a: np.ndarray, act: np.ndarray) -> np.ndarray:
        """``a`` ``(len(act), P)`` (pixels of subsets ``act``) less its mean over the used
        pixels, 0 at the others."""
        if self.wt is None:
            return a - a.mean(axis=1, keepdims=True)
        wt = self.wt if len(act) == self.n else self.wt[act]
        return (a - (np.sum(a * wt, axis=1) / self.cnt[act])[:, None]) * wt

    def _bounds_and_sample(self, act: np.ndarray, hw: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """Which of subsets ``act`` leave the image under their warps, and the current image
        ``(len(inside), P)`` sampled at the warped pixels of those inside (0 where masked)."""
        M, c = self.M[act], self.centre[act]
        wx = M[:, 0, 0, None] * self.ex + M[:, 0, 1, None] * self.ey + M[:, 0, 2, None] + c[:, 0, None]
        wy = M[:, 1, 0, None] * self.ex + M[:, 1, 1, None] * self.ey + M[:, 1, 2, None] + c[:, 1, None]
        h, w = hw
        if self.sel is None:
            lo_x, lo_y, hi_x, hi_y = wx.min(1), wy.min(1), wx.max(1), wy.max(1)
        else:  # only the pixels the subset uses
            sel = self.sel[act]
            lo_x, lo_y = np.where(sel, wx, np.inf).min(1), np.where(sel, wy, np.inf).min(1)
            hi_x, hi_y = np.where(sel, wx, -np.inf).max(1), np.where(sel, wy, -np.inf).max(1)
        out = (lo_x < 0) | (lo_y < 0) | (hi_x > w - 1) | (hi_y > h - 1)
        if out.any():
            wx, wy = wx[~out], wy[~out]
        order, coef = self.trk.order, self.coef
        if self.sel is None:
            g = map_coordinates(coef, [wy.ravel(), wx.ravel()], order=order, prefilter=False,
                                mode="mirror").reshape(wx.shape)
        else:
            sel = self.sel[act][~out]
            g = np.zeros(wx.shape)
            g[sel] = map_coordinates(coef, [wy[sel], wx[sel]], order=order, prefilter=False,
                                     mode="mirror")
        return out, g

    def run(self, hw: tuple[int, int], pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str],
                                                                  np.ndarray]:
        """Iterate every subset to convergence or failure: displacements of ``pts`` ``(K, 2)``
        [px], qualities ``(K,)``, K reasons, displacement gradients ``(K, 2, 2)`` (NaN where
        failed or without the affine shape)."""
        n, trk = self.n, self.trk
        why = [""] * n
        quality = np.full(n, np.nan)  # set on failure; from the ZNSSD for the rest
        znssd = np.full(n, np.nan)
        converged = np.zeros(n, bool)
        flat = self.df == 0
        for j in np.flatnonzero(flat):
            why[j], quality[j] = "reference subset has no texture", 0.0
        act = np.flatnonzero(~flat)
        q = self.JT.shape[1]
        Hinv = np.full((n, q, q), np.nan)  # inverse Gauss-Newton Hessians
        JTw = self.JT[act] if self.wt is None else self.JT[act] * self.wt[act, None, :]
        Hinv[act] = solve_each(JTw @ self.JT[act].transpose(0, 2, 1), np.eye(q)[None])
        degenerate = np.isnan(Hinv[act]).any(axis=(1, 2))
        for j in act[degenerate]:
            why[j], quality[j] = "reference subset gradient is degenerate", 0.0
        act = act[~degenerate]
        half = (self.s - 1) / 2
        for _ in range(trk.max_iter):
            if not len(act):
                break
            out, g = self._bounds_and_sample(act, hw)
            for j in act[out]:
                why[j], quality[j] = "displaced subset leaves the current image", self.peak[j]
            act = act[~out]
            gz = self._zero_mean(g, act)
            dg = np.sqrt(np.sum(gz**2, axis=1))
            for j in act[dg == 0]:
                why[j], quality[j] = "current subset has no texture", 0.0
            if np.any(dg == 0):
                act, gz, dg = act[dg != 0], gz[dg != 0], dg[dg != 0]
            every = len(act) == n  # no gathering of rows while every subset iterates
            df = self.df[act]
            r = (self.fz if every else self.fz[act]) - (df / dg)[:, None] * gz
            znssd[act] = np.sum(r**2, axis=1) / df**2
            # J^T r over the whole chunk (rows of finished subsets zero): cheaper than
            # gathering the active rows of the (K, 6, P) steepest-descent images
            r_all = r if every else np.zeros_like(self.fz)
            r_all[act] = r
            JTr = np.einsum("nkp,np->nk", self.JT, r_all)[act]
            dp = -(Hinv[act] @ JTr[:, :, None])[:, :, 0]
            self.M[act] = self.M[act] @ np.linalg.inv(_warp_matrices(dp, self.affine))
            move = np.hypot(dp[:, 0], dp[:, 1])
            if self.affine:
                move += half * np.sqrt(np.sum(dp[:, 2:] ** 2, axis=1))
            done = move < trk.tol_px
            converged[act[done]] = True
            act = act[~done]
        ran = np.array([not y for y in why])  # no failure before or during the iterations
        quality[ran] = 1.0 - znssd[ran] / 2.0
        for j in np.flatnonzero(ran & ~converged):
            why[j] = f"Gauss-Newton did not converge in {trk.max_iter} iterations"
        loc = pts - self.centre
        A, t = self.M[:, :2, :2], self.M[:, :2, 2]
        disp = np.where(converged[:, None], (A @ loc[:, :, None])[:, :, 0] + t - loc, np.nan)
        grad = np.where(converged[:, None, None] & self.affine, A - np.eye(2), np.nan)
        return disp, quality, why, grad


def _warp_matrices(p: np.ndarray, affine: bool) -> np.ndarray:
    """:func:`_warp_matrix` for a stack of parameters ``p`` ``(K, 6 or 2)``: ``(K, 3, 3)``."""
    M = np.tile(np.eye(3), (len(p), 1, 1))
    M[:, :2, 2] = p[:, :2]
    if affine:
        M[:, 0, 0] += p[:, 2]
        M[:, 0, 1] = p[:, 3]
        M[:, 1, 0] = p[:, 4]
        M[:, 1, 1] += p[:, 5]
    return M


class TranslationGaussNewtonTracker(GaussNewtonTracker):
    """``gn-translation``: the same IC-GN with a pure-translation shape function."""

    name = "gn-translation"

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("shape", "translation")
        super().__init__(**kwargs)
