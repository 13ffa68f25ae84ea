"""A synchronised image sequence from the cameras of a rig."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from skinkit.errors import SchemaError
from skinkit.schemas._fields import as_array


@dataclass
class ImageSequence:
    """Frames from C synchronised cameras.

    Attributes:
        name: sequence name (e.g. the protocol it was taken during).
        frames: ``(F, C, H, W)`` grey images, uint8, uint16 or float [counts].
        camera_names: ``(C,)`` names, matching the rig's cameras.
        time_s: ``(F,)`` trigger times on the robot clock [s], non-decreasing.
    """

    name: str
    frames: Any
    camera_names: tuple[str, ...]
    time_s: Any

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or "/" in self.name:
            raise SchemaError("ImageSequence.name", "must be a non-empty string without '/'")
        frames = np.asarray(self.frames)
        if frames.dtype not in (np.uint8, np.uint16, np.float32, np.float64):
            raise SchemaError("ImageSequence.frames", f"dtype {frames.dtype} is not uint8, uint16 or float")
        dims: dict[str, int] = {}
        self.frames = as_array(frames, "ImageSequence.frames", ("F", "C", "H", "W"), "count", dims,
                               dtype=frames.dtype)
        self.camera_names = tuple(self.camera_names)
        if len(self.camera_names) != dims["C"]:
            raise SchemaError("ImageSequence.camera_names",
                              f"{len(self.camera_names)} names for {dims['C']} cameras in frames")
        self.time_s = as_array(self.time_s, "ImageSequence.time_s", ("F",), "s", dims, finite=True)
        if np.any(np.diff(self.time_s) < 0):
            raise SchemaError("ImageSequence.time_s", "must be non-decreasing")

    @property
    def n_frames(self) -> int:
        """Number of frames."""
        return int(self.frames.shape[0])

    @property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)`` [px]."""
        return int(self.frames.shape[3]), int(self.frames.shape[2])
