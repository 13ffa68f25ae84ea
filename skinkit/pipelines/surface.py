"""The stereo steps of a session, from its images alone: calibrate, profile, register, track.

Reads the experiment file's image sequences and writes back what it finds, each result as the
rest of skinkit reads it:

1. the rig, calibrated from the checkerboard views ``"calibration"`` (the first placement lies
   flat and defines the calibrated world frame);
2. the undeformed surface profile ``"undeformed"``, measured by the profiler plugin on the first
   frame of ``"noise-floor"`` (two frames of the skin at rest) and put in the skin frame;
3. per protocol with images, the track of the material points the identification follows —
   a square grid from 1 mm outside the probe's rim out to ``outer_m``, seeded on the measured
   profile — with its noise level ``noise_m`` per axis, measured as a lab measures it: the
   apparent motion between the two rest frames; and each position's standard error, which
   rises above that floor where the cameras' views disagree under deformation
   (:func:`skinkit.vision.tracking3d.position_uncertainty`).

The skin frame (probe axis at the origin, z out of the skin) is the calibrated frame shifted by
the first board's origin ``board_origin_m`` (where the lab placed it: centred on the probe).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from skinkit import registry
from skinkit.errors import SkinkitError
from skinkit.schemas import SurfaceProfile, SurfaceTrack
from skinkit.store import open_experiment

Progress = Callable[[str, float], None]
#: subset size [px] of the tracker (about 2.7 mm of skin at the rig's 9 px/mm): small enough that
#: the affine subset follows the steep field near the probe, large enough for a noise floor
#: well below a micrometre
SUBSET_PX = 25
NOISE_SEQUENCE = "noise-floor"
CALIBRATION_SEQUENCE = "calibration"


def _quiet(step: str, fraction: float) -> None:
    pass


def tracked_points(profile: SurfaceProfile, probe_radius_m: float, outer_m: float,
                   clearance_m: float = 1e-3) -> np.ndarray:
    """``(P, 3)`` [m] material points (skin frame) to track: the profile's own points from
    ``clearance_m`` outside the probe's rim out to ``outer_m``. Profile points were matched
    across the cameras, so each camera's subset around one is the same patch of skin; a point
    placed off the surface (by interpolating the profile) would be a different patch in each
    camera, and its track would carry that parallax as a constant error."""
    r = np.hypot(profile.points[:, 0], profile.points[:, 1])
    keep = (r >= probe_radius_m + clearance_m - 1e-12) & (r <= outer_m + 1e-12)
    if keep.sum() < 10:
        inner = probe_radius_m + clearance_m
        raise SkinkitError(f"the profile has only {int(keep.sum())} points between {inner:g} "
                           f"and {outer_m:g} m from the probe's axis: too few to track")
    return profile.points[keep]


def pixel_footprint_m(rig: Any, points: np.ndarray) -> float:
    """Mean side [m] of the skin one pixel sees at ``points`` ``(P, 3)`` [m] (world frame), over
    the rig's cameras: a subset of ``n`` pixels averages over about ``n`` times that."""
    from skinkit.vision import camera as cam_ops

    h = 1e-4
    sides = []
    for cam in rig.cameras:
        a = cam_ops.project(cam, points)
        jx = (cam_ops.project(cam, points + [h, 0.0, 0.0]) - a) / h
        jy = (cam_ops.project(cam, points + [0.0, h, 0.0]) - a) / h
        det = np.abs(jx[:, 0] * jy[:, 1] - jx[:, 1] * jy[:, 0])
        sides.append(1.0 / np.sqrt(det))
    return float(np.mean(sides))


def measure_surface(path: str | Path, board_inner: tuple[int, int], square_m: float,
                    board_origin_m: np.ndarray, probe_radius_m: float, outer_m: float = 8e-3,
                    profiler: str = "patchwork", tracker: str = "gn", subset_px: int = SUBSET_PX,
                    progress: Progress = _quiet) -> dict[str, Any]:
    """Run the stereo steps on experiment file ``path`` (module docstring); returns a summary.

    ``board_inner`` (columns, rows) inner corners of ``square_m`` [m]; ``board_origin_m``
    ``(3,)`` [m]: the flat first board's origin in the skin frame; ``probe_radius_m`` [m];
    ``outer_m`` [m]: how far from the probe's axis points are tracked.
    """
    from skinkit.vision.calibration import calibrate
    from skinkit.vision.tracking3d import track_3d

    origin = np.asarray(board_origin_m, dtype=float)
    with open_experiment(path) as exp:
        names = exp.image_names()
        for need in (CALIBRATION_SEQUENCE, NOISE_SEQUENCE):
            if need not in names:
                raise SkinkitError(f"{path}: no image sequence {need!r} (have: {', '.join(names) or 'none'})")
        boards = exp.read_images(CALIBRATION_SEQUENCE)
        rest = exp.read_images(NOISE_SEQUENCE)
        protocols = [n for n in exp.record_names() if n in names]
    progress("calibrate rig", 0.0)
    cal = calibrate(boards.frames, board_inner, square_m, camera_names=list(boards.camera_names))
    with open_experiment(path, "a") as exp:
        exp.write_rig(cal.rig)
        # the calibration's residuals beside the rig, under the name `skinkit vision calibrate`
        # gives them, so that the session report shows them (the rig holds no residuals)
        exp.write_calibration("rig", {
            "images": CALIBRATION_SEQUENCE, "board_inner": [int(n) for n in board_inner],
            "square_mm": float(square_m) * 1e3,
            "rms_px": float(cal.rms_px), "per_camera_rms_px": [float(x) for x in cal.per_camera_rms_px],
            "views": [int(v) for v in cal.detections.found.sum(axis=0)]})
    progress("calibrate rig", 1.0)

    progress("profile surface", 0.0)
    measured = registry.create("skinkit.profilers", profiler).profile(rest, cal.rig, frame=0)
    profile = SurfaceProfile(measured.points + origin, measured.quality, measured.uncertainty_px,
                             measured.quality_name)
    with open_experiment(path, "a") as exp:
        exp.write_profile("undeformed", profile)
    progress("profile surface", 1.0)

    ref_skin = tracked_points(profile, probe_radius_m, outer_m)
    ref_cal = ref_skin - origin
    trk = registry.create("skinkit.trackers", tracker)
    progress("tracking noise floor", 0.0)
    pair, _ = track_3d(cal.rig, rest, ref_cal, trk, subset_px)
    ok = pair.valid.all(axis=1)
    if ok.sum() < 10:
        raise SkinkitError(f"only {int(ok.sum())} of {len(ref_cal)} points could be tracked between the "
                           "rest frames")
    # one position's noise: the rest pair's apparent motion is the difference of two readings
    noise = np.std(pair.points[ok, 1] - pair.points[ok, 0], axis=0) / math.sqrt(2.0)
    progress("tracking noise floor", 1.0)

    window = subset_px * pixel_footprint_m(cal.rig, ref_cal)
    tracked: dict[str, Any] = {}
    for k, name in enumerate(protocols):
        progress("track surface in 3D", k / max(len(protocols), 1))
        with open_experiment(path) as exp:
            seq = exp.read_images(name)
        track, reproj = track_3d(cal.rig, seq, ref_cal, trk, subset_px, noise_floor_m=noise)
        pts = np.where(track.valid[..., None], track.points + origin, np.nan)
        out = SurfaceTrack(pts, track.valid, seq.time_s, uncertainty_m=track.uncertainty_m)
        with open_experiment(path, "a") as exp:
            exp.write_track(name, out)
            exp.set_track_attrs(name, noise_m=[float(v) for v in noise], dimensions=3,
                                tracker=tracker, subset_px=subset_px, window_m=window)
        tracked[name] = {"points": int(len(ref_cal)), "frames": int(seq.time_s.size),
                         "tracked_fraction": float(track.valid.mean()),
                         "reprojection_rms_px": float(np.sqrt(np.nanmean(reproj[track.valid] ** 2))),
                         "uncertainty_rms_m": [float(v) for v in np.sqrt(
                             np.mean(track.uncertainty_m[track.valid] ** 2, axis=0))]}
    progress("track surface in 3D", 1.0)
    return {"reprojection_rms_px": float(cal.rms_px), "profile_points": int(profile.n_points),
            "mean_isu_px": (None if measured.uncertainty_px is None
                            else float(np.mean(measured.uncertainty_px))),
            "tracked_points": int(len(ref_cal)), "noise_m": [float(v) for v in noise],
            "window_m": window,
            "protocols": tracked, "profiler": profiler, "tracker": tracker}


__all__ = ["measure_surface", "pixel_footprint_m", "tracked_points"]
