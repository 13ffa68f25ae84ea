"""3D tracks of profiled material points: project, track in every camera, triangulate."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from skinkit.schemas import CameraRig, ImageSequence, SurfaceTrack
from skinkit.vision import VisionError
from skinkit.vision import camera as cam_ops
from skinkit.vision.triangulation import triangulate


def camera_order(rig: CameraRig, names: Sequence[str]) -> list[int]:
    """Rig index of each named camera; a camera missing from the rig is an error."""
    missing = [n for n in names if n not in rig.names]
    if missing:
        raise VisionError(f"camera(s) {missing} in the images are missing from the rig "
                          f"(rig cameras: {rig.names})")
    return [rig.names.index(n) for n in names]


def reference_pixels(rig: CameraRig, points: np.ndarray, subset_px: int) -> np.ndarray:
    """``(P, C, 2)`` projections of ``(P, 3)`` points [m]; NaN where a subset would not fit."""
    pts = np.asarray(points, float)
    out = np.full((len(pts), len(rig), 2), np.nan)
    half = subset_px // 2 + 1
    for c, cam in enumerate(rig.cameras):
        px = cam_ops.project(cam, pts)
        w, h = cam.image_size
        ok = np.all(np.isfinite(px), axis=1) & (px[:, 0] >= half) & (px[:, 1] >= half) & \
            (px[:, 0] <= w - 1 - half) & (px[:, 1] <= h - 1 - half)
        out[ok, c] = px[ok]
    return out


def track_3d(rig: CameraRig, images: ImageSequence, points: np.ndarray, tracker: Any,
             subset_px: int = 41, masks: np.ndarray | None = None, max_reprojection_px: float = 1.0,
             progress: bool | Callable[[int, int], None] = False,
             noise_floor_m: np.ndarray | None = None) -> tuple[SurfaceTrack, np.ndarray]:
    """Track ``points`` ``(P, 3)`` [m] (e.g. a surface profile, seen in frame 0) through
    ``images`` and triangulate them in every frame.

    Every frame is tracked against frame 0 (no drift). A view is dropped where the tracker
    marks it invalid; a point is valid in a frame when at least two views remain and its
    RMS reprojection error is at most ``max_reprojection_px``. ``masks``: optional
    ``(F, C, H, W)`` bool, usable pixels (e.g. False over the indenter).
    Returns the :class:`SurfaceTrack` and the ``(P, F)`` reprojection errors [px].
    ``progress``: True shows a bar; a callable is told ``(frames tracked, frames to track)``.

    ``noise_floor_m`` ``(3,)`` [m] (the still-frame noise per axis): when given, the track
    carries each position's standard error (:func:`position_uncertainty`) — the views'
    disagreement, which grows with the deformation a subset misreads, never below the floor.
    """
    order = camera_order(rig, images.camera_names)
    sub = CameraRig(tuple(rig.cameras[i] for i in order))
    for cam in sub.cameras:
        if tuple(cam.image_size) != images.image_size:
            raise VisionError(f"camera {cam.name} is {cam.image_size[0]}x{cam.image_size[1]} px in the "
                              f"rig but the images are {images.image_size[0]}x{images.image_size[1]}")
    ref_px = reference_pixels(sub, points, subset_px)
    F, C = images.frames.shape[:2]
    P = len(ref_px)
    cur = np.full((P, F, C, 2), np.nan)
    cur[:, 0] = ref_px
    frames = range(1, F)
    if progress is True:
        from rich.progress import track as rich_track

        frames = rich_track(frames, description="tracking frames")
    for f in frames:
        if callable(progress):
            progress(f - 1, F - 1)
        for c in range(C):
            seen = np.flatnonzero(np.all(np.isfinite(ref_px[:, c]), axis=1))
            if len(seen) == 0:
                continue
            m = None if masks is None else masks[f, c]
            res = tracker.track(images.frames[0, c], images.frames[f, c], ref_px[seen, c], subset_px, m)
            ok = np.asarray(res.valid, bool)
            cur[seen[ok], f, c] = ref_px[seen[ok], c] + np.asarray(res.displacement_px)[ok]
    X = np.full((P, F, 3), np.nan)
    sig = np.full((P, F, 3), np.nan)
    err = np.full((P, F), np.nan)
    valid = np.zeros((P, F), bool)
    for f in range(F):
        tri = triangulate(sub, cur[:, f])
        X[:, f] = tri.points
        sig[:, f] = tri.sigma_m
        err[:, f] = tri.reprojection_px
        valid[:, f] = tri.valid & (tri.reprojection_px <= max_reprojection_px)
    X[~valid] = np.nan
    unc = None if noise_floor_m is None else position_uncertainty(points, sig, valid, noise_floor_m)
    return SurfaceTrack(X, valid, images.time_s, np.arange(P), unc), err


#: neighbours (the point included) whose triangulation variances are pooled into one
#: point's: the error field is smooth on the scale of overlapping subsets, and one point's
#: estimate alone has only 2n − 3 degrees of freedom (5 with four views)
POOLED_NEIGHBOURS = 9


def position_uncertainty(points: np.ndarray, sigma_m: np.ndarray, valid: np.ndarray,
                         floor_m: np.ndarray) -> np.ndarray:
    """``(P, F, 3)`` [m] standard error of each tracked position: per frame and axis, the mean
    triangulation variance ``sigma_m`` ``(P, F, 3)`` [m] over the :data:`POOLED_NEIGHBOURS`
    nearest of ``points`` ``(P, 3)`` [m] (at rest) that are ``valid`` ``(P, F)``, never below
    ``floor_m`` ``(3,)`` [m]; NaN where not valid."""
    from scipy.spatial import cKDTree

    floor = np.broadcast_to(np.asarray(floor_m, float), (3,))
    P = len(points)
    k = min(POOLED_NEIGHBOURS, P)
    _, nb = cKDTree(np.asarray(points, float)).query(points, k)
    nb = np.asarray(nb).reshape(P, k)
    var = np.where(valid[..., None] & np.isfinite(sigma_m), np.square(sigma_m), 0.0)
    have = (valid[..., None] & np.isfinite(sigma_m)).astype(float)
    n = have[nb].sum(axis=1)                                     # (P, F, 3)
    pooled = np.where(n > 0, var[nb].sum(axis=1) / np.maximum(n, 1.0), 0.0)
    out = np.sqrt(np.maximum(pooled, floor**2))
    return np.where(valid[..., None], out, np.nan)
