"""Point tracks from DICe and Vic-3D per-frame exports, and the choice of reader for a source.

A *source* is one file, a folder or a glob (``'results/DICe_solution_*.txt'``). Its format is
told by the header of its first file, or given (``fmt``):

* ``csv`` -- the tracks CSV of :mod:`skinkit.store.track_import` (one file, every frame; a
  ``frame`` column);
* ``dice`` -- DICe's per-frame solution files ``DICe_solution_<n>.txt`` (a folder holding them,
  a glob, or one file): lines starting ``***`` are comments, then a comma-separated header and
  one row per subset. Pixel columns ``COORDINATE_X, COORDINATE_Y`` (the subset's centre in the
  reference image [px], origin top-left, y down) and ``DISPLACEMENT_X, DISPLACEMENT_Y`` [px];
  metric columns (stereo) ``MODEL_COORDINATES_X, _Y, _Z`` and ``MODEL_DISPLACEMENT_X, _Y, _Z``
  in the calibration's unit, which the file does not state (give ``unit``). ``SUBSET_ID``
  names the points; a negative ``SIGMA`` (DICe writes -1) marks a subset not correlated;
* ``vic3d`` -- Vic-3D (or Vic-2D) CSV exports, one file per frame (a folder of ``*.csv``, a
  glob, or one file), one row per data point, the same points in the same order in every file:
  metric ``X, Y, Z`` (reference position) and ``U, V, W`` (displacement), pixel ``x, y``
  (position in the reference camera-0 image) and ``u, v`` [px], ``sigma`` [px] (-1: not
  correlated). A name may carry its unit in brackets (``"X [mm]"``); without one the metric
  unit must be given. Other columns (strains, ``q, r``, ...) are skipped;
* ``multidic`` -- MultiDIC's 3D results, a ``.mat`` file (:mod:`skinkit.store.multidic`),
  told by its suffix.

Column names are matched case-sensitively (``X`` is metric, ``x`` pixels). A source holding
both pixel and metric columns is refused, naming both sets, unless ``columns`` chooses
``"metric"`` or ``"pixel"``. Positions are reference plus displacement, in metres: metric
columns times their unit, pixel columns times ``m_per_px`` (2D: z = 0; no lens model). Per-frame
files are taken in the natural order of the numbers in their names (``_9`` before ``_10``);
frame ``k`` is at ``k / fps`` seconds. A point is missing in a frame where a coordinate is not a
number or its sigma is negative.
"""

from __future__ import annotations

import csv
import glob
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skinkit.errors import SchemaError, StoreError
from skinkit.schemas import SurfaceTrack

#: the formats a source may be read as
FORMATS = ("csv", "dice", "vic3d", "multidic")
#: what ``columns`` may choose when a source holds both pixel and metric coordinate columns
COLUMN_SETS = ("metric", "pixel")
#: metres per metric unit
METRIC_UNITS = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6}
DICE_GLOB = "DICe_solution_*.txt"


@dataclass(frozen=True)
class _Spec:
    """A per-frame format's columns: name -> (axis 0..2, displacement?, "pixel" | "metric")."""

    label: str
    coords: dict[str, tuple[int, bool, str]]
    sigma: str
    point_id: str | None
    comment: str | None


DICE = _Spec("DICe", {
    "COORDINATE_X": (0, False, "pixel"), "COORDINATE_Y": (1, False, "pixel"),
    "DISPLACEMENT_X": (0, True, "pixel"), "DISPLACEMENT_Y": (1, True, "pixel"),
    "MODEL_COORDINATES_X": (0, False, "metric"), "MODEL_COORDINATES_Y": (1, False, "metric"),
    "MODEL_COORDINATES_Z": (2, False, "metric"), "MODEL_DISPLACEMENT_X": (0, True, "metric"),
    "MODEL_DISPLACEMENT_Y": (1, True, "metric"), "MODEL_DISPLACEMENT_Z": (2, True, "metric"),
}, "SIGMA", "SUBSET_ID", "***")
VIC3D = _Spec("Vic-3D", {
    "X": (0, False, "metric"), "Y": (1, False, "metric"), "Z": (2, False, "metric"),
    "U": (0, True, "metric"), "V": (1, True, "metric"), "W": (2, True, "metric"),
    "x": (0, False, "pixel"), "y": (1, False, "pixel"), "u": (0, True, "pixel"), "v": (1, True, "pixel"),
}, "sigma", None, None)
_SPECS = {"dice": DICE, "vic3d": VIC3D}
_BRACKET = re.compile(r"^(.*?)\s*\[(.*)\]$")
_UNIT_WORDS = {"pixel": "px", "pixels": "px", "px": "px", "µm": "um", "μm": "um"}


def default_track_name(source: str | os.PathLike[str]) -> str:
    """A track name for ``source``: a file's stem, a folder's name, or a glob's folder's name."""
    p = Path(source)
    if p.is_dir():
        return p.resolve().name
    if glob.has_magic(str(source)):
        return p.parent.resolve().name
    return p.stem


def _natural(p: Path) -> tuple[list[int], str]:
    return [int(n) for n in re.findall(r"\d+", p.name)], p.name


def source_files(source: str | os.PathLike[str], fmt: str | None) -> tuple[list[Path], str]:
    """The files of ``source`` in frame order, and its format (``fmt``, or detected from the
    first file's header)."""
    text = str(source)
    p = Path(source)
    if p.is_dir():
        dice = sorted(p.glob(DICE_GLOB), key=_natural)
        if fmt == "dice" or (fmt is None and dice):
            if not dice:
                raise StoreError(str(p), "", f"no DICe solution files ({DICE_GLOB}) in this folder")
            return dice, "dice"
        if fmt == "csv":
            raise StoreError(str(p), "", "is a folder: the csv format is one file "
                             "(or give --format dice|vic3d)")
        files = sorted((f for f in p.glob("*.csv") if f.is_file()), key=_natural)
        if not files:
            raise StoreError(str(p), "", f"holds no {DICE_GLOB} or *.csv files")
    elif glob.has_magic(text):
        files = sorted((Path(f) for f in glob.glob(text) if Path(f).is_file()), key=_natural)
        if not files:
            raise StoreError(text, "", "no files match this pattern")
    elif p.is_file():
        files = [p]
    else:
        raise StoreError(text, "", "no such file or folder")
    if fmt is None and files[0].suffix.lower() == ".mat":
        return files, "multidic"
    return files, fmt or detect_format(files[0])


def _header_line(path: Path, comment: str | None) -> tuple[int, list[str], list[list[str]]]:
    """(line number of the header, its names (stripped), the rows after it with ``comment``
    lines and blank lines left as empty rows). Comma, semicolon or tab separated."""
    lines = path.read_text(encoding="utf-8-sig", errors="replace").splitlines()
    k = 0
    while k < len(lines) and (not lines[k].strip() or (comment and lines[k].lstrip().startswith(comment))):
        k += 1
    if k == len(lines):
        raise StoreError(str(path), "", "holds no header line")
    first = lines[k]
    delim = "," if "," in first else (";" if ";" in first else ("\t" if "\t" in first else ","))
    rows = list(csv.reader(lines[k:], delimiter=delim))
    return k + 1, [h.strip() for h in rows[0]], rows[1:]


def _base(name: str) -> tuple[str, str | None]:
    """``"X [mm]"`` -> ``("X", "mm")``; a name without brackets -> ``(name, None)``."""
    m = _BRACKET.match(name)
    if m is None:
        return name, None
    u = m.group(2).strip()
    return m.group(1).strip(), _UNIT_WORDS.get(u.lower(), u)


def detect_format(path: Path) -> str:
    """``csv``, ``dice`` or ``vic3d`` from the header of ``path``; unknown headers are refused
    naming what was seen."""
    lines = [ln for ln in path.read_text(encoding="utf-8-sig", errors="replace").splitlines() if ln.strip()]
    if lines and lines[0].lstrip().startswith("***"):
        return "dice"
    _, names, _ = _header_line(path, None)
    bases = {_base(n)[0] for n in names}
    if bases & set(DICE.coords):
        return "dice"
    if {"frame", "point", "point_id"} & bases:
        return "csv"
    if {"X", "Y"} <= bases or {"x", "y"} <= bases:
        return "vic3d"
    if any(re.match(r"^[xyzuvwXYZUVW]_", b) for b in bases):
        return "csv"
    shown = ", ".join(names[:12]) + (", ..." if len(names) > 12 else "")
    raise StoreError(str(path), "line 1", f"unknown track format (header: {shown}); expected DICe "
                     "(COORDINATE_X, COORDINATE_Y, DISPLACEMENT_X, ...), Vic-3D (X, Y, Z, U, V, W, x, y, "
                     "sigma), MultiDIC (.mat) or csv (frame, point, x_mm, y_mm, ...); or give --format")


@dataclass
class _Columns:
    """The chosen columns of a per-frame format: index -> (axis, displacement?), their scale to
    metres, the set read, the sigma and point-id column indices."""

    coords: dict[int, tuple[int, bool]]
    scale: dict[int, float]
    kind: str
    sigma: int | None
    point_id: int | None
    dims: int


def _columns(path: Path, line: int, names: list[str], spec: _Spec, columns: str | None,
             unit: str | None, m_per_px: float | None) -> _Columns:
    """Pick pixel or metric columns of ``spec`` in ``names`` and their scales (module docstring)."""
    where = f"{path}:line {line}"
    parsed = [_base(n) for n in names]
    kinds = [spec.coords[b][2] if b in spec.coords else None for b, _ in parsed]
    found = {k: [names[i] for i, ki in enumerate(kinds) if ki == k] for k in COLUMN_SETS}
    if found["metric"] and found["pixel"] and columns is None:
        raise StoreError(where, "", f"holds pixel columns {', '.join(found['pixel'])} and metric columns "
                         f"{', '.join(found['metric'])}: choose one set with --columns pixel or "
                         "--columns metric")
    kind = columns or ("metric" if found["metric"] else "pixel")
    if not found[kind]:
        raise StoreError(where, "", f"has no {spec.label} {kind} coordinate columns (header: "
                         f"{', '.join(names[:12])}{', ...' if len(names) > 12 else ''})")
    coords = {i: spec.coords[b][:2] for i, (b, _) in enumerate(parsed) if kinds[i] == kind}
    refs = {a for a, d in coords.values() if not d}
    if not {0, 1} <= refs:
        raise StoreError(where, "", f"needs {spec.label}'s reference x and y {kind} columns "
                         f"(found: {', '.join(names[i] for i in coords)})")
    scale = {i: _unit_scale(where, names[i], parsed[i][1], kind, unit, m_per_px, spec) for i in coords}
    sigma = next((i for i, (b, _) in enumerate(parsed) if b == spec.sigma), None)
    pid = next((i for i, (b, _) in enumerate(parsed) if b == spec.point_id), None)
    return _Columns(coords, scale, kind, sigma, pid, 3 if 2 in refs else 2)


def _unit_scale(where: str, name: str, own: str | None, kind: str, unit: str | None,
                m_per_px: float | None, spec: _Spec) -> float:
    """Metres per unit of one coordinate column: pixels times ``m_per_px``; metric columns in
    the unit their header names, else the unit given (the two must agree)."""
    if kind == "pixel":
        if own not in (None, "px"):
            raise StoreError(where, "", f"pixel column {name!r} is in {own!r}, not pixels")
        if m_per_px is None or not m_per_px > 0:
            raise StoreError(where, "", f"column {name!r} is in pixels: give the scale with --m-per-px "
                             "(or read the metric columns with --columns metric)")
        return float(m_per_px)
    if own is not None and own not in METRIC_UNITS:
        raise StoreError(where, "", f"column {name!r}: unknown unit {own!r} (one of m, mm, cm, um)")
    if own is not None and unit is not None and own != unit:
        raise StoreError(where, "", f"column {name!r} is in {own} but --unit says {unit}")
    u = own or unit
    if u is None or u not in METRIC_UNITS:
        said = "DICe's model coordinates are in the calibration's unit, which the file does not state" \
            if spec is DICE else "its header gives no unit"
        raise StoreError(where, "", f"metric column {name!r}: {said}; give --unit (e.g. mm)")
    return METRIC_UNITS[u]


def parse_cell(text: str, where: str, col: str) -> float:
    """One numeric cell of a track file: empty, nan, na and null are missing (NaN); anything
    else that is not a number is refused naming ``where`` and the column ``col``."""
    t = text.strip()
    if t == "" or t.lower() in ("nan", "na", "null"):
        return float("nan")
    try:
        return float(t)
    except ValueError:
        raise StoreError(where, "", f"column {col!r}: {t!r} is not a number") from None


def _read_frame(path: Path, spec: _Spec, columns: str | None, unit: str | None,
                m_per_px: float | None) -> tuple[_Columns, list[str], np.ndarray, np.ndarray]:
    """One per-frame file: its columns, point ids (as written), positions ``(P, 3)`` [m] and
    validity ``(P,)``."""
    line0, names, rows = _header_line(path, spec.comment)
    c = _columns(path, line0, names, spec, columns, unit, m_per_px)
    ids: list[str] = []
    pos: list[np.ndarray] = []
    ok: list[bool] = []
    for k, row in enumerate(rows, start=line0 + 1):
        if not row or all(not f.strip() for f in row):
            continue
        where = f"{path}:line {k}"
        if len(row) < len(names):
            raise StoreError(where, "", f"has {len(row)} fields, the header {len(names)}")
        x = np.zeros(3)
        for i, (axis, _disp) in c.coords.items():
            x[axis] += parse_cell(row[i], where, names[i]) * c.scale[i]
        good = bool(np.all(np.isfinite(x)))
        if c.sigma is not None:
            s = parse_cell(row[c.sigma], where, names[c.sigma])
            good = good and bool(np.isfinite(s) and s >= 0)
        ids.append(row[c.point_id].strip() if c.point_id is not None else str(len(ids)))
        pos.append(x if good else np.full(3, np.nan))
        ok.append(good)
    if not pos:
        raise StoreError(str(path), "", "holds no data rows")
    return c, ids, np.array(pos), np.array(ok)


def read_frames(source: str, files: list[Path], fmt: str, columns: str | None = None, unit: str | None = None,
                m_per_px: float | None = None, fps: float = 1.0) -> tuple[SurfaceTrack, dict[str, object]]:
    """Every per-frame file of ``source`` (``files`` in frame order, format ``fmt``: ``dice`` or
    ``vic3d``), stacked into one track ``(P, F, 3)`` [m] with frame ``k`` at ``k / fps`` s, and
    the import's facts (format, column set, dimensions, file names). Arguments as in the module
    docstring; :class:`StoreError` in one line naming the file (and line) otherwise."""
    spec = _SPECS[fmt]
    first = None
    ids0: list[str] = []
    pts, valid = [], []
    for f in files:
        c, ids, pos, ok = _read_frame(f, spec, columns, unit, m_per_px)
        if first is None:
            first, ids0 = (c, files[0]), ids
            if len(set(ids)) != len(ids):
                raise StoreError(str(f), "", f"names a point twice in column {spec.point_id!r}")
        elif len(ids) != len(ids0):
            raise StoreError(str(f), "", f"holds {len(ids)} points but {first[1].name} holds {len(ids0)}: "
                             "every per-frame file must hold the same points")
        elif c.kind != first[0].kind or c.dims != first[0].dims:
            raise StoreError(str(f), "", f"its columns differ from {first[1].name}'s")
        elif ids != ids0:
            order = {p: k for k, p in enumerate(ids)}
            missing = [p for p in ids0 if p not in order]
            if missing:
                raise StoreError(str(f), "", f"lacks point {missing[0]!r} of {first[1].name}")
            pos, ok = pos[[order[p] for p in ids0]], ok[[order[p] for p in ids0]]
        pts.append(pos)
        valid.append(ok)
    assert first is not None
    c = first[0]
    points = np.stack(pts, axis=1)
    point_ids = np.array([int(s) for s in ids0]) if all(s.lstrip("-").isdigit() for s in ids0) \
        else np.arange(len(ids0))
    try:
        track = SurfaceTrack(points, np.stack(valid, axis=1), np.arange(len(files)) / fps, point_ids)
    except SchemaError as exc:
        raise StoreError(source, "", str(exc)) from None
    src = source if glob.has_magic(source) else str(Path(source).resolve())
    attrs: dict[str, object] = {"source": src, "format": fmt, "columns": c.kind, "dimensions": c.dims,
                                "layout": "per-frame files", "files": {
                                    "first": files[0].name, "last": files[-1].name, "count": len(files)}}
    if c.dims == 2:
        attrs["z"] = "not measured (2D tracks): stored as 0"
    return track, attrs
