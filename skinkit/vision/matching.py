"""Seed correspondences between two views: SIFT features, ratio test, epipolar check."""

from __future__ import annotations

import cv2
import numpy as np

from skinkit.schemas import CameraModel
from skinkit.vision import camera as cam_ops


def to_uint8(image: np.ndarray) -> np.ndarray:
    """A uint8 copy of a grey image, stretched to its own 0.1-99.9 % range if not uint8."""
    img = np.asarray(image)
    if img.dtype == np.uint8:
        return img
    lo, hi = np.percentile(img, [0.1, 99.9])
    return np.clip((img.astype(float) - lo) * 255.0 / max(hi - lo, 1e-12), 0, 255).astype(np.uint8)


def features(image: np.ndarray, mask: np.ndarray | None, n_features: int = 4000,
             cache: dict[int, tuple] | None = None) -> tuple:
    """SIFT keypoints and descriptors of an image (memoised in ``cache`` by object id)."""
    key = id(image)
    if cache is not None and key in cache and cache[key][0] is image:
        return cache[key][1]
    m = None if mask is None else mask.astype(np.uint8) * 255
    out = cv2.SIFT_create(nfeatures=n_features).detectAndCompute(to_uint8(image), m)
    if cache is not None:
        cache[key] = (image, out)
    return out


def epipolar_distance_px(cam_a: CameraModel, cam_b: CameraModel, px_a: np.ndarray,
                         px_b: np.ndarray) -> np.ndarray:
    """``(N,)`` Sampson distance [px] of correspondences to the rig's epipolar geometry."""
    xa = cam_ops.undistort(cam_a, px_a)
    xb = cam_ops.undistort(cam_b, px_b)
    R = cam_b.R @ cam_a.R.T
    t = cam_b.t - R @ cam_a.t
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    E = tx @ R
    ha = np.column_stack([xa, np.ones(len(xa))])
    hb = np.column_stack([xb, np.ones(len(xb))])
    Ea = ha @ E.T
    Eb = hb @ E
    num = np.sum(hb * Ea, axis=1) ** 2
    den = Ea[:, 0] ** 2 + Ea[:, 1] ** 2 + Eb[:, 0] ** 2 + Eb[:, 1] ** 2
    f = 0.5 * (cam_a.K[0, 0] + cam_b.K[0, 0])
    return np.sqrt(num / den) * f


def seed_matches(img_a: np.ndarray, img_b: np.ndarray, cam_a: CameraModel, cam_b: CameraModel,
                 mask_a: np.ndarray | None = None, mask_b: np.ndarray | None = None,
                 ratio: float = 0.8, max_epipolar_px: float = 2.0, n_features: int = 4000,
                 cache: dict[int, tuple] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(M, 2)`` and ``(M, 2)`` matched feature positions [px] in views a and b.

    ``cache``: a dict kept by the caller to reuse each image's features across pairs.
    """
    ka, da = features(img_a, mask_a, n_features, cache)
    kb, db = features(img_b, mask_b, n_features, cache)
    if da is None or db is None or len(ka) < 2 or len(kb) < 2:
        return np.zeros((0, 2)), np.zeros((0, 2))
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(da, db, k=2)
    good = [m for m, n in (p for p in pairs if len(p) == 2) if m.distance < ratio * n.distance]
    if not good:
        return np.zeros((0, 2)), np.zeros((0, 2))
    pa = np.array([ka[m.queryIdx].pt for m in good])
    pb = np.array([kb[m.trainIdx].pt for m in good])
    keep = epipolar_distance_px(cam_a, cam_b, pa, pb) <= max_epipolar_px
    return pa[keep], pb[keep]
