"""The withheld-effect benchmark's journal: every finished calibration and case, one JSON line
each, written as it finishes — so that a run stopped by a crash, a time limit or a closed
laptop loses at most the cases under way, and a later run with the same journal picks up
where it stopped (or adds cases: more seeds or null sessions reuse the calibrations).

File layout (JSON lines, UTF-8): a header ``{"journal": "skinkit gap benchmark", "version": 1,
"settings": {...}}``, then ``{"calibration": {...}}`` and ``{"case": {...}}`` lines in the order
they finished. ``settings`` are what makes a recorded case valid for another run (the model's
description, its free parameters, the magnitudes' threshold multiples, the diagnosis's options):
a journal written under other settings is refused, naming what differs. Seeds, null sessions,
pairs and the effects restriction only choose which cases run, so they may change between runs.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from skinkit import jsonio
from skinkit.errors import SkinkitError

MAGIC = "skinkit gap benchmark"
VERSION = 1


class JournalError(SkinkitError):
    """A journal that cannot be used: not a benchmark journal, unreadable, other settings."""


def _canonical(obj: Any) -> Any:
    """``obj`` as it reads back from JSON (tuples become lists, keys strings), for comparison."""
    return json.loads(jsonio.dumps(obj, sort_keys=True, default=str))


class Journal:
    """An append-only record of a benchmark's finished tasks at ``path`` (created if absent).

    ``settings``: JSON-ready; must equal the recorded header's when the file exists.
    ``read_only``: only read what ``path`` holds (a run that runs nothing): the file is never
    written, not even the header of an empty one or the cut of a line cut short.
    """

    def __init__(self, path: str | os.PathLike[str], settings: Mapping[str, Any], *,
                 read_only: bool = False) -> None:
        self.path = Path(path)
        self.settings = _canonical(dict(settings))
        self.read_only = read_only
        self.calibrations: dict[str, dict[str, Any]] = {}
        self.cases: dict[str, dict[str, Any]] = {}
        head = self._line({"journal": MAGIC, "version": VERSION, "settings": self.settings})
        raw = self.path.read_bytes() if self.path.exists() else b""
        # this run's own header cut short by a crash (no task recorded yet) is written again
        cut_header = not raw.endswith(b"\n") and head.encode().startswith(raw)
        if raw and not cut_header:
            self._read(raw)
        elif not read_only:
            if self.path.parent and not self.path.parent.exists():
                raise JournalError(f"journal {self.path}: folder {self.path.parent} does not exist")
            with open(self.path, "w", encoding="utf-8") as f:
                f.write(head)
                f.flush()
                os.fsync(f.fileno())

    @staticmethod
    def _line(item: Mapping[str, Any]) -> str:
        return jsonio.dumps(item, default=float, allow_nan=True) + "\n"

    def _read(self, raw: bytes) -> None:
        # a line cut short by a crash while it was written is dropped; the file is cut only once
        # it is known to be this run's journal (any other file is left as it is)
        cut = raw.rfind(b"\n") + 1
        try:
            lines = raw[:cut].decode("utf-8").splitlines()
        except UnicodeDecodeError:
            raise JournalError(f"journal {self.path}: not a skinkit gap benchmark journal (not UTF-8 "
                               "text)") from None
        try:
            head = json.loads(lines[0]) if lines else None
        except json.JSONDecodeError:
            head = None
        if not isinstance(head, dict) or head.get("journal") != MAGIC:
            raise JournalError(f"journal {self.path}: not a skinkit gap benchmark journal (first line)")
        if head.get("version") != VERSION:
            raise JournalError(f"journal {self.path}: version {head.get('version')}, this skinkit "
                               f"reads version {VERSION}")
        old = head.get("settings", {})
        if old != self.settings:
            keys = sorted(k for k in set(old) | set(self.settings) if old.get(k) != self.settings.get(k))
            raise JournalError(f"journal {self.path} was written with other settings ({', '.join(keys)} "
                               "differ): use another journal file for this run")
        for no, line in enumerate(lines[1:], start=2):
            try:
                item = json.loads(line)
            except json.JSONDecodeError as exc:
                raise JournalError(f"journal {self.path}, line {no}: not JSON ({exc.msg})") from None
            if "calibration" in item:
                self.calibrations[item["calibration"]["effect"]] = item["calibration"]
            elif "case" in item:
                self.cases[item["case"]["id"]] = item["case"]
            else:
                raise JournalError(f"journal {self.path}, line {no}: neither a calibration nor a case")
        if cut < len(raw) and not self.read_only:
            with open(self.path, "r+b") as f:
                f.truncate(cut)

    def _append(self, item: Mapping[str, Any]) -> None:
        if self.read_only:
            raise JournalError(f"journal {self.path}: opened read-only, nothing may be recorded in it")
        line = self._line(item)
        with open(self.path, "a", encoding="utf-8") as f:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())

    def add_calibration(self, cal: Mapping[str, Any]) -> None:
        """Record a finished calibration (a :func:`~skinkit.bench.gap_cases.calibrate` result)."""
        self.calibrations[cal["effect"]] = _canonical(cal)
        self._append({"calibration": cal})

    def add_case(self, rec: Mapping[str, Any]) -> None:
        """Record a finished case (a :func:`~skinkit.bench.gap_cases.run_case` record)."""
        self.cases[rec["id"]] = _canonical(rec)
        self._append({"case": rec})


__all__ = ["Journal", "JournalError"]
