"""Joint calibration of N >= 2 cameras from checkerboard views (OpenCV 5 multiview).

Corners are detected in every view, their order fixed by the square colours and checked for
consistent handedness; OpenCV's ``calibrateMultiviewExtended`` then estimates every
camera's intrinsics and distortion and the poses relative to camera 0 by minimising the
total reprojection error. The world frame is the board frame of one chosen view (by default
the first frame camera 0 saw), so a board laid flat on the skin puts z along the skin normal.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from skinkit.schemas import CameraModel, CameraRig
from skinkit.vision import VisionError
from skinkit.vision.boards import check_board, detect_board, handedness


@dataclass
class Detections:
    """Board corners found in each view.

    ``corners``: ``(F, C, P, 2)`` [px], NaN where not detected; ``found``: ``(F, C)`` bool.
    """

    corners: np.ndarray
    found: np.ndarray
    image_size: tuple[int, int]


@dataclass
class Calibration:
    """A calibrated rig and how well it explains the corners.

    Attributes:
        rig: the cameras, world frame = board frame of view ``world_view``.
        rms_px: overall RMS reprojection error [px].
        per_camera_rms_px: ``(C,)`` RMS reprojection error per camera [px].
        per_view_rms_px: ``(F, C)`` RMS per view [px], NaN where the board was not seen.
        detections: the corners used.
        world_view: frame index whose board defines the world frame.
    """

    rig: CameraRig
    rms_px: float
    per_camera_rms_px: np.ndarray
    per_view_rms_px: np.ndarray
    detections: Detections
    world_view: int


def detect_all(images: np.ndarray, inner: tuple[int, int],
               camera_names: Sequence[str] | None = None) -> Detections:
    """Detect the board in ``(F, C, H, W)`` images; check corner orderings are consistent."""
    check_board(inner)
    imgs = np.asarray(images)
    if imgs.ndim != 4:
        raise VisionError(f"calibration images: expected (frames, cameras, H, W), got shape {imgs.shape}")
    F, C, H, W = imgs.shape
    names = list(camera_names) if camera_names is not None else [f"camera {c}" for c in range(C)]
    P = int(inner[0]) * int(inner[1])
    corners = np.full((F, C, P, 2), np.nan)
    found = np.zeros((F, C), bool)
    signs: dict[tuple[int, int], float] = {}
    for f in range(F):
        for c in range(C):
            try:
                pts = detect_board(imgs[f, c], inner)
            except VisionError as exc:
                raise VisionError(f"{names[c]}, frame {f}: {exc}") from None
            if pts is not None:
                corners[f, c] = pts
                found[f, c] = True
                signs[(f, c)] = handedness(pts, int(inner[0]))
    if signs:
        vals = np.array(list(signs.values()))
        major = 1.0 if np.sum(vals > 0) >= np.sum(vals < 0) else -1.0
        bad = [k for k, v in signs.items() if v != major]
        if bad:
            where = ", ".join(f"{names[c]} frame {f}" for f, c in bad[:5])
            raise VisionError(f"inconsistent board corner ordering (mirrored) in {len(bad)} view(s): "
                              f"{where}; is the board seen from behind or its size wrong?")
    return Detections(corners, found, (W, H))


def calibrate(images: np.ndarray, inner: tuple[int, int], square_m: float,
              camera_names: Sequence[str] | None = None, min_views: int = 4,
              world_view: int | None = None, fix_k3: bool = True) -> Calibration:
    """Calibrate the cameras that took ``images`` ``(F, C, H, W)`` of a checkerboard.

    ``inner``: (columns, rows) of inner corners; ``square_m``: square side [m].
    Raises :class:`VisionError` if any camera saw the board in fewer than ``min_views``
    frames or shares no view with another camera.
    """
    det = detect_all(images, inner, camera_names)
    return calibrate_detections(det, inner, square_m, camera_names, min_views, world_view, fix_k3)


def calibrate_detections(det: Detections, inner: tuple[int, int], square_m: float,
                         camera_names: Sequence[str] | None = None, min_views: int = 4,
                         world_view: int | None = None, fix_k3: bool = True) -> Calibration:
    """:func:`calibrate` from corners already detected."""
    F, C = det.found.shape
    names = list(camera_names) if camera_names is not None else [f"cam{c}" for c in range(C)]
    if len(names) != C:
        raise VisionError(f"{len(names)} camera names for {C} cameras in the images")
    if C < 2:
        raise VisionError("a rig calibration needs at least 2 cameras")
    if not square_m > 0:
        raise VisionError(f"board square size must be positive, got {square_m} m")
    counts = det.found.sum(axis=0)
    few = [f"{names[c]} ({counts[c]})" for c in range(C) if counts[c] < min_views]
    if few:
        raise VisionError(f"too few board detections: {', '.join(few)}; each camera needs at "
                          f"least {min_views} views of the whole board")
    for c in range(C):
        shared = np.any(det.found[det.found[:, c]][:, np.arange(C) != c])
        if not shared:
            raise VisionError(f"{names[c]} never sees the board at the same time as another camera")
    c0, r0 = inner
    j, i = np.mgrid[0:r0, 0:c0]
    obj = (np.column_stack([i.ravel(), j.ravel(), np.zeros(c0 * r0)]) * square_m).astype(np.float32)
    obj_points = [obj] * F
    img_points = []
    for c in range(C):
        per = []
        for f in range(F):
            pts = det.corners[f, c] if det.found[f, c] else np.full((len(obj), 2), -1.0)
            per.append(pts.astype(np.float32))
        img_points.append(per)
    mask = det.found.T.astype(np.uint8)
    sizes = [det.image_size] * C
    models = np.zeros(C, np.uint8)
    flags_intr = np.full(C, cv2.CALIB_FIX_K3 if fix_k3 else 0, np.int32)
    try:
        out = cv2.calibrateMultiviewExtended(
            obj_points, img_points, sizes, mask, models, None, None, None, None,
            flagsForIntrinsics=flags_intr)
    except cv2.error as exc:
        raise VisionError(f"OpenCV multiview calibration failed: {str(exc).strip().splitlines()[-1]}") from None
    rms, Ks, dists, Rs, Ts, _pairs, rvecs0, tvecs0, per_frame = out
    if world_view is None:
        world_view = int(np.flatnonzero(det.found[:, 0])[0])
    if not det.found[world_view, 0]:
        raise VisionError(f"camera {names[0]} does not see the board in the world view {world_view}")
    Rb, _ = cv2.Rodrigues(np.asarray(rvecs0[world_view], float).reshape(3))
    tb = np.asarray(tvecs0[world_view], float).reshape(3)
    cams = []
    for c in range(C):
        Rc = np.asarray(Rs[c], float)
        Rc = cv2.Rodrigues(Rc.reshape(3))[0] if Rc.size == 3 else Rc.reshape(3, 3)
        Tc = np.asarray(Ts[c], float).reshape(3)
        cams.append(CameraModel(names[c], np.asarray(Ks[c], float), np.asarray(dists[c], float).ravel()[:5],
                                Rc @ Rb, Rc @ tb + Tc, det.image_size))
    rig = CameraRig(tuple(cams))
    per_view = np.where(det.found, np.asarray(per_frame, float).T, np.nan)
    per_cam = np.array([reprojection_rms(rig[c], det, c, inner, square_m, rvecs0, tvecs0, Rs, Ts)
                        for c in range(C)])
    return Calibration(rig, float(rms), per_cam, per_view, det, world_view)


def reprojection_rms(cam: CameraModel, det: Detections, c: int, inner: tuple[int, int],
                     square_m: float, rvecs0: Sequence, tvecs0: Sequence, Rs: Sequence,
                     Ts: Sequence) -> float:
    """RMS reprojection error [px] of camera ``c`` over the views where it saw the board."""
    c0, r0 = inner
    j, i = np.mgrid[0:r0, 0:c0]
    obj = np.column_stack([i.ravel(), j.ravel(), np.zeros(c0 * r0)]) * square_m
    Rc = np.asarray(Rs[c], float)
    Rc = cv2.Rodrigues(Rc.reshape(3))[0] if Rc.size == 3 else Rc.reshape(3, 3)
    Tc = np.asarray(Ts[c], float).reshape(3)
    sq = []
    for f in np.flatnonzero(det.found[:, c]):
        if rvecs0[f] is None or np.size(rvecs0[f]) != 3:
            continue
        Rb = cv2.Rodrigues(np.asarray(rvecs0[f], float).reshape(3))[0]
        tb = np.asarray(tvecs0[f], float).reshape(3)
        Xc = (obj @ Rb.T + tb) @ Rc.T + Tc
        px, _ = cv2.projectPoints(Xc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.distortion)
        sq.append(np.sum((px.reshape(-1, 2) - det.corners[f, c]) ** 2, axis=1))
    return float(np.sqrt(np.mean(np.concatenate(sq)))) if sq else float("nan")
