"""Import image files from a camera rig (one folder or glob per camera) into an experiment file.

Frames are matched across cameras by the number in their file names (``cam0/img_0007.tif``
and ``cam1/img_0007.tif`` are frame 7) or, when the names carry no frame number, by their
natural sort order. Every image is read with OpenCV (``IMREAD_UNCHANGED``: 8- and 16-bit
grey or colour TIFF, PNG, BMP, JPEG; colour is converted to grey) and checked: readable,
one size and one bit depth for all cameras and frames.

The frames are written to a temporary sequence that is renamed to its final name only when
every image has been read and written; on any error it is deleted again (and a file this
import created is removed), so a failed import leaves the experiment file as it was.
"""

from __future__ import annotations

import glob
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from skinkit import jsonio
from skinkit.store import layout as L
from skinkit.vision import VisionError
from skinkit.vision.imageio import read_gray

#: image file extensions taken from a folder given instead of a glob (lower case)
IMAGE_EXTENSIONS = (".tif", ".tiff", ".png", ".bmp", ".jpg", ".jpeg", ".jp2", ".pgm", ".ppm")

_DIGITS = re.compile(r"\d+")


@dataclass(frozen=True)
class FramePlan:
    """Which file is which frame of which camera.

    Attributes:
        camera_names: ``(C,)`` camera names, in the order given.
        files: ``(F, C)`` paths: ``files[f][c]`` is frame ``f`` of camera ``c``.
        frame_keys: ``(F,)`` the frame numbers read from the names (matched by name), or the
            positions ``0..F-1`` (matched by order).
        matched_by: ``"name"`` or ``"order"``.
    """

    camera_names: tuple[str, ...]
    files: tuple[tuple[Path, ...], ...]
    frame_keys: tuple[tuple[int, ...], ...]
    matched_by: str

    @property
    def n_frames(self) -> int:
        """Number of frames (files)."""
        return len(self.files)


def _good_name(name: str) -> bool:
    """A name stored as an HDF5 group: non-empty, no path ('/', '\\', '..') and no NUL."""
    return bool(name.strip()) and not any(c in name for c in ("/", "\\", "..", "\0"))


def expand(pattern: str) -> list[Path]:
    """Files matching ``pattern`` (a glob, or a folder: its image files), naturally sorted."""
    p = Path(pattern).expanduser()
    if p.is_dir():
        found = [q for q in p.iterdir() if q.is_file() and q.suffix.lower() in IMAGE_EXTENSIONS]
    else:
        found = [Path(q) for q in glob.glob(str(p), recursive=True)]
        found = [q for q in found if q.is_file()]
    return sorted(found, key=_natural_key)


def _natural_key(p: Path) -> tuple:
    """Sort ``img2`` before ``img10``: digit runs compare as numbers."""
    parts = re.split(r"(\d+)", str(p))
    return tuple((0, int(s), "") if s.isdigit() else (1, 0, s) for s in parts)


def _frame_numbers(files: Sequence[Path]) -> list[tuple[int, ...]] | None:
    """Per file, the numbers in its stem that vary across ``files`` (the frame number; a
    camera number constant over its files is dropped); None when they do not tell the files
    apart or the stems differ in how many numbers they hold."""
    runs = [tuple(int(m) for m in _DIGITS.findall(f.stem)) for f in files]
    if len(files) == 1:
        return [()]
    if not runs or len({len(r) for r in runs}) != 1 or not runs[0]:
        return None
    varying = [i for i in range(len(runs[0])) if len({r[i] for r in runs}) > 1]
    keys = [tuple(r[i] for i in varying) for r in runs]
    return keys if len(set(keys)) == len(keys) else None


def _list(keys: Sequence[tuple[int, ...]], n: int = 5) -> str:
    shown = ", ".join("-".join(str(v) for v in k) or "(none)" for k in keys[:n])
    return shown + (f" and {len(keys) - n} more" if len(keys) > n else "")


def plan_frames(cameras: Sequence[tuple[str, str]], match: str = "auto") -> FramePlan:
    """Match the files of each ``(camera name, glob or folder)`` into frames.

    ``match``: ``"name"`` (by the frame number in the file names), ``"order"`` (by natural
    sort order) or ``"auto"`` (by name when every camera's names carry distinct frame
    numbers, else by order). Raises :class:`VisionError` naming the camera and frames when a
    camera has no files, or frames are missing for one camera.
    """
    if match not in ("auto", "name", "order"):
        raise VisionError(f"frame matching must be auto, name or order, got {match!r}")
    if len(cameras) < 1:
        raise VisionError("no cameras given (use --camera NAME 'GLOB' once per camera)")
    names = [str(n) for n, _ in cameras]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise VisionError(f"camera name(s) given twice: {', '.join(dup)}")
    bad = [n for n in names if not _good_name(n)]
    if bad:
        raise VisionError(f"camera name {bad[0]!r} is empty or contains '/', '\\', '..' or NUL")
    files = []
    for name, pattern in cameras:
        found = expand(pattern)
        if not found:
            raise VisionError(f"camera {name}: no files match {pattern!r}")
        files.append(found)
    keys = [_frame_numbers(f) for f in files]
    by_name = match == "name" or (match == "auto" and all(k is not None for k in keys))
    if match == "name":
        missing = [n for n, k in zip(names, keys, strict=True) if k is None]
        if missing:
            raise VisionError(f"camera {missing[0]}: the file names carry no distinct frame numbers "
                              "(match by order with --match order)")
    if by_name:
        sets = [set(k) for k in keys]  # type: ignore[arg-type]
        union = sorted(set().union(*sets))
        for name, s in zip(names, sets, strict=True):
            lacking = [k for k in union if k not in s]
            if lacking:
                have = [n for n, t in zip(names, sets, strict=True) if lacking[0] in t]
                raise VisionError(f"camera {name} has no image for frame(s) {_list(lacking)} "
                                  f"(present for {', '.join(have)}; frames matched by the number "
                                  "in the file names)")
        index = [dict(zip(k, f, strict=True)) for k, f in zip(keys, files, strict=True)]  # type: ignore[arg-type]
        rows = tuple(tuple(ix[k] for ix in index) for k in union)
        return FramePlan(tuple(names), rows, tuple(union), "name")
    counts = [len(f) for f in files]
    if len(set(counts)) > 1:
        detail = ", ".join(f"{n} {c}" for n, c in zip(names, counts, strict=True))
        raise VisionError(f"cameras have different numbers of images ({detail}); frames are matched "
                          "by order because the file names carry no distinct frame numbers")
    rows = tuple(tuple(f[i] for f in files) for i in range(counts[0]))
    return FramePlan(tuple(names), rows, tuple((i,) for i in range(counts[0])), "order")


@dataclass(frozen=True)
class ImportSummary:
    """What :func:`import_images` wrote: sequence name, frames, cameras, image size
    ``(width, height)`` [px], dtype and how frames were matched."""

    name: str
    n_frames: int
    camera_names: tuple[str, ...]
    image_size: tuple[int, int]
    dtype: str
    matched_by: str


def _read(path: Path, cam: str, frame: tuple[int, ...], first: tuple[Path, np.ndarray] | None) -> np.ndarray:
    import cv2

    level = cv2.utils.logging.getLogLevel()
    # OpenCV's own log lines about a corrupt file would precede the one-line error below
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        img = read_gray(path)
    except VisionError as exc:
        raise VisionError(f"camera {cam}, frame {_list([frame])}: {exc}") from None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if first is not None:
        p0, a0 = first
        if img.shape != a0.shape:
            raise VisionError(f"mixed image sizes: {path} is {img.shape[1]}x{img.shape[0]} px, "
                              f"{p0} is {a0.shape[1]}x{a0.shape[0]} px (one size for all cameras and frames)")
        if img.dtype != a0.dtype:
            raise VisionError(f"mixed bit depths: {path} is {img.dtype}, {p0} is {a0.dtype}")
    return img


def import_images(experiment: str | Path, plan: FramePlan, name: str, fps: float = 1.0,
                  progress: Callable[[int, int], None] | None = None) -> ImportSummary:
    """Read every file of ``plan`` and store them as image sequence ``name`` in ``experiment``.

    ``experiment`` is created when it does not exist. Frame ``k`` gets time ``k / fps`` [s]
    (image files carry no trigger clock). ``progress(done, total)`` is called per frame.
    Raises :class:`VisionError` (unreadable image, mixed sizes or bit depths, a sequence of
    that name exists, camera names that differ from the file's rig) without changing the file.
    """
    from skinkit.store import create_experiment, open_experiment

    if not (np.isfinite(fps) and fps > 0):
        raise VisionError(f"frame rate must be positive, got {fps} Hz")
    if not _good_name(name):
        raise VisionError(f"sequence name {name!r} is empty or contains '/', '\\', '..' or NUL")
    path = Path(experiment)
    created = not path.exists()
    tmp = f".importing-{name}"
    F, C = plan.n_frames, len(plan.camera_names)
    first_img = _read(plan.files[0][0], plan.camera_names[0], plan.frame_keys[0], None)
    first = (plan.files[0][0], first_img)
    if not created:
        with open_experiment(path, "r") as exp:  # validates the file before anything is written
            _check_target(exp, name, plan.camera_names)
        _finish(path, tmp, name, False, False, plan)  # a sequence left by an import that was killed
    ok = False
    try:
        with create_experiment(path) if created else open_experiment(path, "a") as exp:
            h, w = first_img.shape
            with exp.image_writer(tmp, plan.camera_names, (w, h), first_img.dtype) as writer:
                for f, row in enumerate(plan.files):
                    frame = np.empty((C, h, w), first_img.dtype)
                    for c, p in enumerate(row):
                        frame[c] = first_img if (f, c) == (0, 0) else \
                            _read(p, plan.camera_names[c], plan.frame_keys[f], first)
                    writer.append(frame, f / fps)
                    if progress is not None:
                        progress(f + 1, F)
        ok = True
    finally:
        _finish(path, tmp, name, ok, created, plan)
    return ImportSummary(name, F, plan.camera_names, (int(first_img.shape[1]), int(first_img.shape[0])),
                         str(first_img.dtype), plan.matched_by)


def _check_target(exp: object, name: str, cameras: Sequence[str]) -> None:
    """Refuse an existing sequence ``name`` and cameras that differ from the file's rig."""
    path = exp.path  # type: ignore[attr-defined]
    if name in exp.image_names():  # type: ignore[attr-defined]
        raise VisionError(f"{path}: already holds an image sequence {name!r} (choose another --name)")
    rig = exp.camera_names()  # type: ignore[attr-defined]
    if rig and list(rig) != list(cameras):
        raise VisionError(f"{path}: its rig's cameras are {', '.join(rig)} but the images are "
                          f"for {', '.join(cameras)} (same names, same order)")


def _finish(path: Path, tmp: str, name: str, ok: bool, created: bool, plan: FramePlan) -> None:
    """Rename the finished temporary sequence, or remove what a failed import wrote."""
    if not ok and created:
        path.unlink(missing_ok=True)
        return
    if not path.exists() or not h5py.is_hdf5(path):
        return
    from skinkit.store.h5file import open_h5

    f, _ = open_h5(path, "a")   # a file its writer left open is refused as every append refuses it
    with f:
        src = f"{L.IMAGES}/{tmp}"
        if src not in f:
            return
        if not ok:
            del f[src]
            return
        f.move(src, f"{L.IMAGES}/{name}")
        f[f"{L.IMAGES}/{name}"].attrs["source"] = jsonio.dumps({
            "matched_by": plan.matched_by,
            "first_files": [str(p) for p in plan.files[0]],
            "last_files": [str(p) for p in plan.files[-1]]})
