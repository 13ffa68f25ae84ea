"""Fluorescent marker spheres: detection, multi-view matching, and validation of speckle
tracks against them (thesis 5.2.4).

Markers are independent of the speckle: their 3D positions, measured by detecting and
triangulating the spheres, are compared with the positions the speckle tracks predict
for the same material points.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from skinkit.schemas import CameraRig, SurfaceTrack
from skinkit.vision import VisionError
from skinkit.vision.matching import epipolar_distance_px
from skinkit.vision.triangulation import triangulate


def detect_markers(image: np.ndarray, threshold: float = 0.93, min_area_px: int = 4,
                   max_area_px: int = 400, max_elongation: float = 1.2) -> np.ndarray:
    """``(M, 2)`` centres [px] of bright round blobs (markers brighter than the speckle).

    Blobs are the connected regions above ``threshold`` (fraction of the image type's full
    scale; of the image maximum for float images). Each centre is the centroid of the
    blob's intensity above its half-maximum level (local background from a surrounding
    ring), which uses the blurred rim and so does not depend on the pixel grid even when
    the blob saturates. Blobs whose weighted second moments are more elongated than
    ``max_elongation`` (a sphere half hidden by the indenter or the skin) are rejected.
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise VisionError(f"marker image: expected (H, W), got shape {img.shape}")
    full = float(np.iinfo(img.dtype).max) if img.dtype.kind in "ui" else float(img.max())
    binary = (img >= threshold * full).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8)
    f = img.astype(float)
    H, W = img.shape
    out = []
    for k in range(1, n):
        area = stats[k, cv2.CC_STAT_AREA]
        if area < min_area_px or area > max_area_px:
            continue
        x0, y0 = stats[k, cv2.CC_STAT_LEFT], stats[k, cv2.CC_STAT_TOP]
        x1, y1 = x0 + stats[k, cv2.CC_STAT_WIDTH], y0 + stats[k, cv2.CC_STAT_HEIGHT]
        if x0 < 5 or y0 < 5 or x1 > W - 5 or y1 > H - 5:
            continue
        ring = np.concatenate([f[y0 - 4:y0 - 2, x0 - 4:x1 + 4].ravel(),
                               f[y1 + 2:y1 + 4, x0 - 4:x1 + 4].ravel(),
                               f[y0 - 2:y1 + 2, x0 - 4:x0 - 2].ravel(),
                               f[y0 - 2:y1 + 2, x1 + 2:x1 + 4].ravel()])
        bg = float(np.median(ring))
        ys, xs = np.mgrid[y0 - 2:y1 + 2, x0 - 2:x1 + 2]
        v = f[ys, xs]
        half = bg + 0.5 * (float(v.max()) - bg)
        w = np.clip(v - half, 0, None)
        # Keep only this blob's rim: pixels of other blobs inside the box are excluded.
        lab = labels[ys, xs]
        w[(lab != k) & (lab != 0)] = 0
        sw = w.sum()
        cx, cy = float(np.sum(w * xs) / sw), float(np.sum(w * ys) / sw)
        dx, dy = xs - cx, ys - cy
        cov = np.array([[np.sum(w * dx * dx), np.sum(w * dx * dy)],
                        [np.sum(w * dx * dy), np.sum(w * dy * dy)]]) / sw
        ev = np.linalg.eigvalsh(cov)
        if ev[0] <= 0 or np.sqrt(ev[1] / ev[0]) > max_elongation:
            continue
        out.append([cx, cy])
    return np.array(out, dtype=float).reshape(-1, 2)


@dataclass
class MarkerSet:
    """Triangulated markers: ``points`` ``(M, 3)`` [m], ``pixels`` ``(M, C, 2)`` [px]
    (NaN where unseen), ``reprojection_px`` ``(M,)``."""

    points: np.ndarray
    pixels: np.ndarray
    reprojection_px: np.ndarray


def match_markers(rig: CameraRig, detections: list[np.ndarray], tol_px: float = 1.0,
                  min_views: int = 3, merge_m: float = 1e-4) -> MarkerSet:
    """Match marker detections across the views of ``rig`` and triangulate them.

    Every epipolar-consistent pair of detections is triangulated, projected into the other
    views, and joined by the detections found within ``tol_px``; hypotheses seen in at
    least ``min_views`` views with a reprojection RMS below ``tol_px`` are kept, and
    duplicates closer than ``merge_m`` [m] merged.
    """
    from skinkit.vision import camera as cam_ops

    C = len(rig)
    if len(detections) != C:
        raise VisionError(f"{len(detections)} detection lists for a rig of {C} cameras")
    found: list[tuple[np.ndarray, np.ndarray, float]] = []
    for a in range(C):
        for b in range(a + 1, C):
            da, db = detections[a], detections[b]
            if len(da) == 0 or len(db) == 0:
                continue
            ia, ib = np.meshgrid(np.arange(len(da)), np.arange(len(db)), indexing="ij")
            ia, ib = ia.ravel(), ib.ravel()
            ok = epipolar_distance_px(rig[a], rig[b], da[ia], db[ib]) <= tol_px
            for i, j in zip(ia[ok], ib[ok], strict=True):
                obs = np.full((1, C, 2), np.nan)
                obs[0, a], obs[0, b] = da[i], db[j]
                X = triangulate(rig, obs).points
                for c in range(C):
                    if c in (a, b) or len(detections[c]) == 0:
                        continue
                    p = cam_ops.project(rig[c], X)[0]
                    d = np.linalg.norm(detections[c] - p, axis=1)
                    if d.min() <= tol_px:
                        obs[0, c] = detections[c][int(np.argmin(d))]
                tri = triangulate(rig, obs)
                if tri.n_views[0] >= min_views and tri.reprojection_px[0] <= tol_px:
                    found.append((tri.points[0], obs[0], float(tri.reprojection_px[0])))
    pts: list[np.ndarray] = []
    pix: list[np.ndarray] = []
    err: list[float] = []
    for X, obs, e in sorted(found, key=lambda f: -np.count_nonzero(np.isfinite(f[1][:, 0]))):
        if any(np.linalg.norm(X - q) < merge_m for q in pts):
            continue
        pts.append(X)
        pix.append(obs)
        err.append(e)
    return MarkerSet(np.array(pts).reshape(-1, 3), np.array(pix).reshape(-1, C, 2), np.array(err))


def predict_from_track(track: SurfaceTrack, frame: int, markers_ref: np.ndarray,
                       neighbours: int = 10) -> np.ndarray:
    """Positions ``(M, 3)`` [m] in ``frame`` of the material points at ``markers_ref``
    ``(M, 3)`` in frame 0, from the speckle track's displacements.

    The displacement is fitted, around each marker, by a quadratic in the in-plane
    coordinates over its ``neighbours`` nearest tracked points (valid in both frames);
    a dimple's curvature would bias a linear interpolation.
    """
    from scipy.spatial import cKDTree

    ok = track.valid[:, 0] & track.valid[:, frame]
    P0 = track.points[ok, 0]
    U = track.points[ok, frame] - P0
    if len(P0) < neighbours:
        raise VisionError(f"only {len(P0)} points tracked in frame {frame}; need {neighbours}")
    tree = cKDTree(P0)
    out = np.empty((len(markers_ref), 3))
    for m, X in enumerate(np.asarray(markers_ref, float)):
        _, idx = tree.query(X, k=neighbours)
        d = P0[idx] - X
        A = np.column_stack([np.ones(len(d)), d[:, 0], d[:, 1], d[:, 0] ** 2, d[:, 0] * d[:, 1],
                             d[:, 1] ** 2])
        coef, *_ = np.linalg.lstsq(A, U[idx], rcond=None)
        out[m] = X + coef[0]
    return out
