"""Import of plain CSV robot records.

The header names each column with its unit, so a file says what it holds::

    time_s,tip_position_z_mm,tip_force_z_N,motor_current_1_A

Column names:

- ``time_<unit>`` (required), a time unit (``s``, ``ms``);
- ``<channel>_<axis>_<unit>`` with ``<channel>`` one of ``RobotRecord.CHANNELS``; ``<axis>``
  ``x``/``y``/``z`` for tip channels and ``1``/``2``/``3`` for motor channels;
- ``force_<unit>``, ``position_<unit>``, ``displacement_<unit>``: one-axis devices; they
  become ``tip_force`` / ``tip_position`` along ``axis`` (default ``z``);
- ``flags`` (non-negative integers).

Axes of a channel that the file does not give are NaN. Values are numbers or ``nan``;
an empty field is an error. Lines starting with ``#`` are comments.
"""

from __future__ import annotations

import io
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.errors import SchemaError, StoreError, UnitError
from skinkit.schemas import Protocol, RobotRecord
from skinkit.units import to_si

_AXES = {"x": 0, "y": 1, "z": 2}
_MOTORS = {"1": 0, "2": 1, "3": 2}
_CHANNEL_RE = re.compile(r"^(?P<ch>" + "|".join(RobotRecord.CHANNELS) + r")_(?P<ax>[xyz123])_(?P<unit>.+)$")
_SINGLE = {"force": "tip_force", "position": "tip_position", "displacement": "tip_position"}


def _parse_header(cols: list[str], path: str, axis: str) -> list[tuple[str, int, float]]:
    """Column -> (target, axis index, SI factor); target ``time``/a channel/``flags``."""
    out: list[tuple[str, int, float]] = []
    seen: dict[tuple[str, int], str] = {}
    for j, raw in enumerate(cols):
        col = raw.strip()
        where = f"header column {j + 1} {col!r}"
        if not col:
            raise StoreError(path, "line 1", f"header column {j + 1} is empty")
        try:
            if col == "flags":
                target, ax, factor = "flags", 0, 1.0
            elif col.startswith("time_"):
                target, ax = "time", 0
                factor = float(to_si(1.0, col[5:], "s", where))
            elif m := _CHANNEL_RE.match(col):
                ch, a, unit = m["ch"], m["ax"], m["unit"]
                is_motor = ch.startswith("motor_")
                if is_motor != (a in _MOTORS):
                    raise StoreError(path, "line 1", f"{where}: axis {a!r} does not fit {ch} "
                                     f"({'1, 2, 3' if is_motor else 'x, y, z'})")
                target, ax = ch, (_MOTORS if is_motor else _AXES)[a]
                factor = float(to_si(1.0, unit, RobotRecord.CHANNELS[ch], where))
            elif (head := col.split("_", 1)[0]) in _SINGLE and "_" in col:
                target, ax = _SINGLE[head], _AXES[axis]
                factor = float(to_si(1.0, col.split("_", 1)[1], RobotRecord.CHANNELS[target], where))
            else:
                raise StoreError(path, "line 1", f"{where} is not a known column (expected time_<unit>, "
                                 "<channel>_<axis>_<unit>, force_<unit>, position_<unit>, "
                                 "displacement_<unit> or flags)")
        except UnitError as exc:
            raise StoreError(path, "line 1", str(exc)) from None
        key = (target, ax)
        if key in seen:
            raise StoreError(path, "line 1", f"{where} duplicates column {seen[key]!r}")
        seen[key] = col
        out.append((target, ax, factor))
    if ("time", 0) not in seen:
        raise StoreError(path, "line 1", "no time column (time_s or time_ms)")
    return out


def read_robot_csv(path: str | os.PathLike[str], protocol: Protocol | str | None = None,
                   axis: str = "z") -> RobotRecord:
    """Read a CSV robot record (format in this module's docstring) into a :class:`RobotRecord`.

    ``protocol`` names the record (default: the file's stem, kind ``"external"``);
    ``axis`` is the tip axis of one-axis columns. Raises :class:`StoreError` with the line
    and column of the first problem.
    """
    p = str(path)
    if axis not in _AXES:
        raise StoreError(p, "", f"axis must be x, y or z, got {axis!r}")
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise StoreError(p, "", "no such file") from None
    except IsADirectoryError:
        raise StoreError(p, "", "is a directory, not a CSV file") from None
    except UnicodeDecodeError as exc:
        raise StoreError(p, "", f"is not UTF-8 text (byte {exc.start})") from None
    if isinstance(protocol, str) or protocol is None:
        name = protocol or re.sub(r"[^A-Za-z0-9_.-]", "_", Path(path).stem) or "imported"
        protocol = Protocol(name, kind="external", description=f"imported from {Path(path).name}")
    return parse_robot_csv(text, p, protocol, axis)


def parse_robot_csv(text: str, source: str, protocol: Protocol, axis: str = "z") -> RobotRecord:
    """Parse CSV ``text`` (``source`` names it in errors); see :func:`read_robot_csv`."""
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines())
             if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise StoreError(source, "", "is empty (no header line)")
    header_line, header = lines[0]
    if "\x00" in text:
        raise StoreError(source, "", "contains NUL bytes; not a text CSV file")
    cols = header.split(",")
    spec = _parse_header(cols, source, axis)
    body = lines[1:]
    if not body:
        raise StoreError(source, f"line {header_line}", "header only, no samples")
    ncol = len(cols)
    try:
        # Fast path; on any failure the slow path below finds and names the first bad field.
        values = np.loadtxt(io.StringIO("\n".join(ln for _, ln in body)), delimiter=",",
                            ndmin=2, dtype=float, comments=None)
        if values.shape != (len(body), ncol):
            raise ValueError("shape")
    except ValueError:
        values = _parse_slowly(body, cols, source)
    inf = np.argwhere(np.isinf(values))
    if inf.size:
        r, j = inf[0]
        raise StoreError(source, f"line {body[r][0]}", f"column {cols[j].strip()!r}: infinite value")
    data: dict[str, Any] = {}
    n = len(body)
    time = None
    flags = None
    for j, (target, ax, factor) in enumerate(spec):
        col = values[:, j] * factor
        if target == "time":
            time = col
        elif target == "flags":
            raw = values[:, j]
            bad = np.flatnonzero(~np.isfinite(raw) | (raw < 0) | (raw != np.round(raw)))
            if bad.size:
                raise StoreError(source, f"line {body[bad[0]][0]}", "flags must be non-negative integers")
            flags = raw.astype(np.uint32)
        else:
            data.setdefault(target, np.full((n, 3), np.nan))[:, ax] = col
    assert time is not None
    tcol = next(j for j, s in enumerate(spec) if s[0] == "time")
    nan_t = np.flatnonzero(np.isnan(time))
    if nan_t.size:
        raise StoreError(source, f"line {body[nan_t[0]][0]}", f"column {cols[tcol].strip()!r} is NaN")
    bad = np.flatnonzero(np.diff(time) <= 0)
    if bad.size:
        lineno = body[bad[0] + 1][0]
        raise StoreError(source, f"line {lineno}", f"time {time[bad[0] + 1]:.6g} s does not increase "
                         f"(previous sample {time[bad[0]]:.6g} s)")
    try:
        return RobotRecord(time_s=time, flags=flags, protocol=protocol, **data)
    except SchemaError as exc:
        raise StoreError(source, "", str(exc)) from None


def _parse_slowly(body: list[tuple[int, str]], cols: list[str], source: str) -> np.ndarray:
    ncol = len(cols)
    values = np.empty((len(body), ncol), dtype=float)
    for r, (lineno, line) in enumerate(body):
        fields = line.split(",")
        if len(fields) != ncol:
            raise StoreError(source, f"line {lineno}", f"has {len(fields)} fields, the header has {ncol}")
        for j, field in enumerate(fields):
            s = field.strip()
            try:
                values[r, j] = float(s)
            except ValueError:
                shown = s if len(s) <= 20 else s[:20] + "..."
                raise StoreError(source, f"line {lineno}",
                                 f"column {cols[j].strip()!r}: {shown!r} is not a number") from None
    return values


def write_robot_csv(record: RobotRecord, path: str | os.PathLike[str] | io.TextIOBase) -> None:
    """Write ``record`` as CSV in SI units (the inverse of :func:`read_robot_csv`)."""
    names = ["time_s"]
    cols = [record.time_s]
    for ch in record.channels:
        axes = ("1", "2", "3") if ch.startswith("motor_") else ("x", "y", "z")
        unit = RobotRecord.CHANNELS[ch].replace(" ", "")
        arr = getattr(record, ch)
        for k, a in enumerate(axes):
            names.append(f"{ch}_{a}_{unit}")
            cols.append(arr[:, k])
    names.append("flags")
    cols.append(record.flags.astype(float))
    table = np.column_stack(cols)
    buf = io.StringIO()
    buf.write(",".join(names) + "\n")
    np.savetxt(buf, table, delimiter=",", fmt="%.17g")
    text = buf.getvalue()
    if isinstance(path, io.TextIOBase):
        path.write(text)
    else:
        Path(path).write_text(text)
