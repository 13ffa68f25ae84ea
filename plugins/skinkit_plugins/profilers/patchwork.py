"""``patchwork``: automatic surface profiling by affine patchwork (thesis 2.6.4 and 5.4).

For every ordered pair of cameras (reference a, other b):

1. seed correspondences by SIFT matching, kept only if they obey the rig's epipolar geometry
   (this replaces the thesis's hand-clicked control points);
2. a grid of points in the reference view, inside the seeds' convex hull;
3. a region is registered by the affine transform fitted (RANSAC) to its seeds, view b is
   warped onto view a, and the integer-shift uncertainty (ISU, thesis 5.4) of every grid
   point is measured by NCC; while the mean ISU is above ``isu_split_px`` and the region
   is large enough it is split in four (the patchwork, found automatically);
4. each grid point is matched to subpixel precision by the tracker on the warped image,
   and mapped back through the affine transform.

Every camera is the reference in turn; each grid point is triangulated from all views
that matched it, views that disagree are dropped by reprojection error, and open3d's
statistical outlier removal cleans the merged cloud.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from matplotlib.path import Path

from skinkit import registry
from skinkit.plugin.profilers import (
    VisionError,
    camera_order,
    edge_reason,
    ncc_integer,
    project,
    seed_matches,
    subset_origin,
    triangulate,
)
from skinkit.schemas import CameraRig, ImageSequence, SurfaceProfile


@dataclass
class ProfileReport:
    """Diagnostics of the last run: per-pair patch counts, mean ISU, points kept."""

    pairs: dict[str, dict[str, float]] = field(default_factory=dict)
    n_candidates: int = 0
    n_reprojection_rejected: int = 0
    n_statistical_outliers: int = 0
    reference_camera: np.ndarray | None = None
    reference_px: np.ndarray | None = None
    outlier_backend: str = ""
    n_surface_outliers: int = 0


class PatchworkProfiler:
    """Automatic profiler.

    Args:
        tracker: tracker plugin name for the subpixel match.
        subset_px: subset side [px].
        spacing_px: grid step in the reference view [px].
        isu_split_px: split a patch while its mean ISU exceeds this [px].
        min_patch_px: do not split patches smaller than this [px].
        max_reprojection_px: drop views (then points) whose RMS reprojection error exceeds it.
        outlier_neighbours, outlier_std: open3d statistical outlier removal settings.
        min_views: views a point needs (two views cannot reveal a match slipped along the
            epipolar line; a third can).
        min_peak: correlation a match needs; a patch where fewer than 80 % of the subsets
            reach it is split.
        masks: optional ``(C, H, W)`` bool arrays of usable pixels, in image camera order.
    """

    name = "patchwork"
    #: the keyword options the constructor accepts (read by ``skinkit vision profile``)
    options = {
        "tracker": "tracker plugin name for the subpixel match",
        "subset_px": "subset side [px]",
        "spacing_px": "grid step in the reference view [px]",
        "isu_split_px": "split a patch while its mean ISU exceeds this [px]",
        "min_patch_px": "do not split patches smaller than this [px]",
        "max_reprojection_px": "drop views whose RMS reprojection error exceeds this [px]",
        "outlier_neighbours": "neighbours of the statistical outlier removal",
        "outlier_std": "standard deviations of the statistical outlier removal",
        "masks": "(C, H, W) bool arrays of usable pixels, in image camera order",
        "search_px": "integer search radius of the tracker [px]",
        "min_views": "views a point needs",
        "min_peak": "correlation a match needs [1]",
    }

    def __init__(self, tracker: str = "pcc", subset_px: int = 31, spacing_px: int = 12,
                 isu_split_px: float = 5.0, min_patch_px: int = 48, max_reprojection_px: float = 0.5,
                 outlier_neighbours: int = 20, outlier_std: float = 2.5,
                 masks: np.ndarray | None = None, search_px: int = 8, min_views: int = 3,
                 min_peak: float = 0.7) -> None:
        self.tracker = registry.create("skinkit.trackers", tracker, search_px=search_px,
                                       min_quality=min_peak)
        self.min_views = int(min_views)
        self.min_peak = float(min_peak)
        self.subset_px = int(subset_px)
        self.spacing_px = int(spacing_px)
        self.isu_split_px = float(isu_split_px)
        self.min_patch_px = int(min_patch_px)
        self.max_reprojection_px = float(max_reprojection_px)
        self.outlier_neighbours = int(outlier_neighbours)
        self.outlier_std = float(outlier_std)
        self.masks = masks
        self.report = ProfileReport()
        self._features: dict[int, tuple] = {}

    # -- one ordered pair -------------------------------------------------------------
    def _patch(self, img_a: np.ndarray, img_b: np.ndarray, mask_a: np.ndarray | None,
               seeds_a: np.ndarray, seeds_b: np.ndarray, grid: np.ndarray, box: tuple[float, ...],
               out: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]], stats: dict[str, float],
               ) -> None:
        x0, y0, x1, y1 = box
        inside = (grid[:, 0] >= x0) & (grid[:, 0] < x1) & (grid[:, 1] >= y0) & (grid[:, 1] < y1)
        pts = grid[inside]
        if len(pts) == 0:
            return
        pad = 0.25 * max(x1 - x0, y1 - y0)
        near = (seeds_a[:, 0] >= x0 - pad) & (seeds_a[:, 0] < x1 + pad) & \
            (seeds_a[:, 1] >= y0 - pad) & (seeds_a[:, 1] < y1 + pad)
        if np.count_nonzero(near) < 6:
            return
        A, inl = cv2.estimateAffine2D(seeds_a[near], seeds_b[near], method=cv2.RANSAC,
                                      ransacReprojThreshold=2.0)
        if A is None or int(np.sum(inl)) < 6:
            return
        h, w = img_a.shape
        warped = cv2.warpAffine(img_b.astype(np.float32), A, (w, h),
                                flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP, borderValue=0)
        valid_b = cv2.warpAffine(np.ones(img_b.shape, np.uint8), A, (w, h),
                                 flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP, borderValue=0)
        m = valid_b.astype(bool) if mask_a is None else (valid_b.astype(bool) & mask_a)
        # The split decision needs only the NCC integer step (thesis 5.4's ISU).
        isu = np.full(len(pts), np.nan)
        peak = np.full(len(pts), np.nan)
        s = self.subset_px
        for i, p in enumerate(pts):
            if edge_reason(p, (h, w), s, margin=2):
                continue
            c0, r0 = subset_origin(p, s)
            if not m[r0:r0 + s, c0:c0 + s].all():
                continue
            match = ncc_integer(img_a, warped, c0, r0, s, 2)
            if match is not None:
                isu[i] = match.isu_px
                peak[i] = match.peak
        finite = np.isfinite(isu)
        mean_isu = float(np.mean(isu[finite])) if np.any(finite) else np.inf
        # A patch is registered well enough when its ISU is low and its subsets still
        # correlate (a poor affine fit lowers the peaks before it widens them).
        poor = mean_isu > self.isu_split_px or not np.mean(np.nan_to_num(peak) >= self.min_peak) >= 0.8
        if poor and min(x1 - x0, y1 - y0) >= 2 * self.min_patch_px:
            xm, ym = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
            for sub in ((x0, y0, xm, ym), (xm, y0, x1, ym), (x0, ym, xm, y1), (xm, ym, x1, y1)):
                self._patch(img_a, img_b, mask_a, seeds_a, seeds_b, grid, sub, out, stats)
            return
        stats["patches"] += 1
        res = self.tracker.track(img_a, warped, pts, self.subset_px, m)
        isu = np.asarray(res.isu_px, float)
        ok = np.asarray(res.valid, bool)
        if not np.any(ok):
            return
        q = pts[ok] + np.asarray(res.displacement_px)[ok]
        pb = q @ A[:, :2].T + A[:, 2]
        out.append((pts[ok], pb, np.asarray(res.quality)[ok], isu[ok]))

    def _pair(self, img_a: np.ndarray, img_b: np.ndarray, cam_a: Any, cam_b: Any,
              mask_a: np.ndarray | None, mask_b: np.ndarray | None, grid: np.ndarray,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, float]]:
        sa, sb = seed_matches(img_a, img_b, cam_a, cam_b, mask_a, mask_b, cache=self._features)
        stats = {"seeds": float(len(sa)), "patches": 0.0, "matched": 0.0, "mean_isu_px": np.nan}
        empty = (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0), stats)
        if len(sa) < 6:
            return empty
        hull = cv2.convexHull(sa.astype(np.float32)).reshape(-1, 2)
        g = grid[Path(hull).contains_points(grid)]
        if len(g) == 0:
            return empty
        out: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        box = (float(g[:, 0].min()), float(g[:, 1].min()), float(g[:, 0].max()) + 1, float(g[:, 1].max()) + 1)
        self._patch(img_a, img_b, mask_a, sa, sb, g, box, out, stats)
        if not out:
            return empty
        pa, pb, q, isu = (np.concatenate(x) for x in zip(*out, strict=True))
        stats["matched"] = float(len(pa))
        stats["mean_isu_px"] = float(np.mean(isu))
        return pa, pb, q, isu, stats

    # -- the profiler -----------------------------------------------------------------
    def profile(self, images: ImageSequence, rig: CameraRig, frame: int = 0) -> SurfaceProfile:
        """Profile the surface seen in ``images.frames[frame]``; points in the rig's world [m]."""
        order = camera_order(rig, images.camera_names)
        sub = CameraRig(tuple(rig.cameras[i] for i in order))
        if not 0 <= frame < images.n_frames:
            raise VisionError(f"frame {frame} is not in the sequence of {images.n_frames} frames")
        C = len(sub)
        if C < 2:
            raise VisionError("profiling needs at least two cameras")
        views = [np.asarray(images.frames[frame, c]) for c in range(C)]
        masks = self.masks
        if masks is not None and np.shape(masks) != (C, *views[0].shape):
            raise VisionError(f"profiler masks: expected shape {(C, *views[0].shape)}, got {np.shape(masks)}")
        h, w = views[0].shape
        half = self.subset_px // 2 + 2
        gy, gx = np.mgrid[half:h - half:self.spacing_px, half:w - half:self.spacing_px]
        grid = np.column_stack([gx.ravel(), gy.ravel()]).astype(float)
        self.report = ProfileReport()
        self._features = {}
        cv2.setRNGSeed(0)  # RANSAC in the affine fits: the same images give the same profile
        all_pts, all_q, all_isu, all_ref, all_px = [], [], [], [], []
        for a in range(C):
            ga = grid if masks is None else grid[masks[a][grid[:, 1].astype(int), grid[:, 0].astype(int)]]
            obs = np.full((len(ga), C, 2), np.nan)
            obs[:, a] = ga
            qsum = np.zeros(len(ga))
            isum = np.zeros(len(ga))
            cnt = np.zeros(len(ga))
            index = {tuple(p): i for i, p in enumerate(ga)}
            for b in range(C):
                if b == a:
                    continue
                pa, pb, q, isu, stats = self._pair(
                    views[a], views[b], sub[a], sub[b],
                    None if masks is None else masks[a], None if masks is None else masks[b], ga)
                self.report.pairs[f"{sub[a].name}->{sub[b].name}"] = stats
                idx = np.array([index[tuple(p)] for p in pa], dtype=int)
                if len(idx):
                    obs[idx, b] = pb
                    qsum[idx] += q
                    isum[idx] += isu
                    cnt[idx] += 1
            keep = cnt > 0
            obs, qsum, isum, cnt, ga_k = obs[keep], qsum[keep], isum[keep], cnt[keep], ga[keep]
            self.report.n_candidates += len(obs)
            X, ok = self._triangulate_robust(sub, obs)
            self.report.n_reprojection_rejected += int(np.count_nonzero(~ok))
            all_pts.append(X[ok])
            all_q.append(qsum[ok] / cnt[ok])
            all_isu.append(isum[ok] / cnt[ok])
            all_ref.append(np.full(int(ok.sum()), a))
            all_px.append(ga_k[ok])
        P = np.concatenate(all_pts) if all_pts else np.zeros((0, 3))
        Q = np.concatenate(all_q) if all_q else np.zeros(0)
        ISU = np.concatenate(all_isu) if all_isu else np.zeros(0)
        ref = np.concatenate(all_ref) if all_ref else np.zeros(0, int)
        rpx = np.concatenate(all_px) if all_px else np.zeros((0, 2))
        if len(P) == 0:
            raise VisionError("profiling found no matched points (no texture, or views do not overlap)")
        keep = self._statistical_inliers(P)
        self.report.n_statistical_outliers = int(np.count_nonzero(~keep))
        smooth = self._surface_inliers(P[keep])
        self.report.n_surface_outliers = int(np.count_nonzero(~smooth))
        keep[np.flatnonzero(keep)[~smooth]] = False
        self.report.reference_camera = ref[keep]
        self.report.reference_px = rpx[keep]
        return SurfaceProfile(P[keep], Q[keep], ISU[keep], "peak_correlation")

    def _triangulate_robust(self, rig: CameraRig, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Triangulate; where the RMS reprojection error is too large, drop the worst
        non-reference view while three or more remain."""
        obs = obs.copy()
        for _ in range(len(rig) - 1):
            tri = triangulate(rig, obs)
            bad = tri.valid & (tri.reprojection_px > self.max_reprojection_px) & (tri.n_views >= 3)
            if not np.any(bad):
                break
            for i in np.flatnonzero(bad):
                errs = []
                for c, cam in enumerate(rig.cameras):
                    if np.all(np.isfinite(obs[i, c])):
                        errs.append((np.linalg.norm(project(cam, tri.points[i:i + 1])[0] - obs[i, c]), c))
                errs.sort()
                obs[i, errs[-1][1]] = np.nan
        tri = triangulate(rig, obs)
        ok = tri.valid & (tri.reprojection_px <= self.max_reprojection_px) & (tri.n_views >= self.min_views)
        return tri.points, ok

    def _surface_inliers(self, P: np.ndarray, k: int = 12, n_sigma: float = 5.0) -> np.ndarray:
        """Skin is smooth at the scale of a few grid steps: drop points farther from the
        plane through their ``k`` nearest neighbours than ``n_sigma`` robust standard
        deviations (MAD) of that distance over the cloud. Open3d's density test misses a
        point that slipped along a line of sight yet still has close neighbours."""
        if len(P) <= k + 3:
            return np.ones(len(P), bool)
        from scipy.spatial import cKDTree

        _, idx = cKDTree(P).query(P, k=k + 1)
        nb = P[idx[:, 1:]]  # (N, k, 3), the point itself excluded
        c = nb.mean(axis=1)
        _, _, vt = np.linalg.svd(nb - c[:, None], full_matrices=False)
        normal = vt[:, -1]
        d = np.abs(np.sum((P - c) * normal, axis=1))
        sigma = 1.4826 * np.median(d)
        return d <= n_sigma * max(sigma, 1e-9)

    def _statistical_inliers(self, P: np.ndarray) -> np.ndarray:
        """open3d's statistical outlier removal: drop points whose mean distance to their
        k neighbours exceeds the cloud's mean by ``outlier_std`` standard deviations.
        Where open3d cannot load (it needs libusb on Linux) the same rule runs on scipy."""
        k = self.outlier_neighbours
        if len(P) <= k:
            return np.ones(len(P), bool)
        try:
            import open3d as o3d
        except (ImportError, OSError):
            from scipy.spatial import cKDTree

            self.report.outlier_backend = "scipy"
            d, _ = cKDTree(P).query(P, k=k + 1)
            mean_d = d[:, 1:].mean(axis=1)
            return mean_d <= mean_d.mean() + self.outlier_std * mean_d.std()
        self.report.outlier_backend = "open3d"
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
        _, idx = pc.remove_statistical_outlier(nb_neighbors=k, std_ratio=self.outlier_std)
        keep = np.zeros(len(P), bool)
        keep[np.asarray(idx, int)] = True
        return keep
