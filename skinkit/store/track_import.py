"""Point tracks from other DIC tools (CSV, 2D or 3D) as a :class:`SurfaceTrack`.

Two layouts, told apart by a ``point`` column (comma, semicolon or tab separated; header
names are matched case-sensitively, as written here):

* long form, one row per point and frame: ``frame, point, x_<unit>, y_<unit>[, z_<unit>]``;
* wide form, one row per frame: ``frame, x_<point>_<unit>, y_<point>_<unit>[, z_<point>_<unit>]``
  for every point (e.g. ``x_1_mm, y_1_mm, z_1_mm, x_2_mm, ...``).

``frame`` is a non-negative whole number (the frame's index).
``<unit>`` is ``m``, ``mm``, ``cm``, ``um`` or ``px`` (pixels need a scale); a bare ``x`` takes
the unit given by the caller. Optional columns: ``time_s`` or ``time_ms`` (else frame ``k``
is at ``k / fps``), ``valid`` (0/1; else a point is valid where its coordinates are
numbers), and displacements ``u, v[, w]`` (same naming as ``x, y, z``), in which case ``x, y,
z`` are the reference coordinates and the position is ``x + u`` (as VIC-2D/3D exports).
Without ``z`` the track is 2D: ``z`` is stored as 0 and the track's ``dimensions`` attribute
is 2. Any other column is an error that names it (unless the caller ignores it).

Pixel beside metric: ``X, Y, Z, U, V, W`` (upper case, bare or ``_<unit>``, long form) are
metric columns as Vic-2D/3D name them, and beside them bare lower-case ``x, y, u, v`` are that
tool's pixel columns. A file holding both pixel columns (those, or any ``_px`` column) and
metric columns is refused, naming both sets, unless the caller chooses one with ``columns``
(``"metric"`` or ``"pixel"``); the other set is then skipped. Two columns for one coordinate
(``x_mm`` and ``x_m``) are refused too.

DICe and Vic-3D per-frame exports are read by :mod:`skinkit.store.dic_formats`.
"""

from __future__ import annotations

import csv
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.errors import SchemaError, StoreError
from skinkit.schemas import SurfaceTrack
from skinkit.store.dic_formats import COLUMN_SETS, FORMATS, read_frames, source_files
from skinkit.store.dic_formats import parse_cell as _number

#: metres per unit; ``px`` is scaled by the caller's metres per pixel
UNITS = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6, "px": None}
_AXES = {"x": 0, "y": 1, "z": 2, "u": 0, "v": 1, "w": 2}
_NAME = re.compile(r"^([xyzuvw])(?:_(.+?))?(?:_(m|mm|cm|um|px))?$")
#: Vic-style metric columns: upper-case axis letter, bare or with a metric unit (long form only)
_METRIC_NAME = re.compile(r"^([XYZUVW])(?:_(m|mm|cm|um))?$")


@dataclass
class TrackImport:
    """A track read from CSV, and facts about it for the track's ``extra`` attribute."""

    track: SurfaceTrack
    attrs: dict[str, Any]


def _column(name: str, long_form: bool) -> tuple[str, str | None, str | None] | None:
    """``(axis letter, point label or None, unit or None)`` of a coordinate column, or None
    (case-sensitive: ``X`` is a metric column, ``x`` a coordinate of the unit given)."""
    up = _METRIC_NAME.match(name)
    if up is not None:
        return (up.group(1).lower(), None, up.group(2)) if long_form else None
    m = _NAME.match(name)
    if m is None:
        return None
    axis, point, unit = m.group(1), m.group(2), m.group(3)
    if long_form:
        if point is not None:
            if point in UNITS and unit is None:
                return axis, None, point
            return None
        return axis, None, unit
    if point is None or (point in UNITS and unit is None):
        return None  # x_mm in a file without a point column: not a per-point column
    return axis, point, unit


def read_tracks_csv(path: str | os.PathLike[str], unit: str | None = None, m_per_px: float | None = None,
                    fps: float = 1.0, ignore: Sequence[str] = (), columns: str | None = None) -> TrackImport:
    """Read a tracks CSV (module docstring) into a :class:`SurfaceTrack` [m].

    ``unit``: unit of bare ``x, y, z`` (and ``X, Y, Z``) columns; ``m_per_px``: scale of ``px``
    columns [m/px]; ``fps``: frame rate [Hz] when the file has no time column; ``ignore``:
    columns to skip (exact names); ``columns``: ``"metric"`` or ``"pixel"``, the set to read
    from a file holding both. Raises :class:`StoreError` in one line naming the file, line and
    column.
    """
    p = Path(path)
    if not p.is_file():
        raise StoreError(str(p), "", "no such tracks file")
    if unit is not None and unit not in UNITS:
        raise StoreError(str(p), "", f"unknown unit {unit!r} (one of {', '.join(UNITS)})")
    if not (np.isfinite(fps) and fps > 0):
        raise StoreError(str(p), "", f"frame rate must be positive, got {fps} Hz")
    text = p.read_text(encoding="utf-8-sig", errors="replace")
    first = text.splitlines()[0] if text.strip() else ""
    delim = "," if "," in first else (";" if ";" in first else ("\t" if "\t" in first else ","))
    rows = list(csv.reader(text.splitlines(), delimiter=delim))
    if not rows or not any(h.strip() for h in rows[0]):
        raise StoreError(str(p), "", "is empty (expected a header such as frame,point,x_mm,y_mm,z_mm)")
    h = _header(p, rows[0], unit, m_per_px, ignore, columns)
    data, times = _rows(p, rows, h)
    return _assemble(p, h, data, times, fps)


@dataclass
class _Header:
    """What the header line says: the names, the coordinate columns (index ->
    axis, point label or None, unit or None) with their scale to metres, the layout, the
    special columns' indices and the wide form's point labels."""

    names: list[str]
    coords: dict[int, tuple[str, str | None, str | None]]
    scale: dict[int, float]
    long_form: bool
    special: dict[str, int]
    points: list[str]
    kind: str = "metric"

    @property
    def has_z(self) -> bool:
        return "z" in {a for a, _, _ in self.coords.values()}

    @property
    def displacements(self) -> bool:
        return bool({a for a, _, _ in self.coords.values()} & {"u", "v", "w"})


_SPECIAL = {"frame", "point", "point_id", "time_s", "time_ms", "valid"}


def _header(p: Path, first: list[str], unit: str | None, m_per_px: float | None,
            ignore: Sequence[str], columns: str | None = None) -> _Header:
    """Parse and check the header line (StoreError naming ``line 1`` otherwise)."""
    header = [h.strip() for h in first]
    skip = {s.strip() for s in ignore}
    long_form = "point" in header or "point_id" in header
    if "frame" not in header:
        near = [h for h in header if h.lower() == "frame"]
        hint = f" ({near[0]!r}: column names are case-sensitive)" if near else ""
        raise StoreError(str(p), "line 1", f"no 'frame' column{hint} (header: {', '.join(header)})")
    coords: dict[int, tuple[str, str | None, str | None]] = {}
    unknown = []
    for i, h in enumerate(header):
        if h in _SPECIAL or h in skip:
            continue
        c = _column(h, long_form)
        if c is None:
            unknown.append(h)
        else:
            coords[i] = c
    if unknown:
        _unknown(p, unknown, long_form)
    coords, kind = _choose(p, header, coords, unit, columns)
    scale = {i: _scale(p, header[i], u or unit, m_per_px) for i, (_a, _pt, u) in coords.items()}
    points = sorted({pt for _, pt, _ in coords.values()}, key=str) if not long_form else []
    axes_given = {a for a, _, _ in coords.values()}
    for need in ("x", "y"):
        if need not in axes_given:
            raise StoreError(str(p), "line 1", f"no {need!r} coordinate column")
    special = {h: header.index(h) for h in _SPECIAL if h in header}
    return _Header(header, coords, scale, long_form, special, points, kind)


def _unknown(p: Path, unknown: list[str], long_form: bool) -> None:
    """Refuse the unknown columns, pointing at a documented name differing only in case."""
    form = "long form: frame, point, x_<unit>, y_<unit>[, z_<unit>]" if long_form else \
        "wide form: frame, x_<point>_<unit>, y_<point>_<unit>[, z_<point>_<unit>]"
    cased = [u for u in unknown if u.lower() in _SPECIAL or _NAME.match(u.lower())]
    hint = f"; names are case-sensitive: {', '.join(repr(c.lower()) for c in cased)}?" if cased else ""
    raise StoreError(str(p), "line 1", f"unknown column(s) {', '.join(repr(u) for u in unknown)} "
                     f"({form}; optional time_s|time_ms, valid, u/v/w displacements{hint})")


_Coords = dict[int, tuple[str, str | None, str | None]]


def _choose(p: Path, header: list[str], coords: _Coords, unit: str | None,
            columns: str | None) -> tuple[_Coords, str]:
    """The coordinate columns to read and their set: pixel columns (``_px``, the unit given
    ``px``, or bare lower-case ``x, y, u, v`` beside upper-case metric ones) and metric columns
    may not be mixed; ``columns`` picks one set. Bare lower-case columns read as pixels get
    unit ``px``."""
    if columns is not None and columns not in COLUMN_SETS:
        raise StoreError(str(p), "", f"unknown column set {columns!r} (one of {', '.join(COLUMN_SETS)})")
    upper = any(_METRIC_NAME.match(header[i]) for i in coords)
    kind: dict[int, str] = {}
    out = dict(coords)
    for i, (a, pt, u) in coords.items():
        bare_lower = u is None and not _METRIC_NAME.match(header[i])
        if upper and bare_lower:
            out[i] = (a, pt, "px")
        kind[i] = "pixel" if out[i][2] == "px" or (out[i][2] is None and unit == "px") else "metric"
    found = {k: [header[i] for i in kind if kind[i] == k] for k in COLUMN_SETS}
    if found["metric"] and found["pixel"] and columns is None:
        raise StoreError(str(p), "line 1", f"holds pixel columns {', '.join(found['pixel'])} and metric "
                         f"columns {', '.join(found['metric'])}: choose one set with --columns pixel "
                         "or --columns metric")
    if columns is not None:
        if not found[columns]:
            raise StoreError(str(p), "line 1", f"has no {columns} coordinate columns (header: "
                             f"{', '.join(header)})")
        out = {i: c for i, c in out.items() if kind[i] == columns}
    seen: dict[tuple[str, str | None], str] = {}
    for i, (a, pt, _u) in out.items():
        if (a, pt) in seen:
            raise StoreError(str(p), "line 1", f"two columns for one coordinate: {seen[(a, pt)]!r} "
                             f"and {header[i]!r}")
        seen[(a, pt)] = header[i]
    return out, columns or ("metric" if found["metric"] else "pixel")


def _scale(p: Path, column: str, u: str | None, m_per_px: float | None) -> float:
    """Metres per unit of ``column`` (its own unit ``u``, or the one given for bare columns)."""
    if u is None:
        raise StoreError(str(p), "line 1", f"column {column!r} has no unit: name it "
                         f"{column}_mm (or _m, _um, _px), or give the unit")
    if u == "px":
        if m_per_px is None or not m_per_px > 0:
            raise StoreError(str(p), "line 1", f"column {column!r} is in pixels: give the "
                             "scale in metres per pixel")
        return float(m_per_px)
    return float(UNITS[u])  # type: ignore[arg-type]


def _rows(p: Path, rows: list[list[str]], h: _Header
          ) -> tuple[dict[tuple[float, str], tuple[np.ndarray, bool]], dict[float, float]]:
    """(frame, point) -> (position (3,) [m], valid), and frame -> time [s], from the data lines."""
    ci = h.special
    pcol = ci.get("point", ci.get("point_id"))
    data: dict[tuple[float, str], tuple[np.ndarray, bool]] = {}
    times: dict[float, float] = {}
    for lineno, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        where = f"{p}:line {lineno}"
        if len(row) < len(h.names):
            raise StoreError(where, "", f"has {len(row)} fields, the header {len(h.names)}")
        frame = _frame(row[ci["frame"]], where)
        if "time_s" in ci or "time_ms" in ci:
            key = "time_s" if "time_s" in ci else "time_ms"
            t = _number(row[ci[key]], where, key) * (1.0 if key == "time_s" else 1e-3)
            if frame in times and times[frame] != t:
                raise StoreError(where, "", f"frame {frame:g} has two times ({times[frame]:g} and {t:g} s)")
            times[frame] = t
        labels = [row[pcol].strip()] if h.long_form else h.points  # type: ignore[index]
        for label in labels:
            point = _point(row, where, h, label)
            if (frame, label) in data:
                raise StoreError(where, "", f"point {label!r} appears twice in frame {frame:g}")
            data[(frame, label)] = point
    if not data:
        raise StoreError(str(p), "", "holds no track rows")
    return data, times


def _frame(text: str, where: str) -> float:
    """The frame index of one data line: a non-negative whole number (a time column, when the
    file has one, says when it was taken; the index only orders and matches the frames)."""
    frame = _number(text, where, "frame")
    if np.isnan(frame):
        raise StoreError(where, "", "column 'frame' is empty")
    if not (np.isfinite(frame) and frame >= 0 and frame == np.floor(frame)):
        raise StoreError(where, "", f"column 'frame': {text.strip()!r} is not a frame index "
                                    "(expected a non-negative whole number)")
    return frame


def _point(row: list[str], where: str, h: _Header, label: str) -> tuple[np.ndarray, bool]:
    """One point's position (3,) [m] on one data line (reference plus displacement when the
    file gives u, v, w) and whether it is valid."""
    pos = np.zeros(3)
    ref = np.zeros(3)
    for i, (axis, pt, _u) in h.coords.items():
        if pt != (None if h.long_form else label):
            continue
        v = _number(row[i], where, h.names[i]) * h.scale[i]
        (pos if axis in "xyz" else ref)[_AXES[axis]] += v
    ok = bool(np.all(np.isfinite(pos + ref)))
    if "valid" in h.special:
        flag = row[h.special["valid"]]
        v = _number(flag, where, "valid")
        # anything but 0/1 (2, -1, an empty cell) is a mistake in the export, not a validity
        if v not in (0.0, 1.0):
            raise StoreError(where, "", f"column 'valid': {flag.strip()!r} is not 0 or 1")
        ok = ok and v == 1.0
    return (pos + ref if h.displacements else pos), ok


def _assemble(p: Path, h: _Header, data: dict[tuple[float, str], tuple[np.ndarray, bool]],
              times: dict[float, float], fps: float) -> TrackImport:
    """The track ``(points, frames, 3)`` [m] with its validity, times and the import's facts."""
    frames = sorted({f for f, _ in data})
    labels = sorted({lb for _, lb in data}, key=lambda s: (not _is_int(s), int(s) if _is_int(s) else 0, s))
    P, F = len(labels), len(frames)
    pts = np.full((P, F, 3), np.nan)
    valid = np.zeros((P, F), bool)
    fi = {f: k for k, f in enumerate(frames)}
    li = {lb: k for k, lb in enumerate(labels)}
    for (f, lb), (x, ok) in data.items():
        if ok:
            pts[li[lb], fi[f]] = x
            valid[li[lb], fi[f]] = True
    time_s = np.array([times[f] for f in frames]) if times else np.asarray(frames, float) / fps
    ids = np.array([int(s) for s in labels]) if all(_is_int(s) for s in labels) else np.arange(P)
    try:
        track = SurfaceTrack(pts, valid, time_s, ids)
    except SchemaError as exc:
        raise StoreError(str(p), "", str(exc)) from None
    attrs: dict[str, Any] = {"source": str(p.resolve()), "dimensions": 3 if h.has_z else 2,
                             "layout": "long" if h.long_form else "wide", "columns": h.kind,
                             "frames": [float(f) for f in frames]}
    if not all(_is_int(s) for s in labels):
        attrs["point_labels"] = labels
    if not h.has_z:
        attrs["z"] = "not measured (2D tracks): stored as 0"
    return TrackImport(track, attrs)


def _is_int(s: str) -> bool:
    return s.strip().lstrip("-").isdigit()


def read_tracks(source: str | os.PathLike[str], fmt: str | None = None, *, columns: str | None = None,
                unit: str | None = None, m_per_px: float | None = None, fps: float = 1.0,
                ignore: Sequence[str] = ()) -> TrackImport:
    """Read the tracks of ``source`` -- a tracks CSV (module docstring), DICe / Vic-3D
    per-frame exports (:mod:`skinkit.store.dic_formats`: a file, a folder or a glob) or
    MultiDIC's ``.mat`` results (:mod:`skinkit.store.multidic`) -- in format ``fmt`` (``csv``,
    ``dice``, ``vic3d``, ``multidic``; None: told by the header or the suffix) into a
    :class:`SurfaceTrack` ``(P, F, 3)`` [m]. ``columns``: ``"metric"`` or ``"pixel"``, the set
    to read from a source holding both; ``unit``: unit of metric columns named without one;
    ``m_per_px`` [m/px]; ``fps`` [Hz]; ``ignore``: columns the csv format skips. Raises
    :class:`StoreError` in one line."""
    where = str(source)
    if fmt is not None and fmt not in FORMATS:
        raise StoreError(where, "", f"unknown format {fmt!r} (one of {', '.join(FORMATS)})")
    if columns is not None and columns not in COLUMN_SETS:
        raise StoreError(where, "", f"unknown column set {columns!r} (one of {', '.join(COLUMN_SETS)})")
    if unit is not None and unit not in UNITS:
        raise StoreError(where, "", f"unknown unit {unit!r} (one of {', '.join(UNITS)})")
    if not (np.isfinite(fps) and fps > 0):
        raise StoreError(where, "", f"frame rate must be positive, got {fps} Hz")
    files, fmt = source_files(source, fmt)
    if fmt == "multidic":
        return _read_multidic(where, files, columns, unit, fps)
    if fmt != "csv":
        track, attrs = read_frames(where, files, fmt, columns, unit, m_per_px, fps)
        return TrackImport(track, dict(attrs))
    if len(files) != 1:
        raise StoreError(where, "", f"the csv format holds every frame in one file, but {len(files)} "
                         "files were given: name one, or give --format dice|vic3d")
    imp = read_tracks_csv(files[0], unit, m_per_px, fps, ignore, columns)
    imp.attrs["format"] = "csv"
    return imp


def _read_multidic(where: str, files: list[Path], columns: str | None, unit: str | None,
                   fps: float) -> TrackImport:
    """MultiDIC's ``Points3D`` of one ``.mat`` file as a track; frame ``k`` at ``k / fps`` s."""
    from skinkit.store.multidic import read_points3d

    if len(files) != 1:
        raise StoreError(where, "", f"MultiDIC's results are one .mat file, but {len(files)} files "
                         "were given")
    metric = {u: f for u, f in UNITS.items() if f is not None}
    pts, valid, struct = read_points3d(files[0], unit, metric, columns)
    P, F = valid.shape
    try:
        track = SurfaceTrack(pts, valid, np.arange(F) / fps, np.arange(P))
    except SchemaError as exc:
        raise StoreError(where, "", str(exc)) from None
    return TrackImport(track, {"source": str(files[0].resolve()), "format": "multidic", "columns": "metric",
                               "dimensions": 3, "layout": f"{struct}.Points3D"})


def import_tracks(experiment: str | os.PathLike[str], path: str | os.PathLike[str], name: str | None = None,
                  unit: str | None = None, m_per_px: float | None = None, fps: float = 1.0,
                  ignore: Sequence[str] = (), overwrite: bool = False, fmt: str | None = None,
                  columns: str | None = None) -> TrackImport:
    """Read ``path`` (a tracks CSV, or DICe / Vic-3D per-frame exports: a file, a folder or a
    glob; :func:`skinkit.store.dic_formats.read_tracks`, format ``fmt`` or detected) and store
    it as track ``name`` (default: the file's stem, or the folder's name) in ``experiment``
    (created if missing). The input is read and checked whole before the file is touched; an
    existing track of that name is refused unless ``overwrite``."""
    from skinkit.store.dic_formats import default_track_name
    from skinkit.store.experiment import create_experiment, open_experiment

    imp = read_tracks(path, fmt, columns=columns, unit=unit, m_per_px=m_per_px, fps=fps, ignore=ignore)
    name = default_track_name(path) if name is None else name
    if not name or "/" in name:
        raise StoreError(str(experiment), "", f"track name {name!r} is empty or contains '/'")
    out = Path(experiment)
    if out.exists():
        with open_experiment(out, "r") as exp:
            if name in exp.track_names() and not overwrite:
                raise StoreError(str(out), f"/tracks/{name}",
                                 "already exists (pass --overwrite to replace it)")
    with open_experiment(out, "a") if out.exists() else create_experiment(out) as exp:
        exp.write_track(name, imp.track)
        exp.set_track_attrs(name, **imp.attrs)
    return imp
