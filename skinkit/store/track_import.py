"""Point tracks from other DIC tools (CSV, 2D or 3D) as a :class:`SurfaceTrack`.

Two layouts, told apart by a ``point`` column (comma, semicolon or tab separated; header
names are case-insensitive):

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

#: metres per unit; ``px`` is scaled by the caller's metres per pixel
UNITS = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6, "px": None}
_AXES = {"x": 0, "y": 1, "z": 2, "u": 0, "v": 1, "w": 2}
_NAME = re.compile(r"^([xyzuvw])(?:_(.+?))?(?:_(m|mm|cm|um|px))?$", re.IGNORECASE)


@dataclass
class TrackImport:
    """A track read from CSV, and facts about it for the track's ``extra`` attribute."""

    track: SurfaceTrack
    attrs: dict[str, Any]


def _column(name: str, long_form: bool) -> tuple[str, str | None, str | None] | None:
    """``(axis letter, point label or None, unit or None)`` of a coordinate column, or None."""
    m = _NAME.match(name)
    if m is None:
        return None
    axis, point, unit = m.group(1).lower(), m.group(2), (m.group(3) or "").lower() or None
    if long_form:
        if point is not None:
            if point.lower() in UNITS and unit is None:
                point = point.lower()
                return axis, None, point
            return None
        return axis, None, unit
    if point is None or (point.lower() in UNITS and unit is None):
        return None  # x_mm in a file without a point column: not a per-point column
    return axis, point, unit


def _number(text: str, where: str, col: str) -> float:
    t = text.strip()
    if t == "" or t.lower() in ("nan", "na", "null"):
        return float("nan")
    try:
        return float(t)
    except ValueError:
        raise StoreError(where, "", f"column {col!r}: {t!r} is not a number") from None


def read_tracks_csv(path: str | os.PathLike[str], unit: str | None = None, m_per_px: float | None = None,
                    fps: float = 1.0, ignore: Sequence[str] = ()) -> TrackImport:
    """Read a tracks CSV (module docstring) into a :class:`SurfaceTrack` [m].

    ``unit``: unit of bare ``x, y, z`` columns; ``m_per_px``: scale of ``px`` columns [m/px];
    ``fps``: frame rate [Hz] when the file has no time column; ``ignore``: columns to skip.
    Raises :class:`StoreError` in one line naming the file, line and column.
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
    h = _header(p, rows[0], unit, m_per_px, ignore)
    data, times = _rows(p, rows, h)
    return _assemble(p, h, data, times, fps)


@dataclass
class _Header:
    """What the header line says: the lower-case names, the coordinate columns (index ->
    axis, point label or None, unit or None) with their scale to metres, the layout, the
    special columns' indices and the wide form's point labels."""

    names: list[str]
    coords: dict[int, tuple[str, str | None, str | None]]
    scale: dict[int, float]
    long_form: bool
    special: dict[str, int]
    points: list[str]

    @property
    def has_z(self) -> bool:
        return "z" in {a for a, _, _ in self.coords.values()}

    @property
    def displacements(self) -> bool:
        return bool({a for a, _, _ in self.coords.values()} & {"u", "v", "w"})


_SPECIAL = {"frame", "point", "point_id", "time_s", "time_ms", "valid"}


def _header(p: Path, first: list[str], unit: str | None, m_per_px: float | None,
            ignore: Sequence[str]) -> _Header:
    """Parse and check the header line (StoreError naming ``line 1`` otherwise)."""
    raw = [h.strip() for h in first]
    header = [h.lower() for h in raw]
    skip = {s.strip().lower() for s in ignore}
    long_form = "point" in header or "point_id" in header
    if "frame" not in header:
        raise StoreError(str(p), "line 1", f"no 'frame' column (header: {', '.join(header)})")
    coords: dict[int, tuple[str, str | None, str | None]] = {}
    unknown = []
    for i, h in enumerate(header):
        if h in _SPECIAL or h in skip:
            continue
        c = _column(raw[i], long_form)
        if c is None:
            unknown.append(raw[i])
        else:
            coords[i] = c
    if unknown:
        form = "long form: frame, point, x_<unit>, y_<unit>[, z_<unit>]" if long_form else \
            "wide form: frame, x_<point>_<unit>, y_<point>_<unit>[, z_<point>_<unit>]"
        raise StoreError(str(p), "line 1", f"unknown column(s) {', '.join(repr(u) for u in unknown)} "
                         f"({form}; optional time_s|time_ms, valid, u/v/w displacements)")
    scale = {i: _scale(p, header[i], u or unit, m_per_px) for i, (_a, _pt, u) in coords.items()}
    points = sorted({pt for _, pt, _ in coords.values()}, key=str) if not long_form else []
    axes_given = {a for a, _, _ in coords.values()}
    for need in ("x", "y"):
        if need not in axes_given:
            raise StoreError(str(p), "line 1", f"no {need!r} coordinate column")
    special = {h: header.index(h) for h in _SPECIAL if h in header}
    return _Header(header, coords, scale, long_form, special, points)


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
                             "layout": "long" if h.long_form else "wide",
                             "frames": [float(f) for f in frames]}
    if not all(_is_int(s) for s in labels):
        attrs["point_labels"] = labels
    if not h.has_z:
        attrs["z"] = "not measured (2D tracks): stored as 0"
    return TrackImport(track, attrs)


def _is_int(s: str) -> bool:
    return s.strip().lstrip("-").isdigit()


def import_tracks(experiment: str | os.PathLike[str], path: str | os.PathLike[str], name: str | None = None,
                  unit: str | None = None, m_per_px: float | None = None, fps: float = 1.0,
                  ignore: Sequence[str] = (), overwrite: bool = False) -> TrackImport:
    """Read ``path`` (:func:`read_tracks_csv`) and store it as track ``name`` (default: the
    file's stem) in ``experiment`` (created if missing). The CSV is read and checked whole
    before the file is touched; an existing track of that name is refused unless ``overwrite``."""
    from skinkit.store.experiment import create_experiment, open_experiment

    imp = read_tracks_csv(path, unit, m_per_px, fps, ignore)
    name = Path(path).stem if name is None else name
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
