"""Reading and writing experiment files (layout in :mod:`skinkit.store.layout`).

:class:`Experiment` gathers the parts of a file, each in its own module: records and attempts
(:mod:`~skinkit.store.records`), camera rig and images (:mod:`~skinkit.store.cameras`), surface
profiles and tracks (:mod:`~skinkit.store.surfaces`), fits, gaps and calibrations
(:mod:`~skinkit.store.results`), on the checked access of :mod:`~skinkit.store.h5file`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import h5py

from skinkit.errors import StoreError
from skinkit.store import layout as L
from skinkit.store.cameras import CameraAccess
from skinkit.store.h5file import ExperimentFile, check_name, reading
from skinkit.store.records import RecordAccess, RecordWriter
from skinkit.store.results import ResultAccess
from skinkit.store.surfaces import SurfaceAccess

__all__ = ["Experiment", "ExperimentFile", "RecordWriter", "check_name", "create_experiment",
           "open_experiment", "recover"]


class Experiment(RecordAccess, CameraAccess, SurfaceAccess, ResultAccess):
    """One experiment file. Create with :func:`create_experiment`, open with :func:`open_experiment`.

    Writing methods need a file opened for writing (``"w"`` or ``"a"``); reading methods
    validate what they read and raise :class:`StoreError` naming the object and the problem.
    """

    def __enter__(self) -> Experiment:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- summary -------------------------------------------------------------------------
    def _points(self, base: str, name: str, ndim: int) -> h5py.Dataset:
        return self._dataset(self._group(f"{base}/{name}"), "points", ndim, last=3, unit="m")

    @reading
    def summary(self) -> dict[str, Any]:
        """Everything ``skinkit inspect`` shows, JSON-ready."""
        cams = []
        if L.RIG in self._f:
            rig = self.read_rig()
            cams = [{"name": c.name, "image_size": list(c.image_size),
                     "focal_px": [float(c.K[0, 0]), float(c.K[1, 1])]} for c in rig.cameras]
        return {
            "path": str(self.path),
            "schema_version": self.schema_version,
            "skinkit_version": str(self._f.attrs.get("skinkit_version", "?")),
            "created": str(self._f.attrs.get("created", "?")),
            "closed_cleanly": self.closed_cleanly,
            "session": {k: (v if isinstance(v, (int, float, str)) else str(v))
                        for k, v in self.metadata().items()},
            "records": [self.record_info(n) for n in self.record_names()],
            "cameras": cams,
            "images": [self.image_info(n) for n in self.image_names()],
            "profiles": [{"name": n, "points": self._points(L.PROFILES, n, 2).shape[0]}
                         for n in self.profile_names()],
            "tracks": [{"name": n, "points": self._points(L.TRACKS, n, 3).shape[0],
                        "frames": self._points(L.TRACKS, n, 3).shape[1]}
                       for n in self.track_names()],
            "calibrations": self.calibration_names(),
            "fits": self.fit_names(),
            "gaps": self.gap_names(),
            "attempts": self.attempts(),
        }


def create_experiment(path: str | os.PathLike[str], overwrite: bool = False) -> Experiment:
    """Create a new experiment file; refuses to replace an existing one unless ``overwrite``."""
    if Path(path).exists() and not overwrite:
        raise StoreError(str(path), "", "already exists (pass overwrite=True to replace it)")
    return Experiment(path, "w")


def open_experiment(path: str | os.PathLike[str], mode: str = "r") -> Experiment:
    """Open an experiment file for reading (``"r"``) or appending (``"a"``), validating its
    format and schema version."""
    if mode not in ("r", "a"):
        raise StoreError(str(path), "", f"mode must be 'r' or 'a', got {mode!r}")
    return Experiment(path, mode)


def recover(path: str | os.PathLike[str], out: str | os.PathLike[str]) -> Path:
    """Copy what a crashed writer left in ``path`` into a new, cleanly closed file ``out``.

    Records keep only their committed samples and stay marked incomplete.
    """
    with open_experiment(path) as src, h5py.File(out, "w", libver="latest") as dst:
        for k, v in src._f.attrs.items():
            dst.attrs[k] = v
        for name in src._f:
            src._f.copy(src._f[name], dst, name=name)
        for rec in src.record_names():
            g = dst[f"{L.RECORDS}/{rec}"]
            n = src._committed(src._group(f"{L.RECORDS}/{rec}"))
            for ds in g.values():
                if isinstance(ds, h5py.Dataset) and ds.name.rsplit("/", 1)[-1] != "committed":
                    if ds.maxshape[0] is None:
                        ds.resize(n, axis=0)
    return Path(out)
