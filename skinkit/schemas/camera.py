"""Camera models (OpenCV pinhole + distortion) and a rig of cameras in one world frame."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from skinkit.errors import SchemaError
from skinkit.schemas._fields import as_array

_DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)  # the lengths OpenCV accepts


@dataclass
class CameraModel:
    """One calibrated camera, OpenCV conventions: ``x_cam = R @ X_world + t``.

    Attributes:
        name: camera name, unique within a rig.
        K: ``(3, 3)`` intrinsic matrix [px].
        distortion: ``(k,)`` OpenCV distortion coefficients, k in 0, 4, 5, 8, 12, 14 [1].
        R: ``(3, 3)`` rotation world -> camera, orthonormal with det +1 [1].
        t: ``(3,)`` translation world -> camera [m].
        image_size: ``(width, height)`` [px].
    """

    name: str
    K: Any
    distortion: Any
    R: Any
    t: Any
    image_size: tuple[int, int]

    def __post_init__(self) -> None:
        f = f"CameraModel[{self.name!r}]"
        if not isinstance(self.name, str) or not self.name or "/" in self.name:
            raise SchemaError(f"{f}.name", "must be a non-empty string without '/'")
        dims: dict[str, int] = {}
        self.K = as_array(self.K, f"{f}.K", (3, 3), "px", dims, finite=True)
        if self.K[0, 0] <= 0 or self.K[1, 1] <= 0 or not np.allclose(self.K[2], [0, 0, 1]):
            raise SchemaError(f"{f}.K", "must have positive focal lengths and last row (0, 0, 1)")
        self.distortion = as_array(np.ravel(self.distortion), f"{f}.distortion", ("k",), "1", dims,
                                   finite=True)
        if dims["k"] not in _DISTORTION_LENGTHS:
            raise SchemaError(f"{f}.distortion", f"length {dims['k']} is not one of {_DISTORTION_LENGTHS}")
        self.R = as_array(self.R, f"{f}.R", (3, 3), "1", dims, finite=True)
        if not np.allclose(self.R @ self.R.T, np.eye(3), atol=1e-6) or np.linalg.det(self.R) < 0:
            raise SchemaError(f"{f}.R", "is not a rotation (orthonormal with determinant +1)")
        self.t = as_array(np.ravel(self.t), f"{f}.t", (3,), "m", dims, finite=True)
        size = tuple(int(s) for s in self.image_size)
        if len(size) != 2 or min(size) <= 0:
            raise SchemaError(f"{f}.image_size", f"must be (width, height) > 0, got {self.image_size!r}")
        self.image_size = size  # type: ignore[assignment]

    @property
    def P(self) -> np.ndarray:
        """``(3, 4)`` projection matrix ``K [R | t]``."""
        return self.K @ np.hstack([self.R, self.t[:, None]])

    @property
    def centre(self) -> np.ndarray:
        """``(3,)`` camera centre in the world frame [m]."""
        return -self.R.T @ self.t


@dataclass
class CameraRig:
    """N cameras in one world frame. Index by position or by name."""

    cameras: tuple[CameraModel, ...]

    def __post_init__(self) -> None:
        self.cameras = tuple(self.cameras)
        if not self.cameras:
            raise SchemaError("CameraRig.cameras", "a rig needs at least one camera")
        for c in self.cameras:
            if not isinstance(c, CameraModel):
                raise SchemaError("CameraRig.cameras", f"holds a {type(c).__name__}, not a CameraModel")
        names = [c.name for c in self.cameras]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise SchemaError("CameraRig.cameras", f"duplicate camera name(s) {sorted(dup)}")

    @property
    def names(self) -> list[str]:
        """The cameras' names, in rig order."""
        return [c.name for c in self.cameras]

    def __len__(self) -> int:
        return len(self.cameras)

    def __getitem__(self, key: int | str) -> CameraModel:
        if isinstance(key, str):
            for c in self.cameras:
                if c.name == key:
                    return c
            raise KeyError(f"camera {key!r} is not in the rig (cameras: {self.names})")
        return self.cameras[key]
