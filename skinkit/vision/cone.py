"""Least-squares cone fit and the indenter tip (thesis 5.3, after Forbes 1991's ``lscone``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from skinkit.vision import VisionError


@dataclass
class ConeFit:
    """``apex`` ``(3,)`` [m]; ``axis`` ``(3,)`` unit, from the apex into the cone;
    ``half_angle_rad``; ``rms_m`` RMS orthogonal distance of the points [m]; ``n_points``."""

    apex: np.ndarray
    axis: np.ndarray
    half_angle_rad: float
    rms_m: float
    n_points: int

    def tip(self, tip_length_m: float) -> np.ndarray:
        """``(3,)`` probe tip ``apex + tip_length_m * axis`` [m]."""
        return self.apex + float(tip_length_m) * self.axis


def _basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def cone_distance(points: np.ndarray, apex: np.ndarray, axis: np.ndarray, half_angle: float) -> np.ndarray:
    """Signed orthogonal distance [m] of ``(N, 3)`` points to the cone (positive outside)."""
    v = points - apex
    h = v @ axis
    r = np.linalg.norm(v - np.outer(h, axis), axis=1)
    return r * np.cos(half_angle) - h * np.sin(half_angle)


def fit_cone(points: np.ndarray, axis_guess: np.ndarray = (0.0, 0.0, -1.0),
             half_angle_guess_deg: float = 35.0, apex_guess: np.ndarray | None = None,
             trim_sigma: float = 3.0, rounds: int = 3, fixed_half_angle_deg: float | None = None,
             ) -> ConeFit:
    """Fit a right circular cone to ``(N, 3)`` surface points [m] by orthogonal least squares.

    ``axis_guess``: rough direction from the apex into the cone (for an indenter hanging
    above the skin with its cone widening downwards, ``-z``). The apex guess defaults to
    the point cloud's extreme along ``-axis_guess``. Points farther than ``trim_sigma``
    RMS distances from the fitted cone are dropped and the fit repeated (``rounds`` times):
    stereo mismatches along an epipolar line must not pull the axis.
    ``fixed_half_angle_deg``: the half angle when it is known (a lathed indenter); the
    apex then no longer trades against the angle along the axis.
    """
    P = np.asarray(points, float)
    if P.ndim != 2 or P.shape[1] != 3:
        raise VisionError(f"cone points: expected (N, 3), got shape {P.shape}")
    if len(P) < 10:
        raise VisionError(f"cone fit needs at least 10 points, got {len(P)}")
    n0 = np.asarray(axis_guess, float)
    n0 = n0 / np.linalg.norm(n0)
    e1, e2 = _basis(n0)
    if apex_guess is None:
        h = P @ n0
        top = P[h <= np.percentile(h, 2)].mean(axis=0)
        centre = P.mean(axis=0)
        # Apex on the axis through the cloud's centre, just beyond its top.
        apex_guess = centre + ((top - centre) @ n0 - 0.1 * np.ptp(h)) * n0
    x0 = np.array([*np.asarray(apex_guess, float), 0.0, 0.0, np.deg2rad(half_angle_guess_deg)])
    scale = float(np.std(P - P.mean(axis=0))) or 1.0

    fixed = None if fixed_half_angle_deg is None else np.deg2rad(float(fixed_half_angle_deg))
    if fixed is not None:
        x0 = x0[:5]

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        n = n0 + x[3] * e1 + x[4] * e2
        return x[:3], n / np.linalg.norm(n), (x[5] if fixed is None else fixed)

    keep = np.ones(len(P), bool)
    for _ in range(max(1, rounds)):
        Pk = P[keep]

        def res(x: np.ndarray, Pk: np.ndarray = Pk) -> np.ndarray:
            a, n, ang = unpack(x)
            return cone_distance(Pk, a, n, ang) / scale

        xs = np.r_[np.full(3, scale), 0.1, 0.1, 0.1][:len(x0)]
        sol = least_squares(res, x0, method="lm", x_scale=xs)
        x0 = sol.x
        a, n, ang = unpack(sol.x)
        d = np.abs(cone_distance(P, a, n, ang))
        rms_k = float(np.sqrt(np.mean(d[keep] ** 2)))
        new = d <= trim_sigma * rms_k
        if np.array_equal(new, keep) or new.sum() < 10:
            break
        keep = new
    if not 0 < ang < np.pi / 2:
        raise VisionError(f"cone fit converged to an impossible half angle {np.degrees(ang):.1f} deg")
    rms = float(np.sqrt(np.mean(cone_distance(P[keep], a, n, ang) ** 2)))
    return ConeFit(a, n, float(ang), rms, int(keep.sum()))
