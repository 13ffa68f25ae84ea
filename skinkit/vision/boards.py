"""Checkerboard detection with orientation checks, and rendered board views for tests."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from skinkit.vision import VisionError
from skinkit.vision.scene import Board, CharucoTarget

#: image-plane handedness of a board seen from its printed (+z) face: with the image y axis
#: pointing down, board x -> (1, 0) and y -> (0, -1) for a camera looking along -z.
FRONT_HANDEDNESS = -1.0


def check_board(inner: tuple[int, int], symmetric_ok: bool = False) -> None:
    """Refuse a board whose pattern looks the same after a half turn.

    A board of ``(cols, rows)`` inner corners has ``(cols + 1) x (rows + 1)`` squares; when
    ``cols + rows`` is even the 180-degree rotation maps black squares onto black squares,
    so the corner order (and hence the camera poses) cannot be told apart from one image.
    ``symmetric_ok``: accept such a board (a rig calibration resolves the half turn with the
    cameras' geometry, :mod:`skinkit.vision.board_symmetry`); a square board (also symmetric
    under a quarter turn) is always refused.
    """
    c, r = (int(v) for v in inner)
    if c < 3 or r < 3:
        raise VisionError(f"board of {c}x{r} inner corners is too small (need at least 3x3)")
    if c == r:
        raise VisionError(f"board of {c}x{r} inner corners is symmetric under a quarter turn "
                          "(square): its corner order is ambiguous; use a board with unequal counts")
    if (c + r) % 2 == 0 and not symmetric_ok:
        raise VisionError(f"board of {c}x{r} inner corners is symmetric under a half turn "
                          "(columns + rows is even): its corner order is ambiguous; use a board "
                          "with one even and one odd count, e.g. 9x6")


def _first_square_is_dark(image: np.ndarray, corners: np.ndarray, cols: int) -> bool | None:
    """Sample the square between inner corners 0, 1, cols and cols + 1: dark, bright or unsure."""
    quad = corners[[0, 1, cols, cols + 1]]
    c = quad.mean(axis=0)
    rad = max(1.0, 0.2 * float(np.min(np.linalg.norm(quad - c, axis=1))))
    h, w = image.shape
    ys, xs = np.mgrid[-2:3, -2:3] * rad / 2
    xx = np.clip(np.rint(c[0] + xs).astype(int), 0, w - 1)
    yy = np.clip(np.rint(c[1] + ys).astype(int), 0, h - 1)
    inside = float(np.median(image[yy, xx]))
    # Compare with the neighbouring square along the first row (opposite colour).
    quad2 = corners[[1, 2, cols + 1, cols + 2]] if cols > 2 else quad
    c2 = quad2.mean(axis=0)
    xx2 = np.clip(np.rint(c2[0] + xs).astype(int), 0, w - 1)
    yy2 = np.clip(np.rint(c2[1] + ys).astype(int), 0, h - 1)
    other = float(np.median(image[yy2, xx2]))
    lo, hi = float(np.percentile(image, 5)), float(np.percentile(image, 95))
    if abs(inside - other) < 0.25 * (hi - lo):
        return None
    return inside < other


def detect_board(image: np.ndarray, inner: tuple[int, int],
                 symmetric_ok: bool = False) -> np.ndarray | None:
    """``(cols * rows, 2)`` inner corners [px] in board order, or None when not found.

    The order is fixed geometrically: the board's x (along a row) and y (down the columns)
    axes with z towards the camera form a right-handed frame (the printed face is seen), and
    corner 0 is the corner whose first inner square (between corners 0, 1, cols, cols + 1)
    is dark, as on :class:`skinkit.vision.scene.Board`.
    Raises :class:`VisionError` when the colour cannot tell the order.
    A symmetric board (``symmetric_ok``, see :func:`check_board`) is returned in either of its
    two orders: the colours cannot tell them apart.
    """
    check_board(inner, symmetric_ok)
    img = np.asarray(image)
    if img.dtype != np.uint8:
        img = cv2.normalize(img.astype(np.float32), None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    ok, corners = cv2.findChessboardCornersSB(img, tuple(int(v) for v in inner),
                                              cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if not ok or corners is None:
        return None
    cols, rows = int(inner[0]), int(inner[1])
    # The sector-based detector can be off by tenths of a pixel on steep views; the
    # gradient-orthogonality refinement brings every corner to ~0.1 px on rendered boards.
    grid = corners.reshape(rows, cols, 2)
    pitch = min(float(np.min(np.linalg.norm(np.diff(grid, axis=0), axis=2))),
                float(np.min(np.linalg.norm(np.diff(grid, axis=1), axis=2))))
    half = int(np.clip(np.floor(0.3 * pitch), 2, 6))
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
    corners = cv2.cornerSubPix(img, corners.reshape(-1, 1, 2).astype(np.float32), (half, half),
                               (-1, -1), crit)
    corners = corners.reshape(-1, 2).astype(np.float64)
    if handedness(corners, cols) != FRONT_HANDEDNESS:
        # Mirrored order: reverse each row so the board's x, y, z frame is right-handed
        # with z towards the camera (the printed face).
        corners = corners.reshape(rows, cols, 2)[:, ::-1].reshape(-1, 2).copy()
    if (cols + rows) % 2 == 0:
        return corners
    dark = _first_square_is_dark(img.astype(float), corners, int(inner[0]))
    if dark is None:
        raise VisionError("board corners found but the square colours cannot fix their order "
                          "(low contrast or a board that does not match the given size)")
    if not dark:
        corners = corners[::-1].copy()
    return corners


def handedness(corners: np.ndarray, cols: int) -> float:
    """Sign of the image-plane cross product of the board's x and y directions."""
    ex = corners[1] - corners[0]
    ey = corners[cols] - corners[0]
    return float(np.sign(ex[0] * ey[1] - ex[1] * ey[0]))


def detect_charuco(image: np.ndarray, target: CharucoTarget) -> np.ndarray:
    """``(P, 2)`` ChArUco chessboard corners [px] in id order, NaN where not detected.

    Marker ids make the order unambiguous, and a partly visible board still counts.
    """
    img = np.asarray(image)
    if img.dtype != np.uint8:
        img = cv2.normalize(img.astype(np.float32), None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    board = target.cv_board()
    det = cv2.aruco.CharucoDetector(board)
    corners, ids, _, _ = det.detectBoard(img)
    out = np.full((len(target.object_points()), 2), np.nan)
    if ids is not None and len(ids):
        out[np.asarray(ids).ravel()] = np.asarray(corners, float).reshape(-1, 2)
    return out


def random_board_poses(n: int, rng: np.random.Generator, board: Board | CharucoTarget,
                       tilt_deg: float = 25.0, shift_m: float = 0.006,
                       lift_m: tuple[float, float] = (0.0, 0.012)) -> list:
    """``n`` placements of ``board`` around the origin, printed face up; the first lies
    flat and centred (it defines the calibrated world frame)."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    if isinstance(board, CharucoTarget):
        c, r = board.squares
        centre_local = np.array([c / 2, r / 2, 0.0]) * board.square_m
        face = np.diag([1.0, -1.0, -1.0])  # OpenCV's ChArUco is printed on its -z side
    else:
        c, r = board.inner
        centre_local = np.array([(c - 1) / 2, (r - 1) / 2, 0.0]) * board.square_m
        face = np.eye(3)
    out = []
    for k in range(n):
        if k == 0:
            R = np.eye(3)
            centre = np.zeros(3)
        else:
            spin = Rotation.from_euler("z", rng.uniform(-30, 30), degrees=True)
            axis = rng.normal(size=3)
            axis[2] = 0
            axis /= np.linalg.norm(axis)
            tilt = Rotation.from_rotvec(axis * np.deg2rad(rng.uniform(8, tilt_deg)))
            R = (tilt * spin).as_matrix()
            centre = np.array([*rng.uniform(-shift_m, shift_m, 2), rng.uniform(*lift_m)])
        R = R @ face
        out.append(replace(board, R=R, t=centre - R @ centre_local))
    return out


def board_views(rig: object, boards: Sequence[Board], sensor: object, seed: int,
                supersample: int = 2) -> np.ndarray:
    """``(F, C, H, W)`` uint images of each board placement seen by each camera of ``rig``."""
    from skinkit.vision.scene import render_view

    rng = np.random.default_rng(seed)
    cams = rig.cameras  # type: ignore[attr-defined]
    w, h = cams[0].image_size
    out = None
    for f, b in enumerate(boards):
        for c, cam in enumerate(cams):
            img = render_view(cam, [b], sensor, rng, supersample)  # type: ignore[arg-type]
            if out is None:
                out = np.zeros((len(boards), len(cams), h, w), img.dtype)
            out[f, c] = img
    return out
