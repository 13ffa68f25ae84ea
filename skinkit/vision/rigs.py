"""Camera rigs like the thesis stereoscope (thesis 5.1): cameras on a ring, looking inwards."""

from __future__ import annotations

import numpy as np

from skinkit.schemas import CameraModel, CameraRig


def look_at(centre: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Rotation world -> camera for a camera at ``centre`` looking at ``target`` (y down in the image)."""
    z = np.asarray(target, float) - np.asarray(centre, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.vstack([x, y, z])


def ring_rig(n: int = 4, ring_diameter_m: float = 0.125, inclination_deg: float = 55.0,
             image_size: tuple[int, int] = (480, 384), focal_px: float = 1100.0,
             distortion: np.ndarray | None = None, target: np.ndarray = (0.0, 0.0, 0.0),
             azimuth0_deg: float = 45.0) -> CameraRig:
    """``n`` cameras evenly spaced on a horizontal ring of ``ring_diameter_m`` [m], each tilted
    ``inclination_deg`` [deg] from horizontal and aimed at ``target`` [m] (the skin at z = 0,
    z up). Defaults: the thesis's four cameras, 55 deg, 125 mm ring; a small sensor so that
    ~40 mm of skin fills the image. ``distortion``: ``(n, 5)`` or ``(5,)`` coefficients.
    """
    r = ring_diameter_m / 2
    height = r * np.tan(np.deg2rad(inclination_deg))
    w, h = image_size
    K = np.array([[focal_px, 0, (w - 1) / 2], [0, focal_px, (h - 1) / 2], [0, 0, 1.0]])
    dist = np.zeros((n, 5)) if distortion is None else np.broadcast_to(np.asarray(distortion, float), (n, 5))
    cams = []
    tgt = np.asarray(target, float)
    for i in range(n):
        phi = np.deg2rad(azimuth0_deg) + 2 * np.pi * i / n
        c = tgt + np.array([r * np.cos(phi), r * np.sin(phi), height])
        R = look_at(c, tgt)
        cams.append(CameraModel(f"cam{i}", K.copy(), dist[i].copy(), R, -R @ c, (w, h)))
    return CameraRig(tuple(cams))
