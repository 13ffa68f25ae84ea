"""The profiled skin surface and the 3D tracks of its material points."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from skinkit.errors import SchemaError
from skinkit.schemas._fields import as_array


@dataclass
class SurfaceProfile:
    """A point cloud on the undeformed surface.

    Attributes:
        points: ``(N, 3)`` positions in the rig's world frame [m], finite.
        quality: ``(N,)`` per-point quality, larger is better; the profiler states its scale
            in ``quality_name`` (the built-in profiler: peak correlation in [-1, 1]).
        uncertainty_px: ``(N,)`` integer-shift uncertainty (thesis 5.4) [px], or None.
        quality_name: what ``quality`` measures.
    """

    points: Any
    quality: Any
    uncertainty_px: Any = None
    quality_name: str = "peak_correlation"

    def __post_init__(self) -> None:
        dims: dict[str, int] = {}
        self.points = as_array(self.points, "SurfaceProfile.points", ("N", 3), "m", dims, finite=True)
        self.quality = as_array(self.quality, "SurfaceProfile.quality", ("N",), "1", dims)
        if self.uncertainty_px is not None:
            self.uncertainty_px = as_array(self.uncertainty_px, "SurfaceProfile.uncertainty_px", ("N",),
                                           "px", dims)

    @property
    def n_points(self) -> int:
        """Number of points."""
        return int(self.points.shape[0])


@dataclass
class SurfaceTrack:
    """Material points followed through a deformation.

    Attributes:
        points: ``(P, F, 3)`` positions [m]; NaN where not valid.
        valid: ``(P, F)`` bool, True where the point was tracked in that frame.
        time_s: ``(F,)`` frame times [s], non-decreasing.
        point_ids: ``(P,)`` integer ids (index into the profile), or None.
        uncertainty_m: ``(P, F, 3)`` [m] the producer's standard error of each valid position
            per axis (positive and finite where ``valid``), or None when the producer gives one
            level per axis only (the track's ``noise_m`` attribute).
    """

    points: Any
    valid: Any
    time_s: Any
    point_ids: Any = None
    uncertainty_m: Any = None

    def __post_init__(self) -> None:
        dims: dict[str, int] = {}
        self.points = as_array(self.points, "SurfaceTrack.points", ("P", "F", 3), "m", dims)
        self.valid = as_array(self.valid, "SurfaceTrack.valid", ("P", "F"), "1", dims, dtype=bool)
        if not np.all(np.isfinite(self.points[self.valid])):
            raise SchemaError("SurfaceTrack.points", "a point marked valid is not finite")
        self.time_s = as_array(self.time_s, "SurfaceTrack.time_s", ("F",), "s", dims, finite=True)
        if np.any(np.diff(self.time_s) < 0):
            raise SchemaError("SurfaceTrack.time_s", "must be non-decreasing")
        if self.point_ids is not None:
            self.point_ids = as_array(self.point_ids, "SurfaceTrack.point_ids", ("P",), "count", dims,
                                      dtype=np.int64)
        if self.uncertainty_m is not None:
            u = as_array(self.uncertainty_m, "SurfaceTrack.uncertainty_m", ("P", "F", 3), "m", dims)
            on = u[self.valid]
            if not np.all(np.isfinite(on) & (on > 0)):
                raise SchemaError("SurfaceTrack.uncertainty_m", "must be positive and finite where valid")
            self.uncertainty_m = u

    @property
    def n_points(self) -> int:
        """Number of points P."""
        return int(self.points.shape[0])

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return int(self.points.shape[1])

    def displacements(self) -> np.ndarray:
        """``(P, F, 3)`` displacement from frame 0 [m]; NaN where either frame is invalid."""
        return self.points - self.points[:, :1, :]
