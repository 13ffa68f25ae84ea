"""Reading and writing experiment files (layout in :mod:`skinkit.store.layout`)."""

from __future__ import annotations

import datetime as _dt
import functools
import json
import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import h5py
import numpy as np

from skinkit import __version__, jsonio
from skinkit.errors import SchemaError, StoreError
from skinkit.schemas import (
    CameraModel,
    CameraRig,
    FitResult,
    GapReport,
    ImageSequence,
    Protocol,
    RobotRecord,
    SurfaceProfile,
    SurfaceTrack,
)
from skinkit.store import layout as L


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


_F = TypeVar("_F", bound=Callable[..., Any])


def _memory_bytes() -> int | None:
    """This machine's physical memory [bytes], or None where the OS does not say."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return None


def check_name(name: Any, what: str) -> str:
    """A name stored as an HDF5 group (record, image sequence, camera, profile, track, fit,
    gap, calibration): non-empty text without '/' (a path: nested groups), '\\', '..' or NUL."""
    if not isinstance(name, str) or not name.strip():
        raise SchemaError(what, f"must be a non-empty name, got {name!r}")
    if "/" in name or "\\" in name or ".." in name or "\0" in name:
        raise SchemaError(what, f"{name!r}: a name must not contain '/', '\\', '..' or NUL")
    return name


def _int_pair(value: Any) -> tuple[int, int]:
    """Two integers from an attribute value (``ValueError``/``TypeError`` otherwise)."""
    arr = np.asarray(value)
    if arr.shape != (2,) or arr.dtype.kind not in "iu":
        raise ValueError("not two integers")
    return int(arr[0]), int(arr[1])


def _flag(value: Any) -> bool:
    """A boolean attribute (HDF5 stores it as a numpy bool or a 0/1 integer)."""
    if isinstance(value, (bool, np.bool_)) or (isinstance(value, (int, np.integer)) and value in (0, 1)):
        return bool(value)
    raise ValueError("not a boolean")


def _text(value: Any) -> str:
    """A string attribute (h5py returns ``str``; bytes from other writers are decoded)."""
    if isinstance(value, bytes):
        return value.decode()
    if not isinstance(value, str):
        raise TypeError("not a string")
    return value


#: modules whose exceptions, raised while reading, come from the file's content
_FILE_MODULES = ("h5py", "json")


def _from_file(exc: BaseException) -> bool:
    """True when ``exc`` was raised inside the HDF5 or JSON readers (a damaged or foreign
    file), False when skinkit's own code raised it (a bug, which must propagate)."""
    tb = exc.__traceback__
    last = None
    while tb is not None:
        last = tb.tb_frame
        tb = tb.tb_next
    name = "" if last is None else str(last.f_globals.get("__name__", ""))
    return isinstance(exc, OSError) or name.split(".")[0] in _FILE_MODULES


def _reading(method: _F) -> _F:
    """Turn what HDF5 raises on a damaged file into a one-line StoreError naming the file;
    an exception raised by skinkit's own code is a bug and propagates with its traceback."""

    @functools.wraps(method)
    def wrapper(self: Experiment, *args: Any, **kwargs: Any) -> Any:
        try:
            return method(self, *args, **kwargs)
        except (StoreError, SchemaError):
            raise
        except (OSError, KeyError, RuntimeError, ValueError, TypeError, IndexError) as exc:
            if not _from_file(exc):
                raise
            what = method.__name__ + (f"({args[0]!r})" if args else "")
            raise StoreError(str(self.path), "", f"damaged or unreadable file during {what}: "
                             f"{type(exc).__name__}: {_one_line(exc)}") from None

    return wrapper  # type: ignore[return-value]


def _open_h5(path: Path, mode: str) -> tuple[h5py.File, bool]:
    """Open ``path``; returns the file and whether it was closed cleanly by its last writer."""
    if not path.exists():
        raise StoreError(str(path), "", "no such file")
    if path.is_dir():
        raise StoreError(str(path), "", "is a directory, not an experiment file")
    if not h5py.is_hdf5(path):
        size = path.stat().st_size
        raise StoreError(str(path), "", f"not an HDF5 file (no HDF5 signature in its {size} bytes)")
    try:
        return h5py.File(path, mode, libver="latest" if mode != "r" else None), True
    except OSError as exc:
        msg = _one_line(exc)
        if mode == "r" and "already open for" in msg:
            # The last writer died in SWMR mode; the file is consistent and readable as SWMR.
            try:
                return h5py.File(path, "r", swmr=True), False
            except OSError as exc2:
                msg = _one_line(exc2)
        elif "already open for" in msg:
            raise StoreError(str(path), "", "was not closed by its writer (crash?) and cannot be "
                             "appended to; read it, or copy it with skinkit.store.recover()") from None
        if "truncated" in msg:
            raise StoreError(str(path), "", f"file is truncated ({msg})") from None
        raise StoreError(str(path), "", f"cannot be opened as HDF5 ({msg})") from None


class RecordWriter:
    """Appends blocks of one robot record; use through :meth:`Experiment.record_writer`.

    Each :meth:`append` writes a block, flushes it, then advances the ``committed`` marker
    and flushes again, so a crash loses at most the block being written.
    """

    def __init__(self, group: h5py.Group, protocol: Protocol, channels: Sequence[str],
                 path: str) -> None:
        self._g = group
        self._protocol = protocol
        self._channels = list(channels)
        self._path = path
        self._n = 0
        self._last_t = -np.inf

    @property
    def n_samples(self) -> int:
        """Samples committed so far."""
        return self._n

    def append(self, block: RobotRecord) -> None:
        """Append ``block`` (a :class:`RobotRecord` with at least this record's channels)."""
        if not isinstance(block, RobotRecord):
            raise SchemaError("RecordWriter.append", f"expects a RobotRecord, got {type(block).__name__}")
        missing = [c for c in self._channels if getattr(block, c) is None]
        if missing:
            raise SchemaError("RecordWriter.append", f"block lacks channel(s) {missing} of this record")
        m = block.n_samples
        if m == 0:
            return
        if block.time_s[0] <= self._last_t:
            raise SchemaError("RecordWriter.append",
                              f"block starts at t={block.time_s[0]:.6g} s, not after the last "
                              f"sample written (t={self._last_t:.6g} s)")
        n0, n1 = self._n, self._n + m
        g = self._g
        names = ["time_s", *self._channels, "flags"]
        for name in names:
            g[name].resize(n1, axis=0)
        g["time_s"][n0:n1] = block.time_s
        for c in self._channels:
            g[c][n0:n1] = getattr(block, c)
        g["flags"][n0:n1] = block.flags
        g.file.flush()
        g["committed"][0] = n1
        g.file.flush()
        self._n = n1
        self._last_t = float(block.time_s[-1])


class Experiment:
    """One experiment file. Create with :func:`create_experiment`, open with :func:`open_experiment`.

    Writing methods need a file opened for writing (``"w"`` or ``"a"``); reading methods
    validate what they read and raise :class:`StoreError` naming the object and the problem.
    """

    def __init__(self, path: str | os.PathLike[str], mode: str = "r") -> None:
        if mode not in ("r", "a", "w"):
            raise StoreError(str(path), "", f"mode must be 'r', 'a' or 'w', got {mode!r}")
        self.path = Path(path)
        self.mode = mode
        self._swmr = False
        if mode == "w":
            if self.path.is_dir():
                raise StoreError(str(path), "", "is a directory")
            try:
                self._f = h5py.File(self.path, "w", libver="latest")
            except OSError as exc:
                raise StoreError(str(path), "", f"cannot create ({_one_line(exc)})") from None
            self._f.attrs["format"] = L.FORMAT
            self._f.attrs["schema_version"] = L.SCHEMA_VERSION
            self._f.attrs["skinkit_version"] = __version__
            self._f.attrs["created"] = _dt.datetime.now(_dt.timezone.utc).isoformat()
            self._f.flush()
            self.closed_cleanly = True
        else:
            self._f, self.closed_cleanly = _open_h5(self.path, mode)
            self._validate_root()

    # -- lifecycle -------------------------------------------------------------------------
    def close(self) -> None:
        """Close the file (idempotent)."""
        if getattr(self, "_f", None) is not None and self._f.id.valid:
            self._f.close()

    def __enter__(self) -> Experiment:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _writable(self) -> h5py.File:
        if self.mode == "r":
            raise StoreError(str(self.path), "", "opened read-only; open with mode='a' to write")
        if self._swmr:
            # SWMR cannot be switched off: reopen to create objects or attributes again.
            self._f.close()
            self._f = h5py.File(self.path, "a", libver="latest")
            self._swmr = False
        return self._f

    # -- validation ------------------------------------------------------------------------
    @property
    def schema_version(self) -> str:
        """The file's schema version."""
        return str(self._f.attrs["schema_version"])

    def _err(self, where: str, problem: str) -> StoreError:
        return StoreError(str(self.path), where, problem)

    @_reading
    def _validate_root(self) -> None:
        attrs = self._f.attrs
        if attrs.get("format") != L.FORMAT:
            raise self._err("/", f"not a skinkit experiment file (attribute format={attrs.get('format')!r},"
                            f" expected {L.FORMAT!r})")
        version = attrs.get("schema_version")
        if version is None:
            raise self._err("/", "schema_version attribute is missing")
        try:
            major = int(str(version).split(".")[0])
        except ValueError:
            raise self._err("/", f"malformed schema_version {version!r}") from None
        if major not in L.SUPPORTED_MAJOR:
            raise self._err("/", f"schema version {version} is not supported by skinkit {__version__} "
                            f"(supports {sorted(L.SUPPORTED_MAJOR)}.x)")

    def _group(self, path: str) -> h5py.Group:
        if path not in self._f:
            raise self._err(path, "missing")
        g = self._f[path]
        if not isinstance(g, h5py.Group):
            raise self._err(path, "is a dataset where a group is required")
        return g

    def _dataset(self, g: h5py.Group, name: str, ndim: int, last: int | None = None,
                 unit: str | None = None) -> h5py.Dataset:
        where = f"{g.name}/{name}"
        if name not in g:
            raise self._err(where, "missing")
        d = g[name]
        if not isinstance(d, h5py.Dataset):
            raise self._err(where, "is a group where a dataset is required")
        if d.ndim != ndim or (last is not None and d.shape[-1] != last):
            want = f"{ndim}-d" + (f" with last axis {last}" if last is not None else "")
            raise self._err(where, f"has shape {d.shape}, expected {want}")
        if unit is not None and d.attrs.get("unit", unit) != unit:
            raise self._err(where, f"unit {d.attrs.get('unit')!r} where {unit!r} is required")
        return d

    def _json_attr(self, obj: h5py.HLObject, key: str, kind: type | None = None) -> Any:
        """Attribute ``key`` of ``obj`` parsed as JSON (and of type ``kind`` when given)."""
        if key not in obj.attrs:
            raise self._err(obj.name, f"attribute {key!r} is missing")
        try:
            value = json.loads(obj.attrs[key])
        except (TypeError, ValueError) as exc:
            raise self._err(obj.name, f"attribute {key!r} is not valid JSON ({exc})") from None
        if kind is not None and not isinstance(value, kind):
            want = {dict: "an object", list: "a list"}.get(kind, kind.__name__)
            raise self._err(f"{obj.name}@{key}", f"is a JSON {type(value).__name__}, expected {want}")
        return value

    def _attr(self, obj: h5py.HLObject, key: str, convert: Callable[[Any], Any], default: Any,
              what: str) -> Any:
        """Attribute ``key`` of ``obj`` through ``convert`` (``default`` when absent); a value
        that does not convert is a damaged file, named as such (not a bug in skinkit)."""
        if key not in obj.attrs:
            return default
        value = obj.attrs[key]
        try:
            return convert(value)
        except (TypeError, ValueError, OverflowError):
            raise self._err(f"{obj.name}@{key}", f"is {value!r}, expected {what}") from None

    def _count(self, g: h5py.Group, rows: int) -> int:
        """The ``committed`` sample count of ``g``: one integer in ``0..rows``."""
        d = self._dataset(g, "committed", 1)
        if d.shape[0] < 1 or d.dtype.kind not in "iu":
            raise self._err(d.name, f"holds {d.shape[0]} {d.dtype} value(s), expected one integer")
        n = int(d[0])
        if n < 0 or n > rows:
            raise self._err(d.name, f"{n} is outside 0..{rows}")
        return n

    # -- session metadata ---------------------------------------------------------------------
    def set_metadata(self, **items: str | float | int) -> None:
        """Store free session metadata (subject, site, operator, notes...)."""
        g = self._writable().require_group(L.SESSION)
        for k, v in items.items():
            g.attrs[k] = v
        self._f.flush()

    @_reading
    def metadata(self) -> dict[str, Any]:
        """The session's metadata (attributes as plain values; empty without a session group)."""
        if L.SESSION not in self._f:
            return {}
        return {k: (v.item() if hasattr(v, "item") else v) for k, v in self._f[L.SESSION].attrs.items()}

    # -- robot records -------------------------------------------------------------------------
    @contextmanager
    def record_writer(self, protocol: Protocol, channels: Sequence[str] = ("tip_position", "tip_force"),
                      rate_hz: float | None = None, chunk: int = 4096) -> Iterator[RecordWriter]:
        """Open a new record for ``protocol`` and append blocks to it incrementally.

        ``channels`` are :attr:`RobotRecord.CHANNELS` names; ``rate_hz`` the nominal rate.
        The record is marked complete when the context exits without an exception.
        """
        if not isinstance(protocol, Protocol):
            raise SchemaError("record_writer.protocol", f"must be a Protocol, got {type(protocol).__name__}")
        unknown = [c for c in channels if c not in RobotRecord.CHANNELS]
        if unknown:
            raise SchemaError("record_writer.channels",
                              f"unknown channel(s) {unknown}; known: {list(RobotRecord.CHANNELS)}")
        f = self._writable()
        records = f.require_group(L.RECORDS)
        if protocol.name in records:
            raise self._err(f"/{L.RECORDS}/{protocol.name}", "a record of this protocol already exists")
        g = records.create_group(check_name(protocol.name, "record name"))
        g.attrs["protocol"] = protocol.to_json()
        g.attrs["channels"] = jsonio.dumps(list(channels))
        g.attrs["rate_hz"] = float("nan") if rate_hz is None else float(rate_hz)
        g.attrs["complete"] = False
        g.create_dataset("time_s", shape=(0,), maxshape=(None,), chunks=(chunk,), dtype="f8")
        g["time_s"].attrs["unit"] = "s"
        for c in channels:
            d = g.create_dataset(c, shape=(0, 3), maxshape=(None, 3), chunks=(chunk, 3), dtype="f8",
                                 fillvalue=np.nan)
            d.attrs["unit"] = RobotRecord.CHANNELS[c]
        g.create_dataset("flags", shape=(0,), maxshape=(None,), chunks=(chunk,), dtype="u4")
        g.create_dataset("committed", data=np.zeros(1, dtype="i8"))
        f.flush()
        f.swmr_mode = True
        self._swmr = True
        writer = RecordWriter(g, protocol, channels, str(self.path))
        yield writer
        f = self._writable()
        f[f"{L.RECORDS}/{protocol.name}"].attrs["complete"] = True
        f.flush()

    def write_record(self, record: RobotRecord, rate_hz: float | None = None) -> None:
        """Write a whole record at once (as one block)."""
        with self.record_writer(record.protocol, record.channels,
                                rate_hz if rate_hz is not None else record.rate_hz) as w:
            w.append(record)

    @_reading
    def record_names(self) -> list[str]:
        """Names (protocol names) of the records in the file."""
        return sorted(self._f[L.RECORDS]) if L.RECORDS in self._f else []

    @_reading
    def record_info(self, name: str) -> dict[str, Any]:
        """What a record holds, without reading its samples (see ``skinkit inspect``)."""
        g = self._group(f"{L.RECORDS}/{name}")
        channels = self._json_attr(g, "channels", list)
        n = self._committed(g)
        rate = self._attr(g, "rate_hz", float, np.nan, "a rate in Hz")
        if np.isnan(rate) and n >= 2:
            t = g["time_s"][: min(n, 1001)]
            rate = float(1.0 / np.median(np.diff(t)))
        protocol = self._json_attr(g, "protocol", dict)
        return {
            "protocol": name,
            "kind": protocol.get("kind"),
            "samples": n,
            "rate_hz": None if np.isnan(rate) else rate,
            "duration_s": float(g["time_s"][n - 1] - g["time_s"][0]) if n >= 1 else 0.0,
            "channels": channels,
            "units": {c: RobotRecord.CHANNELS[c] for c in channels if c in RobotRecord.CHANNELS},
            "complete": self._attr(g, "complete", _flag, False, "true or false"),
            "extra": self._json_attr(g, "extra", dict) if "extra" in g.attrs else {},
        }

    def set_record_attrs(self, name: str, **items: Any) -> None:
        """Attach JSON-ready facts to record ``name`` (e.g. the link's ``samples_lost``), merged
        into its ``extra`` attribute; call once its writer has closed (or crashed)."""
        self._merge_extra(L.RECORDS, "record", name, items)

    def _merge_extra(self, base: str, kind: str, name: str, items: dict[str, Any]) -> None:
        """Merge ``items`` into the ``extra`` JSON attribute of ``base/name``."""
        f = self._writable()
        path = f"{base}/{name}"
        if path not in f:
            raise self._err(path, "missing")
        g = f[path]
        extra = self._json_attr(g, "extra", dict) if "extra" in g.attrs else {}
        extra.update(items)
        try:
            g.attrs["extra"] = jsonio.dumps(extra, allow_nan=True)
        except TypeError as exc:
            raise SchemaError(f"{kind} {name!r} attrs", f"not JSON-ready ({exc})") from None
        f.flush()

    def _committed(self, g: h5py.Group) -> int:
        return self._count(g, self._dataset(g, "time_s", 1, unit="s").shape[0])

    def _check_declared(self, g: h5py.Group, n: int, names: Sequence[str]) -> None:
        """Refuse, before reading, ``n`` rows of datasets ``names`` of ``g`` that the file does
        not hold (declared but never written: a damaged file) or that would not fit in memory."""
        total = 0
        for name in names:
            d = g[name]
            row = int(np.prod(d.shape[1:], dtype=np.int64)) * d.dtype.itemsize
            need = n * row
            total += need
            # unwritten chunks take no space: a file that stores fewer bytes than it declares
            # (and does not compress) never held those rows
            if d.compression is None and d.id.get_storage_size() < need:
                raise self._err(d.name, f"declares {n:,} rows ({need / 1e9:.3g} GB) but stores only "
                                f"{d.id.get_storage_size():,} bytes: damaged (rows never written)")
        mem = _memory_bytes()
        if mem is not None and total > mem // 2:
            raise self._err(g.name, f"{n:,} samples take {total / 1e9:.3g} GB to read, more than half "
                            f"this machine's {mem / 1e9:.3g} GB of memory")

    @_reading
    def read_record(self, name: str) -> RobotRecord:
        """The committed samples of record ``name``, validated."""
        g = self._group(f"{L.RECORDS}/{name}")
        try:
            protocol = Protocol.from_dict(self._json_attr(g, "protocol", dict))
        except SchemaError as exc:
            raise self._err(f"{g.name}@protocol", str(exc)) from None
        channels = self._json_attr(g, "channels")
        if not isinstance(channels, list) or any(c not in RobotRecord.CHANNELS for c in channels):
            raise self._err(f"{g.name}@channels", f"malformed channel list {channels!r}")
        n = self._committed(g)
        time_s = self._dataset(g, "time_s", 1, unit="s")
        for c in channels:
            d = self._dataset(g, c, 2, last=3, unit=RobotRecord.CHANNELS[c])
            if d.shape[0] < n:
                raise self._err(d.name, f"has {d.shape[0]} rows but {n} samples are committed")
        flags = self._dataset(g, "flags", 1)
        if time_s.shape[0] < n or flags.shape[0] < n:
            raise self._err(g.name, f"time_s or flags shorter than the {n} committed samples")
        self._check_declared(g, n, ["time_s", "flags", *channels])
        data: dict[str, Any] = {c: g[c][:n] for c in channels}
        try:
            return RobotRecord(time_s=time_s[:n], flags=flags[:n], protocol=protocol, **data)
        except SchemaError as exc:
            raise self._err(g.name, str(exc)) from None

    def discard_empty_record(self, name: str) -> bool:
        """Delete record ``name`` if it holds no committed sample (its run failed before the
        first one: see :meth:`add_attempt`), so that a new run can write it; True if deleted."""
        f = self._writable()
        path = f"{L.RECORDS}/{name}"
        if path not in f or self._committed(self._group(path)) > 0:
            return False
        del f[path]
        f.flush()
        return True

    def add_attempt(self, protocol: Protocol, **facts: Any) -> str:
        """Record a run of ``protocol`` that failed (e.g. before its first sample, which leaves
        no record): ``facts`` are JSON-ready (driver, stage, reason, started, samples, ...).
        Returns the attempt's name under ``/attempts``."""
        if not isinstance(protocol, Protocol):
            raise SchemaError("add_attempt.protocol", f"must be a Protocol, got {type(protocol).__name__}")
        try:
            payload = jsonio.dumps(facts, allow_nan=True)
        except TypeError as exc:
            raise SchemaError("add_attempt.facts", f"not JSON-ready ({exc})") from None
        g = self._writable().require_group(L.ATTEMPTS)
        name = f"{len(g) + 1:04d}"
        a = g.create_group(name)
        a.attrs["protocol"] = protocol.to_json()
        a.attrs["json"] = payload
        self._f.flush()
        return name

    @_reading
    def attempts(self) -> list[dict[str, Any]]:
        """The failed runs recorded by :meth:`add_attempt`, oldest first: each its facts with
        ``name`` and ``protocol`` (the protocol's dict)."""
        if L.ATTEMPTS not in self._f:
            return []
        g = self._group(L.ATTEMPTS)
        return [{**self._json_attr(g[n], "json", dict), "name": n,
                 "protocol": self._json_attr(g[n], "protocol", dict)} for n in sorted(g)]

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

    @_reading
    def camera_names(self) -> list[str]:
        """The rig's camera names, in camera index order."""
        if L.RIG not in self._f:
            return []
        g = self._f[L.RIG]
        return sorted(g, key=lambda n: self._attr(g[n], "index", int, 0, "an integer"))

    @_reading
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
                    image_size=self._attr(c, "image_size", _int_pair, (0, 0), "two integers")))
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

    @_reading
    def image_names(self) -> list[str]:
        """The names of the stored image sequences."""
        return sorted(self._f[L.IMAGES]) if L.IMAGES in self._f else []

    @_reading
    def image_info(self, name: str) -> dict[str, Any]:
        """Image sequence ``name`` without its pixels: frames, cameras, image size [px] and more."""
        g = self._group(f"{L.IMAGES}/{name}")
        frames = self._dataset(g, "frames", 4)
        return {"name": name,
                "frames": self._count(g, frames.shape[0]) if "committed" in g else frames.shape[0],
                "cameras": self._json_attr(g, "camera_names", list),
                "image_size": [int(frames.shape[3]), int(frames.shape[2])],
                "dtype": str(frames.dtype),
                "complete": self._attr(g, "complete", _flag, False, "true or false")}

    @_reading
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

    # -- surfaces ------------------------------------------------------------------------
    def _replace_group(self, base: str, name: str) -> h5py.Group:
        singular = base.rstrip("s")
        path = f"{base}/{check_name(name, f'{singular} name')}"
        f = self._writable()
        if path in f:
            del f[path]
        return f.require_group(path)

    def write_profile(self, name: str, profile: SurfaceProfile) -> None:
        """Store (replace) the surface profile ``name``: points (N, 3) [m], quality, uncertainty [px]."""
        g = self._replace_group(L.PROFILES, name)
        g.create_dataset("points", data=profile.points).attrs["unit"] = "m"
        g.create_dataset("quality", data=profile.quality)
        if profile.uncertainty_px is not None:
            g.create_dataset("uncertainty_px", data=profile.uncertainty_px).attrs["unit"] = "px"
        g.attrs["quality_name"] = profile.quality_name
        self._f.flush()

    @_reading
    def profile_names(self) -> list[str]:
        """The names of the stored surface profiles."""
        return sorted(self._f[L.PROFILES]) if L.PROFILES in self._f else []

    @_reading
    def read_profile(self, name: str) -> SurfaceProfile:
        """The surface profile ``name``."""
        g = self._group(f"{L.PROFILES}/{name}")
        try:
            return SurfaceProfile(
                points=self._dataset(g, "points", 2, last=3, unit="m")[()],
                quality=self._dataset(g, "quality", 1)[()],
                uncertainty_px=g["uncertainty_px"][()] if "uncertainty_px" in g else None,
                quality_name=self._attr(g, "quality_name", _text, "peak_correlation", "a name"))
        except SchemaError as exc:
            raise self._err(g.name, str(exc)) from None

    def write_track(self, name: str, track: SurfaceTrack) -> None:
        """Store (replace) the surface track ``name``: points (P, F, 3) [m], valid (P, F), times (F,) [s]."""
        g = self._replace_group(L.TRACKS, name)
        g.create_dataset("points", data=track.points, chunks=True).attrs["unit"] = "m"
        g.create_dataset("valid", data=track.valid)
        g.create_dataset("time_s", data=track.time_s).attrs["unit"] = "s"
        if track.point_ids is not None:
            g.create_dataset("point_ids", data=track.point_ids)
        self._f.flush()

    @_reading
    def track_names(self) -> list[str]:
        """The names of the stored surface tracks."""
        return sorted(self._f[L.TRACKS]) if L.TRACKS in self._f else []

    def set_track_attrs(self, name: str, **items: Any) -> None:
        """Attach JSON-ready facts to track ``name`` (e.g. its producer's ``noise_m`` [m] per
        axis, ``dimensions``), merged into its ``extra`` attribute."""
        self._merge_extra(L.TRACKS, "track", name, items)

    @_reading
    def track_attrs(self, name: str) -> dict[str, Any]:
        """The facts attached to track ``name`` by :meth:`set_track_attrs` (empty if none)."""
        g = self._group(f"{L.TRACKS}/{name}")
        return self._json_attr(g, "extra", dict) if "extra" in g.attrs else {}

    @_reading
    def read_track(self, name: str) -> SurfaceTrack:
        """The surface track ``name``."""
        g = self._group(f"{L.TRACKS}/{name}")
        try:
            return SurfaceTrack(
                points=self._dataset(g, "points", 3, last=3, unit="m")[()],
                valid=self._dataset(g, "valid", 2)[()],
                time_s=self._dataset(g, "time_s", 1, unit="s")[()],
                point_ids=g["point_ids"][()] if "point_ids" in g else None)
        except SchemaError as exc:
            raise self._err(g.name, str(exc)) from None

    # -- results -------------------------------------------------------------------------
    def _write_json(self, base: str, name: str, payload: dict[str, Any]) -> None:
        g = self._replace_group(base, name)
        g.attrs["json"] = jsonio.dumps(payload, allow_nan=True)
        self._f.flush()

    def write_fit(self, name: str, fit: FitResult) -> None:
        """Store (replace) the fit result ``name`` as JSON."""
        self._write_json(L.FITS, name, fit.to_dict())

    @_reading
    def fit_names(self) -> list[str]:
        """The names of the stored fit results."""
        return sorted(self._f[L.FITS]) if L.FITS in self._f else []

    @_reading
    def read_fit(self, name: str) -> FitResult:
        """The fit result ``name``."""
        g = self._group(f"{L.FITS}/{name}")
        try:
            return FitResult.from_dict(self._json_attr(g, "json", dict))
        except (SchemaError, TypeError, KeyError) as exc:
            raise self._err(g.name, f"malformed fit result ({_one_line(exc)})") from None

    def write_gap(self, name: str, report: GapReport) -> None:
        """Store (replace) the gap report ``name`` as JSON."""
        self._write_json(L.GAPS, name, report.to_dict())

    @_reading
    def gap_names(self) -> list[str]:
        """The names of the stored gap reports."""
        return sorted(self._f[L.GAPS]) if L.GAPS in self._f else []

    @_reading
    def read_gap(self, name: str) -> dict[str, Any]:
        """The gap report ``name`` as its JSON dict."""
        return self._json_attr(self._group(f"{L.GAPS}/{name}"), "json", dict)

    def write_calibration(self, name: str, payload: dict[str, Any]) -> None:
        """Store (replace) a device calibration ``name`` (e.g. ``"robot"``) as JSON."""
        self._write_json(L.CALIBRATIONS, name, payload)

    @_reading
    def calibration_names(self) -> list[str]:
        """The names of the stored device calibrations."""
        return sorted(self._f[L.CALIBRATIONS]) if L.CALIBRATIONS in self._f else []

    @_reading
    def read_calibration(self, name: str) -> dict[str, Any]:
        """The calibration ``name`` as its JSON dict."""
        return self._json_attr(self._group(f"{L.CALIBRATIONS}/{name}"), "json", dict)

    # -- summary -------------------------------------------------------------------------
    def _points(self, base: str, name: str, ndim: int) -> h5py.Dataset:
        return self._dataset(self._group(f"{base}/{name}"), "points", ndim, last=3, unit="m")

    @_reading
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
