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
from skinkit.vision.board_symmetry import is_symmetric, resolve_half_turns
from skinkit.vision.boards import check_board, detect_board, detect_charuco, handedness
from skinkit.vision.scene import CharucoTarget


@dataclass
class Detections:
    """Board corners found in each view.

    ``corners``: ``(F, C, P, 2)`` [px], NaN where not detected; ``found``: ``(F, C)`` bool
    (the view is usable: the whole checkerboard, or enough ChArUco corners).
    """

    corners: np.ndarray
    found: np.ndarray
    image_size: tuple[int, int]
    object_points: np.ndarray | None = None  # (P, 3) board coordinates [m] of the corners


@dataclass
class Calibration:
    """A calibrated rig and how well it explains the corners.

    Attributes:
        rig: the cameras, world frame = board frame of view ``world_view``.
        rms_px: overall RMS reprojection error [px] over the joint adjustment's views.
        per_camera_rms_px: ``(C,)`` RMS reprojection error per camera [px], same views.
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
               camera_names: Sequence[str] | None = None, symmetric_ok: bool = False) -> Detections:
    """Detect the board in ``(F, C, H, W)`` images; check corner orderings are consistent.

    ``symmetric_ok``: accept a board symmetric under a half turn, whose views then come in
    either corner order (see :func:`skinkit.vision.board_symmetry.resolve_half_turns`)."""
    check_board(inner, symmetric_ok)
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
                pts = detect_board(imgs[f, c], inner, symmetric_ok)
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


def detect_all_charuco(images: np.ndarray, target: CharucoTarget, min_corners: int = 8) -> Detections:
    """Detect a ChArUco board in ``(F, C, H, W)`` images; a view counts with ``min_corners``."""
    imgs = np.asarray(images)
    if imgs.ndim != 4:
        raise VisionError(f"calibration images: expected (frames, cameras, H, W), got shape {imgs.shape}")
    F, C, H, W = imgs.shape
    P = len(target.object_points())
    corners = np.full((F, C, P, 2), np.nan)
    for f in range(F):
        for c in range(C):
            corners[f, c] = detect_charuco(imgs[f, c], target)
    found = np.sum(np.isfinite(corners[..., 0]), axis=2) >= min_corners
    corners[~found] = np.nan
    return Detections(corners, found, (W, H), target.object_points())


def calibrate_charuco(images: np.ndarray, target: CharucoTarget,
                      camera_names: Sequence[str] | None = None, min_views: int = 4,
                      world_view: int | None = None, fix_k3: bool = True) -> Calibration:
    """:func:`calibrate` from views of a ChArUco board (partial views allowed)."""
    det = detect_all_charuco(images, target)
    return calibrate_detections(det, None, target.square_m, camera_names, min_views, world_view, fix_k3)


def calibrate(images: np.ndarray, inner: tuple[int, int], square_m: float,
              camera_names: Sequence[str] | None = None, min_views: int = 4,
              world_view: int | None = None, fix_k3: bool = True) -> Calibration:
    """Calibrate the cameras that took ``images`` ``(F, C, H, W)`` of a checkerboard.

    ``inner``: (columns, rows) of inner corners; ``square_m``: square side [m].
    A board symmetric under a half turn (``cols + rows`` even, e.g. 12 x 8) is accepted: its
    corner order is made consistent across the cameras of each frame with the rig's geometry
    (:mod:`skinkit.vision.board_symmetry`), and the world frame's corner 0 is then the one
    camera 0 labelled first.
    Raises :class:`VisionError` if any camera saw the board in fewer than ``min_views``
    frames or shares no view with another camera.
    """
    det = detect_all(images, inner, camera_names, symmetric_ok=True)
    C = det.found.shape[1]
    names = list(camera_names) if camera_names is not None else [f"cam{c}" for c in range(C)]
    if is_symmetric(inner) and len(names) == C:  # (a wrong name count is refused below)
        corners, found = resolve_half_turns(det.corners, det.found, inner, square_m, det.image_size, names)
        det = Detections(corners, found, det.image_size)
    return calibrate_detections(det, inner, square_m, camera_names, min_views, world_view, fix_k3)


def calibrate_detections(det: Detections, inner: tuple[int, int] | None, square_m: float,
                         camera_names: Sequence[str] | None = None, min_views: int = 4,
                         world_view: int | None = None, fix_k3: bool = True) -> Calibration:
    """:func:`calibrate` from corners already detected (``inner`` None: the detections
    carry their board's object points)."""
    F, C = det.found.shape
    names = list(camera_names) if camera_names is not None else [f"cam{c}" for c in range(C)]
    _check_detections(det, names, square_m, min_views)
    obj = _object_points(det, inner, square_m).astype(np.float32)
    # OpenCV 5.0's multiview calibration initialises poses badly from partly observed
    # boards, so each camera is first calibrated alone on every corner it saw (partial
    # ChArUco views included), and the joint adjustment then starts from those intrinsics
    # and uses the views where a camera saw the whole board.
    full = det.found & np.all(np.isfinite(det.corners[..., 0]), axis=2)
    counts_full = full.sum(axis=0)
    few = [f"{names[c]} ({counts_full[c]})" for c in range(C) if counts_full[c] < 2]
    if few:
        raise VisionError(f"too few views of the whole board for the joint calibration: {', '.join(few)}")
    obj_points = [obj] * F
    img_points = []
    for c in range(C):
        per = []
        for f in range(F):
            pts = det.corners[f, c] if full[f, c] else np.full((len(obj), 2), -1.0)
            per.append(pts.astype(np.float32))
        img_points.append(per)
    flag = cv2.CALIB_FIX_K3 if fix_k3 else 0
    Ks0, dists0 = _single_camera_intrinsics(det, obj, names, flag)
    if not hasattr(cv2, "calibrateMultiviewExtended"):
        raise VisionError(f"joint rig calibration needs OpenCV >= 5.0 (calibrateMultiviewExtended); "
                          f"this is OpenCV {cv2.__version__}")
    mask = full.T.astype(np.uint8)
    sizes = [det.image_size] * C
    models = np.zeros(C, np.uint8)
    flags_intr = np.full(C, flag, np.int32)
    try:
        out = cv2.calibrateMultiviewExtended(
            obj_points, img_points, sizes, mask, models, Ks0, dists0, None, None,
            flagsForIntrinsics=flags_intr, flags=cv2.CALIB_USE_INTRINSIC_GUESS)
    except cv2.error as exc:
        detail = str(exc).strip().splitlines()[-1]
        raise VisionError(f"OpenCV multiview calibration failed: {detail}") from None
    rms, Ks, dists, Rs, Ts, _pairs, rvecs0, tvecs0, per_frame = out
    if world_view is None:
        world_view = int(np.flatnonzero(full[:, 0])[0])
    if not full[world_view, 0]:
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
    rig = _z_towards_cameras(CameraRig(tuple(cams)))
    per_view = np.where(full, np.asarray(per_frame, float).T, np.nan)
    used = Detections(det.corners, full, det.image_size, det.object_points)
    per_cam = np.array([reprojection_rms(rig[c], used, c, obj, rvecs0, tvecs0, Rs, Ts)
                        for c in range(C)])
    return Calibration(rig, float(rms), per_cam, per_view, det, world_view)


def _check_detections(det: Detections, names: list[str], square_m: float, min_views: int) -> None:
    """VisionError unless there are names for every camera (at least 2), a positive square
    size, ``min_views`` detections per camera and a view shared with another camera."""
    C = det.found.shape[1]
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


def _single_camera_intrinsics(det: Detections, obj: np.ndarray, names: list[str],
                              flag: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Each camera calibrated alone on every corner it saw: ``K`` (3, 3) [px] and the
    distortion ``(1, 5)``, the starting point of the joint adjustment."""
    Ks0, dists0 = [], []
    for c in range(det.found.shape[1]):
        views = np.flatnonzero(det.found[:, c])
        seen = [np.isfinite(det.corners[f, c, :, 0]) for f in views]
        try:
            _, K, dist, _, _ = cv2.calibrateCamera(
                [obj[m] for m in seen],
                [det.corners[f, c, m].astype(np.float32) for f, m in zip(views, seen, strict=True)],
                det.image_size, None, None, flags=flag)
        except cv2.error as exc:
            detail = str(exc).strip().splitlines()[-1]
            raise VisionError(f"calibration of {names[c]} alone failed: {detail}") from None
        Ks0.append(K)
        dists0.append(dist.ravel()[:5].reshape(1, 5))
    return Ks0, dists0


def _object_points(det: Detections, inner: tuple[int, int] | None, square_m: float) -> np.ndarray:
    if inner is None:
        if det.object_points is None:
            raise VisionError("detections carry no board object points and no board size was given")
        return np.asarray(det.object_points, float)
    c0, r0 = inner
    j, i = np.mgrid[0:r0, 0:c0]
    return np.column_stack([i.ravel(), j.ravel(), np.zeros(c0 * r0)]) * square_m


def _z_towards_cameras(rig: CameraRig) -> CameraRig:
    """Turn the world half a turn about x if the cameras sit on its -z side, so that z
    points from the board (the skin) towards the cameras whatever the board's convention."""
    if np.mean([cam.centre[2] for cam in rig.cameras]) >= 0:
        return rig
    flip = np.diag([1.0, -1.0, -1.0])
    return CameraRig(tuple(CameraModel(c.name, c.K, c.distortion, c.R @ flip, c.t, c.image_size)
                           for c in rig.cameras))


def reprojection_rms(cam: CameraModel, det: Detections, c: int, obj: np.ndarray,
                     rvecs0: Sequence, tvecs0: Sequence, Rs: Sequence, Ts: Sequence) -> float:
    """RMS reprojection error [px] of camera ``c`` over the corners it saw."""
    Rc = np.asarray(Rs[c], float)
    Rc = cv2.Rodrigues(Rc.reshape(3))[0] if Rc.size == 3 else Rc.reshape(3, 3)
    Tc = np.asarray(Ts[c], float).reshape(3)
    sq = []
    for f in np.flatnonzero(det.found[:, c]):
        if rvecs0[f] is None or np.size(rvecs0[f]) != 3:
            continue
        Rb = cv2.Rodrigues(np.asarray(rvecs0[f], float).reshape(3))[0]
        tb = np.asarray(tvecs0[f], float).reshape(3)
        Xc = (np.asarray(obj, float) @ Rb.T + tb) @ Rc.T + Tc
        px, _ = cv2.projectPoints(Xc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.distortion)
        seen = np.all(np.isfinite(det.corners[f, c]), axis=1)
        sq.append(np.sum((px.reshape(-1, 2)[seen] - det.corners[f, c][seen]) ** 2, axis=1))
    return float(np.sqrt(np.mean(np.concatenate(sq)))) if sq else float("nan")
