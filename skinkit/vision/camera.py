"""Projection and back-projection through a :class:`skinkit.schemas.CameraModel` (OpenCV model)."""

from __future__ import annotations

import cv2
import numpy as np

from skinkit.schemas import CameraModel
from skinkit.vision import VisionError

_ZERO = np.zeros(3)


def _points3(X: np.ndarray, name: str = "points") -> np.ndarray:
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] != 3:
        raise VisionError(f"{name}: expected an (N, 3) array of positions [m], got shape {X.shape}")
    return X


def to_camera(cam: CameraModel, X: np.ndarray) -> np.ndarray:
    """``(N, 3)`` world points [m] in the camera frame [m]."""
    return _points3(X) @ cam.R.T + cam.t


def project(cam: CameraModel, X: np.ndarray) -> np.ndarray:
    """``(N, 2)`` pixel positions of ``(N, 3)`` world points [m], lens distortion included.

    Points behind the camera come out as NaN.
    """
    Xc = to_camera(cam, X)
    return project_camera_frame(cam, Xc)


def project_camera_frame(cam: CameraModel, Xc: np.ndarray) -> np.ndarray:
    """``(N, 2)`` pixels of ``(N, 3)`` points given in the camera frame [m]."""
    Xc = np.asarray(Xc, dtype=float)
    out = np.full((len(Xc), 2), np.nan)
    front = Xc[:, 2] > 0
    if np.any(front):
        px, _ = cv2.projectPoints(Xc[front].reshape(-1, 1, 3), _ZERO, _ZERO, cam.K, cam.distortion)
        out[front] = px.reshape(-1, 2)
    return out


def normalized_to_pixels(cam: CameraModel, xn: np.ndarray) -> np.ndarray:
    """``(N, 2)`` ideal normalised coordinates ``(X/Z, Y/Z)`` -> distorted pixels."""
    xn = np.asarray(xn, dtype=float)
    return project_camera_frame(cam, np.column_stack([xn, np.ones(len(xn))]))


def undistort(cam: CameraModel, px: np.ndarray, tol: float = 1e-12, iterations: int = 100) -> np.ndarray:
    """``(N, 2)`` distorted pixels -> ideal normalised coordinates ``(X/Z, Y/Z)``.

    OpenCV's fixed-point inversion, then Newton steps on the forward model so that
    re-distorting returns the input pixels to ``~1e-9`` px.
    """
    px = np.asarray(px, dtype=float).reshape(-1, 2)
    if len(px) == 0:
        return np.zeros((0, 2))
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, tol)
    xn = cv2.undistortPoints(px.reshape(-1, 1, 2), cam.K, cam.distortion, None, None, None, crit)
    xn = xn.reshape(-1, 2)
    if not np.any(cam.distortion):
        return xn
    eps = 1e-7
    for _ in range(3):
        r = normalized_to_pixels(cam, xn) - px
        if np.nanmax(np.abs(r)) < 1e-9:
            break
        jx = (normalized_to_pixels(cam, xn + [eps, 0]) - px - r) / eps
        jy = (normalized_to_pixels(cam, xn + [0, eps]) - px - r) / eps
        det = jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1]
        dx = (jy[:, 1] * r[:, 0] - jy[:, 0] * r[:, 1]) / det
        dy = (-jx[:, 1] * r[:, 0] + jx[:, 0] * r[:, 1]) / det
        xn = xn - np.column_stack([dx, dy])
    return xn


def rays(cam: CameraModel, px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World rays through pixels: origin ``(3,)`` (camera centre) and ``(N, 3)`` unit directions."""
    xn = undistort(cam, px)
    d_cam = np.column_stack([xn, np.ones(len(xn))])
    d = d_cam @ cam.R  # R^T applied to row vectors
    return cam.centre, d / np.linalg.norm(d, axis=1, keepdims=True)


def pixel_grid(image_size: tuple[int, int], supersample: int = 1) -> np.ndarray:
    """``(H * W * s^2, 2)`` pixel sample positions, ``s x s`` per pixel, row-major by pixel."""
    w, h = image_size
    s = int(supersample)
    offs = (np.arange(s) + 0.5) / s - 0.5
    y, x = np.mgrid[0:h, 0:w].astype(float)
    ox, oy = np.meshgrid(offs, offs)
    pts = np.stack([x[..., None] + ox.ravel(), y[..., None] + oy.ravel()], axis=-1)
    return pts.reshape(-1, 2)
