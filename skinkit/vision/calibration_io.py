"""Camera calibrations written by OpenCV's ``cv::FileStorage`` (YAML or XML) as a CameraRig.

Accepted layouts (keys are matched without regard to case):

* one camera per file: ``camera_matrix`` (or ``K``, ``cameraMatrix``, ``M``, ``intrinsic_matrix``),
  ``distortion_coefficients`` (or ``D``, ``dist_coeffs``, ``distCoeffs``, ``distortion``), and
  optionally ``R`` (3x3 matrix or Rodrigues vector; ``rotation_matrix``, ``rvec``), ``T``
  (``translation``, ``tvec``, ``t``), ``image_width`` + ``image_height`` or ``image_size``;
* several cameras in one file, either as one map per camera (``cam0: {K: ..., D: ...}``, the
  map's key naming the camera), a sequence ``cameras: [{name: ..., K: ...}, ...]``, or numbered
  keys (``K1, D1, K2, D2``; ``M1, D1, M2, D2`` with ``R, T`` of camera 2 relative to camera 1, as
  OpenCV's ``stereo_calib`` writes; ``camera_matrix_0, distortion_coefficients_0, R_0, T_0``).

``R``, ``T`` map world (or camera-1) coordinates to the camera: ``x_cam = R X + T``, OpenCV's
convention. A camera without them is the world frame (identity); translations are in the
unit the board was measured in, given by a ``unit`` string node or the caller (``mm``, ``m``).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from skinkit.errors import SchemaError
from skinkit.schemas import CameraModel, CameraRig
from skinkit.vision import VisionError

_KEYS = {
    "K": ("camera_matrix", "k", "cameramatrix", "m", "intrinsic_matrix", "intrinsics", "mtx"),
    "D": ("distortion_coefficients", "d", "dist_coeffs", "distcoeffs", "distortion", "dist"),
    "R": ("r", "rotation_matrix", "rotation", "rvec"),
    "T": ("t", "translation", "tvec", "translation_vector"),
    "W": ("image_width", "width"),
    "H": ("image_height", "height"),
    "S": ("image_size", "imagesize", "size", "resolution"),
    "name": ("name", "camera_name"),
}
_ALIAS = {alias: field for field, names in _KEYS.items() for alias in names}
#: metres per unit of length
UNITS = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6}
_NUMBERED = re.compile(r"^(.*?)[_-]?(\d+)$")


def _value(node: Any) -> Any:
    """A FileNode as a numpy array, float, str, list (sequence) or dict (map)."""
    if node.isMap():
        if node.keys() and node.getNode("dt").isString() and not node.getNode("data").empty():
            return np.asarray(node.mat(), float)  # an opencv-matrix written as a map
        return {k: _value(node.getNode(k)) for k in node.keys()}
    if node.isSeq():
        items = [_value(node.at(i)) for i in range(node.size())]
        if items and all(isinstance(v, (int, float)) for v in items):
            return np.asarray(items, float)
        return items
    if node.isString():
        return node.string()
    if node.isInt() or node.isReal():
        return float(node.real())
    mat = node.mat()
    return None if mat is None else np.asarray(mat, float)


def read_filestorage(path: str | Path) -> dict[str, Any]:
    """The top-level nodes of a ``cv::FileStorage`` file (YAML/XML/JSON) as Python values."""
    p = Path(path)
    if not p.is_file():
        raise VisionError(f"{p}: no such calibration file")
    try:
        fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:
        # OpenCV's parser raises cv2.error, which its Python binding may wrap in a SystemError
        err = exc if isinstance(exc, cv2.error) else (exc.__cause__ or exc.__context__ or exc)
        detail = " ".join(str(err).split()).split("error: ")[-1]
        raise VisionError(f"{p}: not an OpenCV FileStorage file (YAML/XML): {detail}") from None
    try:
        if not fs.isOpened():
            raise VisionError(f"{p}: cannot be opened as an OpenCV FileStorage file (YAML/XML)")
        root = fs.root()
        return {k: _value(root.getNode(k)) for k in root.keys()}
    finally:
        fs.release()


def _fields(d: dict[str, Any]) -> dict[str, Any]:
    """Known fields of one camera's keys (by alias), others dropped."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        field = _ALIAS.get(k.lower())
        if field is not None and field not in out:
            out[field] = v
    return out


def _split_cameras(nodes: dict[str, Any]) -> tuple[list[tuple[str | None, dict[str, Any]]], dict[str, Any]]:
    """``([(name or None, fields)], shared fields)`` from a file's top-level nodes."""
    seq = next((v for k, v in nodes.items() if k.lower() in ("cameras", "cams")), None)
    if isinstance(seq, list) and seq and all(isinstance(v, dict) for v in seq):
        return [(None, _fields(v)) for v in seq], {}
    maps = [(k, _fields(v)) for k, v in nodes.items() if isinstance(v, dict)]
    maps = [(k, f) for k, f in maps if "K" in f]
    if maps:
        return maps, {}
    top = _fields(nodes)
    numbered: dict[int, dict[str, Any]] = {}
    for k, v in nodes.items():
        m = _NUMBERED.match(k)
        if m and m.group(1) and k.lower() not in _ALIAS:
            field = _ALIAS.get(m.group(1).lower())
            # with a shared R, T (stereo_calib), R1, R2 are rectification rotations, not poses
            if field is not None and not (field in ("R", "T") and "R" in top and "T" in top):
                numbered.setdefault(int(m.group(2)), {})[field] = v
    cams = [(None, numbered[i]) for i in sorted(numbered) if "K" in numbered[i]]
    if cams:
        return cams, top
    return ([(None, top)] if "K" in top else []), {}


def _matrix(v: Any, shape: tuple[int, ...], what: str, where: str) -> np.ndarray:
    a = np.asarray(v, float) if v is not None and not isinstance(v, (str, dict, list)) else None
    if a is None or a.size != int(np.prod(shape)):
        got = "missing" if v is None else f"{np.shape(v)}"
        raise VisionError(f"{where}: {what} must have {int(np.prod(shape))} numbers {shape}, got {got}")
    return a.reshape(shape)


def _size(f: dict[str, Any], where: str) -> tuple[int, int] | None:
    if "W" in f and "H" in f:
        return int(_matrix(f["W"], (1,), "image_width", where)[0]), int(_matrix(f["H"], (1,), "image_height",
                                                                                 where)[0])
    if "S" in f:
        w, h = _matrix(f["S"], (2,), "image_size (width, height)", where)
        return int(w), int(h)
    return None


def read_calibration_files(paths: Sequence[str | Path], unit: str | None = None) -> list[dict[str, Any]]:
    """The cameras of ``paths`` in order, each as ``{name, K (3,3) px, distortion (k,), R (3,3),
    t (3,) m, image_size (w, h) or None, source}``.

    ``unit``: the length unit of the translations (``m``, ``mm``, ``cm``, ``um``) unless the
    file holds a ``unit`` string. Raises :class:`VisionError` naming the file and key.
    """
    cams: list[dict[str, Any]] = []
    groups: list[tuple[str, dict[str, Any]]] = []
    for path in paths:
        nodes = read_filestorage(path)
        if not _split_cameras(nodes)[0] and groups:
            # e.g. stereo_calib's extrinsics.yml (R, T) after its intrinsics.yml (M1, D1, M2, D2)
            groups[-1] = (f"{groups[-1][0]} + {path}", {**groups[-1][1], **nodes})
        else:
            groups.append((str(path), nodes))
    for path, nodes in groups:
        file_unit = next((v for k, v in nodes.items() if k.lower() in ("unit", "units", "length_unit")
                          and isinstance(v, str)), None)
        found, shared = _split_cameras(nodes)
        if not found:
            raise VisionError(f"{path}: holds no camera matrix (keys camera_matrix, K, cameraMatrix, M; "
                              f"found {', '.join(nodes) or 'nothing'})")
        stereo = len(found) == 2 and "R" in shared and "T" in shared and \
            not any("R" in f or "T" in f for _, f in found)
        for i, (name, f) in enumerate(found):
            where = f"{path}: camera {name or i + 1}"
            if stereo and i == 1:  # stereo_calib: R, T of camera 2 relative to camera 1
                f = {**f, "R": shared["R"], "T": shared["T"]}
            K = _matrix(f.get("K"), (3, 3), "camera matrix", where)
            dist = np.ravel(np.asarray(f["D"], float)) if "D" in f and f["D"] is not None else np.zeros(5)
            R = np.eye(3)
            if "R" in f:
                r = np.asarray(f["R"], float)
                R = cv2.Rodrigues(r.reshape(3))[0] if r.size == 3 else _matrix(r, (3, 3), "R", where)
            t = np.zeros(3)
            if "T" in f:
                t = _matrix(f["T"], (3,), "T", where)
                u = file_unit or unit
                if np.any(t) and u is None:
                    raise VisionError(f"{path}: gives translations T without their unit; pass the unit "
                                      "(e.g. --unit mm) in which the board's squares were measured")
                if u is not None and u not in UNITS:
                    raise VisionError(f"{path}: unknown length unit {u!r} (one of {', '.join(UNITS)})")
                t = t * (UNITS[u] if u is not None else 1.0)
            cams.append({"name": name if isinstance(name, str) else None, "K": K, "distortion": dist,
                         "R": R, "t": t, "image_size": _size(f, where) or _size(shared, where),
                         "source": str(path)})
    return cams


def rig_from_files(paths: Sequence[str | Path], camera_names: Sequence[str],
                   image_size: tuple[int, int] | None = None, unit: str | None = None) -> CameraRig:
    """A :class:`CameraRig` for the session's ``camera_names`` from OpenCV calibration files.

    Cameras are matched by name when the files name them all alike, else by order (the
    files' cameras in the order the files are given). ``image_size`` ``(w, h)`` [px] is used
    for cameras whose file gives none. Raises :class:`VisionError` when the number of cameras
    differs from the session's.
    """
    cams = read_calibration_files(paths, unit)
    names = list(camera_names)
    files = ", ".join(str(p) for p in paths)
    if len(cams) != len(names):
        raise VisionError(f"{files}: {len(cams)} camera(s) in the calibration but the session has "
                          f"{len(names)} ({', '.join(names)})")
    given = [c["name"] for c in cams]
    if sorted(n for n in given if n) == sorted(names):
        cams = [cams[given.index(n)] for n in names]
    out = []
    for name, c in zip(names, cams, strict=True):
        size = c["image_size"] or image_size
        if size is None:
            raise VisionError(f"{c['source']}: camera {name}: no image size in the file and no images "
                              "in the session to take it from")
        try:
            out.append(CameraModel(name, c["K"], c["distortion"], c["R"], c["t"], size))
        except SchemaError as exc:
            raise VisionError(f"{c['source']}: camera {name}: {exc}") from None
    return CameraRig(tuple(out))


def session_cameras(exp: Any) -> tuple[list[str], tuple[int, int] | None]:
    """The camera names of an open experiment (its rig's, else its image sequences') and the
    images' size ``(w, h)`` [px] (None without images). Raises :class:`VisionError` when the
    image sequences disagree on their cameras or the file holds neither rig nor images."""
    infos = [exp.image_info(n) for n in exp.image_names()]
    size = tuple(infos[0]["image_size"]) if infos else None
    rig = exp.camera_names()
    if rig:
        return list(rig), size  # type: ignore[return-value]
    if not infos:
        raise VisionError(f"{exp.path}: holds neither a rig nor images, so its cameras are unknown; "
                          "import the images first (skinkit import-images)")
    names = {tuple(i["cameras"]) for i in infos}
    if len(names) > 1:
        raise VisionError(f"{exp.path}: its image sequences name different cameras "
                          f"({'; '.join(', '.join(n) for n in sorted(names))})")
    return list(names.pop()), size  # type: ignore[return-value]


def import_calibration(experiment: str | Path, paths: Sequence[str | Path], unit: str | None = None,
                       replace: bool = False) -> CameraRig:
    """Read OpenCV calibration ``paths`` (:func:`rig_from_files`) for the cameras of
    ``experiment`` and store the rig there, with a note of the sources in
    ``/calibrations/rig_import``. Everything is read and checked before anything is written;
    an existing rig is refused unless ``replace``."""
    from skinkit.store import open_experiment

    with open_experiment(experiment, "r") as exp:
        names, size = session_cameras(exp)
        if exp.camera_names() and not replace:
            raise VisionError(f"{experiment}: already holds a rig (pass --replace to overwrite it)")
    rig = rig_from_files(paths, names, size, unit)
    with open_experiment(experiment, "a") as exp:
        exp.write_rig(rig)
        exp.write_calibration("rig_import", {"sources": [str(Path(p).resolve()) for p in paths],
                                             "unit": unit, "cameras": list(rig.names),
                                             "convention": "x_cam = R X_world + t (OpenCV)"})
    return rig
