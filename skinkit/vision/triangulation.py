"""Triangulation of points seen by any subset of >= 2 cameras, with reprojection errors."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skinkit.schemas import CameraRig
from skinkit.vision import VisionError
from skinkit.vision import camera as cam_ops


@dataclass
class Triangulated:
    """``points`` ``(N, 3)`` [m] (NaN where fewer than 2 views); ``reprojection_px`` ``(N,)``
    RMS reprojection error over the views used [px]; ``n_views`` ``(N,)``; ``valid`` ``(N,)``;
    ``sigma_m`` ``(N, 3)`` [m]: each coordinate's standard error from the views' disagreement
    (see :func:`triangulate`), NaN with fewer than 2 views."""

    points: np.ndarray
    reprojection_px: np.ndarray
    n_views: np.ndarray
    valid: np.ndarray
    sigma_m: np.ndarray | None = None


def triangulate(rig: CameraRig, pixels: np.ndarray, iterations: int = 5) -> Triangulated:
    """Triangulate ``pixels`` ``(N, C, 2)`` (NaN where camera ``c`` does not see point ``n``).

    Linear (DLT) solution on undistorted normalised coordinates, refined by Gauss-Newton on
    the normalised reprojection error (each view weighted by its focal length, so the cost
    is in pixels).

    ``sigma_m`` is the a-posteriori standard error of least squares (Hartley & Zisserman,
    *Multiple View Geometry*, 2nd ed., ch. 5): s² (JᵀJ)⁻¹ with s² = Σ r² / (2n − 3) over the
    n views' 2n pixel residuals, so it grows where the views disagree — e.g. where a subset
    tracker misreads a steep deformation differently in each camera. It sees no error the
    views share.
    """
    px = np.asarray(pixels, dtype=float)
    C = len(rig)
    if px.ndim != 3 or px.shape[1:] != (C, 2):
        raise VisionError(f"pixels: expected shape (N, {C}, 2) for a rig of {C} cameras, got {px.shape}")
    N = px.shape[0]
    seen = np.all(np.isfinite(px), axis=2)  # (N, C)
    xn = np.full_like(px, np.nan)
    for c, cam in enumerate(rig.cameras):
        if np.any(seen[:, c]):
            xn[seen[:, c], c] = cam_ops.undistort(cam, px[seen[:, c], c])
    Ps = np.stack([np.hstack([cam.R, cam.t[:, None]]) for cam in rig.cameras])  # (C, 3, 4)
    fs = np.array([0.5 * (cam.K[0, 0] + cam.K[1, 1]) for cam in rig.cameras])
    w = np.where(seen, 1.0, 0.0)
    xs = np.nan_to_num(xn)
    A = np.concatenate([
        w[:, :, None] * (xs[:, :, 0:1] * Ps[None, :, 2, :] - Ps[None, :, 0, :]),
        w[:, :, None] * (xs[:, :, 1:2] * Ps[None, :, 2, :] - Ps[None, :, 1, :]),
    ], axis=1)  # (N, 2C, 4)
    n_views = seen.sum(axis=1)
    ok = n_views >= 2
    X = np.full((N, 3), np.nan)
    if np.any(ok):
        _, _, vt = np.linalg.svd(A[ok])
        h = vt[:, -1, :]
        X[ok] = h[:, :3] / h[:, 3:4]
    R = Ps[:, :, :3]
    t = Ps[:, :, 3]
    for _ in range(iterations):
        if not np.any(ok):
            break
        Xo = X[ok]
        rf, Jf = _linearised(R, t, fs, w[ok], xs[ok], Xo)
        H = np.einsum("nki,nkj->nij", Jf, Jf)
        g = np.einsum("nki,nk->ni", Jf, rf)
        step = np.linalg.solve(H, g[:, :, None])[:, :, 0]
        X[ok] = Xo - step
        if np.max(np.abs(step)) < 1e-12:
            break
    sigma = np.full((N, 3), np.nan)
    if np.any(ok):
        sigma[ok] = _standard_errors(R, t, fs, w[ok], xs[ok], X[ok], n_views[ok])
    err = np.full(N, np.nan)
    if np.any(ok):
        sq = np.zeros(N)
        for c, cam in enumerate(rig.cameras):
            m = ok & seen[:, c]
            if np.any(m):
                sq[m] += np.sum((cam_ops.project(cam, X[m]) - px[m, c]) ** 2, axis=1)
        err[ok] = np.sqrt(sq[ok] / n_views[ok])
    return Triangulated(X, err, n_views, ok & np.all(np.isfinite(X), axis=1), sigma)


def _linearised(R: np.ndarray, t: np.ndarray, fs: np.ndarray, w: np.ndarray, xs: np.ndarray,
                X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reprojection residuals ``(n, 2C)`` [px] of points ``X`` ``(n, 3)`` [m] against the
    normalised views ``xs`` (weight ``w``, focal lengths ``fs``) and their Jacobian ``(n, 2C, 3)``
    [px/m]."""
    Xc = np.einsum("cij,nj->nci", R, X) + t[None]  # (n, C, 3)
    z = Xc[:, :, 2]
    pred = Xc[:, :, :2] / z[:, :, None]
    r = (pred - xs) * (w * fs)[:, :, None]  # (n, C, 2) in px
    # d(pred)/dX = (R[:2] - pred R[2]) / z
    J = (R[None, :, :2, :] - pred[:, :, :, None] * R[None, :, 2:3, :]) / z[:, :, None, None]
    J = J * (w * fs)[:, :, None, None]
    return r.reshape(len(X), -1), J.reshape(len(X), -1, 3)


def _standard_errors(R: np.ndarray, t: np.ndarray, fs: np.ndarray, w: np.ndarray, xs: np.ndarray,
                     X: np.ndarray, n_views: np.ndarray) -> np.ndarray:
    """``(n, 3)`` [m] per-coordinate standard errors of triangulated ``X`` ``(n, 3)``: the
    residual variance per pixel coordinate times the diagonal of (JᵀJ)⁻¹ [m²/px²]."""
    rf, Jf = _linearised(R, t, fs, w, xs, X)
    H = np.einsum("nki,nkj->nij", Jf, Jf)
    s2 = np.sum(rf ** 2, axis=1) / (2 * n_views - 3)
    diag = np.diagonal(np.linalg.inv(H), axis1=1, axis2=2)
    return np.sqrt(s2[:, None] * diag)
