"""Stereo step of a session: calibrate the rig, profile the surface, track it in 3D.

Every intermediate result goes into the experiment file (rig, profile, surface track), so
each step can be re-run or inspected on its own (``skinkit vision ...`` does the same from
the command line).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from skinkit import registry
from skinkit.schemas import ImageSequence, SurfaceProfile, SurfaceTrack
from skinkit.store import open_experiment

Progress = Callable[[str, float], None]


def _quiet(step: str, fraction: float) -> None:
    pass


def calibrate_profile_track(path: Path, boards: ImageSequence, skin: ImageSequence,
                            board_inner: tuple[int, int], square_m: float,
                            profiler: str = "patchwork", tracker: str = "gn",
                            progress: Progress = _quiet,
                            ) -> tuple[dict[str, Any], SurfaceProfile, SurfaceTrack]:
    """Store ``boards`` and ``skin`` in experiment ``path``, calibrate the rig from the board
    views (``board_inner`` inner corners, ``square_m`` [m]), profile frame 0 of ``skin`` with
    the ``profiler`` plugin and track the profile through ``skin`` with the ``tracker``
    plugin. Returns a summary, the profile and the track (calibrated world frame, [m])."""
    from skinkit.vision.calibration import calibrate
    from skinkit.vision.tracking3d import track_3d

    with open_experiment(path, "a") as exp:
        exp.write_images(boards)
        exp.write_images(skin)
    progress("calibrate rig", 0.0)
    cal = calibrate(boards.frames, board_inner, square_m, camera_names=list(boards.camera_names))
    with open_experiment(path, "a") as exp:
        exp.write_rig(cal.rig)
    progress("calibrate rig", 1.0)
    progress("profile surface", 0.0)
    profile = registry.create("skinkit.profilers", profiler).profile(skin, cal.rig, frame=0)
    with open_experiment(path, "a") as exp:
        exp.write_profile("undeformed", profile)
    progress("profile surface", 1.0)
    progress("track surface in 3D", 0.0)
    track, _ = track_3d(cal.rig, skin, profile.points, registry.create("skinkit.trackers", tracker), 41)
    with open_experiment(path, "a") as exp:
        exp.write_track(skin.name, track)
    progress("track surface in 3D", 1.0)
    summary = {
        "reprojection_rms_px": float(cal.rms_px),
        "per_camera_rms_px": [float(v) for v in cal.per_camera_rms_px],
        "profile_points": profile.n_points,
        "mean_isu_px": None if profile.uncertainty_px is None else float(np.mean(profile.uncertainty_px)),
        "tracked_fraction": float(track.valid.all(axis=1).mean()),
        "profiler": profiler, "tracker": tracker,
    }
    return summary, profile, track


def missing_plugins(profiler: str = "patchwork", tracker: str = "gn") -> list[str]:
    """The plugins this step needs that are not installed."""
    wanted = [("skinkit.profilers", profiler), ("skinkit.trackers", tracker)]
    return [f"{group}:{name}" for group, name in wanted if name not in registry.names(group)]
