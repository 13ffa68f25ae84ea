"""The camera rig and image sequences of an experiment file (``/rig/cameras``, ``/images`` of
:mod:`skinkit.store.layout`)."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np

from skinkit import jsonio
from skinkit.errors import SchemaError
from skinkit.schemas import CameraModel, CameraRig, ImageSequence
from skinkit.store import layout as L
from skinkit.store.h5file import ExperimentFile, check_name, flag, int_pair, reading


class CameraAccess(ExperimentFile):
    """The camera rig and the image sequences of an experiment file."""

    # -- camera rig ----------------------------------------------------------------------
    def write_rig(self, rig: CameraRig) -> None:
        """Store (replace) the camera rig."""
        f = self._writable()
        if L.RIG in f:
            del f[L.RIG]
        g = f.require_group(L.RIG)
        for i, cam in enumerate(rig.cameras):
            c = g.create_group(check_name(cam.name, "camera name"))
            c.attrs["index"] = i
            c.create_dataset("K", data=cam.K).attrs["unit"] = "px"
            c.create_dataset("distortion", data=cam.distortion)
            c.create_dataset("R", data=cam.R)
            c.create_dataset("t", data=cam.t).attrs["unit"] = "m"
            c.attrs["image_size"] = np.asarray(cam.image_size, dtype=np.int64)
        f.flush()

    @reading
    def camera_names(self) -> list[str]:
        """The rig's camera names, in camera index order."""
        if L.RIG not in self._f:
            return []
        g = self._f[L.RIG]
        return sorted(g, key=lambda n: self._attr(g[n], "index", int, 0, "an integer"))

    @reading
    def read_rig(self) -> CameraRig:
        """The camera rig, validated."""
        g = self._group(L.RIG)
        cams = []
        for name in self.camera_names():
            c = g[name]
            try:
                cams.append(CameraModel(
                    name=name,
                    K=self._dataset(c, "K", 2)[()],
                    distortion=self._dataset(c, "distortion", 1)[()],
                    R=self._dataset(c, "R", 2)[()],
                    t=self._dataset(c, "t", 1, unit="m")[()],
                    image_size=self._attr(c, "image_size", int_pair, (0, 0), "two integers")))
            except SchemaError as exc:
                raise self._err(c.name, str(exc)) from None
        return CameraRig(tuple(cams))

    # -- images --------------------------------------------------------------------------
    @contextmanager
    def image_writer(self, name: str, camera_names: Sequence[str], image_size: tuple[int, int],
                     dtype: Any = np.uint8) -> Iterator[Any]:
        """Append frames one at a time: ``w.append(frame (C, H, W), time_s)``; flushed per frame."""
        f = self._writable()
        check_name(name, "image sequence name")
        for cam in camera_names:
            check_name(cam, "camera name")
        if f"{L.IMAGES}/{name}" in f:
            raise self._err(f"/{L.IMAGES}/{name}", "an image sequence of this name already exists")
        w, h = (int(s) for s in image_size)
        ncam = len(camera_names)
        g = f.require_group(L.IMAGES).create_group(name)
        g.attrs["camera_names"] = jsonio.dumps(list(camera_names))
        g.attrs["complete"] = False
        frames = g.create_dataset("frames", shape=(0, ncam, h, w), maxshape=(None, ncam, h, w),
                                  chunks=(1, 1, h, w), dtype=dtype)
        times = g.create_dataset("time_s", shape=(0,), maxshape=(None,), chunks=(256,), dtype="f8")
        g.create_dataset("committed", data=np.zeros(1, dtype="i8"))
        f.flush()
        f.swmr_mode = True
        self._swmr = True
        store = self

        class _FrameWriter:
            n = 0

            def append(self, frame: np.ndarray, time_s: float) -> None:
                frame = np.asarray(frame)
                if frame.shape != (ncam, h, w):
                    raise SchemaError(f"images[{name!r}].frame",
                                      f"shape {frame.shape}, expected {(ncam, h, w)} (C, H, W)")
                i = self.n
                frames.resize(i + 1, axis=0)
                times.resize(i + 1, axis=0)
                frames[i] = frame
                times[i] = time_s
                g.file.flush()
                g["committed"][0] = i + 1
                g.file.flush()
                self.n = i + 1

        yield _FrameWriter()
        store._writable()[f"{L.IMAGES}/{name}"].attrs["complete"] = True
        store._f.flush()

    def write_images(self, seq: ImageSequence) -> None:
        """Store a whole image sequence."""
        with self.image_writer(seq.name, seq.camera_names, seq.image_size, seq.frames.dtype) as w:
            for frame, t in zip(seq.frames, seq.time_s, strict=True):
                w.append(frame, float(t))

    @reading
    def image_names(self) -> list[str]:
        """The names of the stored image sequences."""
        return sorted(self._f[L.IMAGES]) if L.IMAGES in self._f else []

    @reading
    def image_info(self, name: str) -> dict[str, Any]:
        """Image sequence ``name`` without its pixels: frames, cameras, image size [px] and more."""
        g = self._group(f"{L.IMAGES}/{name}")
        frames = self._dataset(g, "frames", 4)
        return {"name": name,
                "frames": self._count(g, frames.shape[0]) if "committed" in g else frames.shape[0],
                "cameras": self._json_attr(g, "camera_names", list),
                "image_size": [int(frames.shape[3]), int(frames.shape[2])],
                "dtype": str(frames.dtype),
                "complete": self._attr(g, "complete", flag, False, "true or false")}

    @reading
    def read_images(self, name: str) -> ImageSequence:
        """The image sequence ``name`` (only the committed frames of one being written)."""
        g = self._group(f"{L.IMAGES}/{name}")
        frames = self._dataset(g, "frames", 4)
        n = self._count(g, frames.shape[0]) if "committed" in g else frames.shape[0]
        self._check_declared(g, n, ["frames"])
        try:
            return ImageSequence(name=name, frames=frames[:n],
                                 camera_names=tuple(self._json_attr(g, "camera_names", list)),
                                 time_s=self._dataset(g, "time_s", 1)[:n])
        except SchemaError as exc:
            raise self._err(g.name, str(exc)) from None

