"""Robot records in an experiment file: written block by block, read back validated, and the
runs that failed before recording (``/records``, ``/attempts`` of :mod:`skinkit.store.layout`)."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import h5py
import numpy as np

from skinkit import jsonio
from skinkit.errors import SchemaError
from skinkit.schemas import Protocol, RobotRecord
from skinkit.store import layout as L
from skinkit.store.h5file import ExperimentFile, check_name, flag, reading


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


class RecordAccess(ExperimentFile):
    """The robot records and failed attempts of an experiment file."""

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

    @reading
    def record_names(self) -> list[str]:
        """Names (protocol names) of the records in the file."""
        return sorted(self._f[L.RECORDS]) if L.RECORDS in self._f else []

    @reading
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
            "complete": self._attr(g, "complete", flag, False, "true or false"),
            "extra": self._json_attr(g, "extra", dict) if "extra" in g.attrs else {},
        }

    def set_record_attrs(self, name: str, **items: Any) -> None:
        """Attach JSON-ready facts to record ``name`` (e.g. the link's ``samples_lost``), merged
        into its ``extra`` attribute; call once its writer has closed (or crashed)."""
        self._merge_extra(L.RECORDS, "record", name, items)

    def _committed(self, g: h5py.Group) -> int:
        return self._count(g, self._dataset(g, "time_s", 1, unit="s").shape[0])


    @reading
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

    @reading
    def attempts(self) -> list[dict[str, Any]]:
        """The failed runs recorded by :meth:`add_attempt`, oldest first: each its facts with
        ``name`` and ``protocol`` (the protocol's dict)."""
        if L.ATTEMPTS not in self._f:
            return []
        g = self._group(L.ATTEMPTS)
        return [{**self._json_attr(g[n], "json", dict), "name": n,
                 "protocol": self._json_attr(g[n], "protocol", dict)} for n in sorted(g)]

