"""Point tracks from MultiDIC's 3D-DIC results (a MATLAB ``.mat`` file).

MultiDIC (STEP3 and STEP4 of its scripts) saves a struct ``DIC3DPPresults`` (or, per camera pair,
``DIC3DpairResults``) whose field ``Points3D`` is a cell array with one ``(N, 3)`` matrix per
frame: the same ``N`` reconstructed points in every frame (row ``i`` is point ``i``), in the
unit of the calibration (the checkerboard's, usually mm), which the file does not state -- it
must be given. A row holding NaN is a point not reconstructed in that frame (missing). Other
fields (``Faces``, ``corrComb``, ``Disp``, ``Deform``, ...) are not read. The file may be a MAT
v5/v7 file (read with :func:`scipy.io.loadmat`) or a v7.3 one (HDF5, read with h5py).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from skinkit.errors import StoreError

#: the MultiDIC structs whose ``Points3D`` is read, in the order looked for
STRUCTS = ("DIC3DPPresults", "DIC3DpairResults")


def read_points3d(path: Path, unit: str | None, metres_per_unit: dict[str, float],
                  columns: str | None) -> tuple[np.ndarray, np.ndarray, str]:
    """``(points (P, F, 3) [m], valid (P, F), struct name)`` from MultiDIC's ``Points3D`` in
    ``path``; ``unit``: the calibration's unit (a key of ``metres_per_unit``); ``columns`` may
    only be None or ``"metric"``. :class:`StoreError` in one line naming the file otherwise."""
    where = str(path)
    if columns == "pixel":
        raise StoreError(where, "", "MultiDIC's 3D results hold metric positions only: drop --columns pixel")
    name, frames = _frames(path)
    if not frames:
        raise StoreError(where, "", f"{name}.Points3D holds no frames")
    for k, a in enumerate(frames, start=1):
        if a.ndim != 2 or a.shape[1] != 3:
            raise StoreError(where, "", f"{name}.Points3D{{{k}}} is {a.shape}, not (N, 3)")
        if a.shape[0] != frames[0].shape[0]:
            raise StoreError(where, "", f"{name}.Points3D{{{k}}} holds {a.shape[0]} points but "
                             f"Points3D{{1}} holds {frames[0].shape[0]}: every frame must hold the "
                             "same points")
    if unit is None or unit not in metres_per_unit:
        raise StoreError(where, "", "MultiDIC positions are in the calibration's unit, which the file does "
                         "not state: give --unit (e.g. mm)")
    pts = np.stack(frames, axis=1).astype(float) * metres_per_unit[unit]
    valid = np.all(np.isfinite(pts), axis=2)
    pts[~valid] = np.nan
    return pts, valid, name


def _frames(path: Path) -> tuple[str, list[np.ndarray]]:
    """The struct's name and its ``Points3D`` matrices, one per frame."""
    import h5py
    import scipy.io

    if h5py.is_hdf5(path):   # MAT v7.3
        return _frames_h5(path)
    try:
        data = scipy.io.loadmat(path, simplify_cells=True)
    except (ValueError, OSError, TypeError) as exc:
        raise StoreError(str(path), "", f"is not a MATLAB file scipy can read ({exc})") from None
    name = next((n for n in STRUCTS if n in data), None)
    if name is None:
        _no_struct(path, [k for k in data if not k.startswith("__")])
    cell = data[name].get("Points3D") if isinstance(data[name], dict) else None
    if cell is None:
        raise StoreError(str(path), "", f"{name} has no field Points3D")
    is_cell = isinstance(cell, (list, tuple)) or (isinstance(cell, np.ndarray) and cell.dtype == object)
    items = list(cell) if is_cell else [cell]
    return name, [np.atleast_2d(np.asarray(a, dtype=float)) for a in items]


def _frames_h5(path: Path) -> tuple[str, list[np.ndarray]]:
    """``Points3D`` of a MAT v7.3 file: a dataset of references to ``(3, N)`` datasets (MATLAB
    stores matrices transposed)."""
    import h5py

    with h5py.File(path, "r") as f:
        name = next((n for n in STRUCTS if n in f), None)
        if name is None:
            _no_struct(path, [k for k in f if not k.startswith("#")])
        g: Any = f[name]
        if not isinstance(g, h5py.Group) or "Points3D" not in g:
            raise StoreError(str(path), "", f"{name} has no field Points3D")
        refs = np.asarray(g["Points3D"][()]).ravel()
        return name, [np.asarray(f[r][()], dtype=float).T for r in refs]


def _no_struct(path: Path, names: list[str]) -> None:
    raise StoreError(str(path), "", f"holds no {' or '.join(STRUCTS)} (MultiDIC's 3D results); its "
                     f"variables: {', '.join(names[:10]) or 'none'}")
