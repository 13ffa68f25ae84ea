"""What every part of an experiment file shares: opening it, turning a damaged file's errors
into one-line :class:`StoreError` messages, and reading groups, datasets and attributes with checks
(:class:`ExperimentFile`, the base of :class:`skinkit.store.Experiment`)."""

from __future__ import annotations

import datetime as _dt
import functools
import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import h5py
import numpy as np

from skinkit import __version__, jsonio
from skinkit.errors import SchemaError, StoreError
from skinkit.store import layout as L


def one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (HDF5 messages span several)."""
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


def int_pair(value: Any) -> tuple[int, int]:
    """Two integers from an attribute value (``ValueError``/``TypeError`` otherwise)."""
    arr = np.asarray(value)
    if arr.shape != (2,) or arr.dtype.kind not in "iu":
        raise ValueError("not two integers")
    return int(arr[0]), int(arr[1])


def flag(value: Any) -> bool:
    """A boolean attribute (HDF5 stores it as a numpy bool or a 0/1 integer)."""
    if isinstance(value, (bool, np.bool_)) or (isinstance(value, (int, np.integer)) and value in (0, 1)):
        return bool(value)
    raise ValueError("not a boolean")


def text(value: Any) -> str:
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


def reading(method: _F) -> _F:
    """Turn what HDF5 raises on a damaged file into a one-line StoreError naming the file;
    an exception raised by skinkit's own code is a bug and propagates with its traceback."""

    @functools.wraps(method)
    def wrapper(self: Any, *args: Any, **kwargs: Any) -> Any:
        try:
            return method(self, *args, **kwargs)
        except (StoreError, SchemaError):
            raise
        except (OSError, KeyError, RuntimeError, ValueError, TypeError, IndexError) as exc:
            if not _from_file(exc):
                raise
            what = method.__name__ + (f"({args[0]!r})" if args else "")
            raise StoreError(str(self.path), "", f"damaged or unreadable file during {what}: "
                             f"{type(exc).__name__}: {one_line(exc)}") from None

    return wrapper  # type: ignore[return-value]


def open_h5(path: Path, mode: str) -> tuple[h5py.File, bool]:
    """Open ``path``; returns the file and whether it was closed cleanly by its last writer. Every
    open of an experiment file goes through here, so that a file a writer left open (SWMR) is
    refused for appending in the same words whichever command appends to it."""
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
        msg = one_line(exc)
        if mode == "r" and "already open for" in msg:
            # The last writer died in SWMR mode; the file is consistent and readable as SWMR.
            try:
                return h5py.File(path, "r", swmr=True), False
            except OSError as exc2:
                msg = one_line(exc2)
        elif "already open for" in msg:
            raise StoreError(str(path), "", "was not closed by its writer (crash?) and cannot be "
                             "appended to; read it, or copy it with skinkit.store.recover()") from None
        if "truncated" in msg:
            raise StoreError(str(path), "", f"file is truncated ({msg})") from None
        raise StoreError(str(path), "", f"cannot be opened as HDF5 ({msg})") from None


class ExperimentFile:
    """An open experiment file and the checked access every part of it uses; the parts
    (records, cameras and images, surfaces, results) add their methods in their own modules."""

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
                raise StoreError(str(path), "", f"cannot create ({one_line(exc)})") from None
            self._f.attrs["format"] = L.FORMAT
            self._f.attrs["schema_version"] = L.SCHEMA_VERSION
            self._f.attrs["skinkit_version"] = __version__
            self._f.attrs["created"] = _dt.datetime.now(_dt.timezone.utc).isoformat()
            self._f.flush()
            self.closed_cleanly = True
        else:
            self._f, self.closed_cleanly = open_h5(self.path, mode)
            self._validate_root()

    # -- lifecycle -------------------------------------------------------------------------
    def close(self) -> None:
        """Close the file (idempotent)."""
        if getattr(self, "_f", None) is not None and self._f.id.valid:
            self._f.close()

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

    @reading
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

    @reading
    def metadata(self) -> dict[str, Any]:
        """The session's metadata (attributes as plain values; empty without a session group)."""
        if L.SESSION not in self._f:
            return {}
        return {k: (v.item() if hasattr(v, "item") else v) for k, v in self._f[L.SESSION].attrs.items()}

    # -- shared by the parts ------------------------------------------------------------
    def _replace_group(self, base: str, name: str) -> h5py.Group:
        singular = base.rstrip("s")
        path = f"{base}/{check_name(name, f'{singular} name')}"
        f = self._writable()
        if path in f:
            del f[path]
        return f.require_group(path)


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

