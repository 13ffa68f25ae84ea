"""Where a long computation's time goes: named stages, their seconds and their solves.

A caller opens a :func:`recording`; code that does the work marks its parts with
:func:`stage`, and forward models report each whole-session prediction with :func:`count`
(protocols solved, sensitivities asked for, the method of each derivative). Outside a recording
every call is a no-op, so the marks cost nothing in normal runs. Stages nest: a stage's
``seconds`` and ``forward_equivalents`` are its own, those of the stages opened inside it left
out (the outer stage is charged the rest).

A *forward equivalent* is one whole-session prediction (every protocol of the observations
solved once, with whatever sensitivities were asked for; a central-difference derivative adds
two more).

Progress: a caller that shows progress opens :func:`reporting` with a sink; code deep inside
(the finite-element model's protocol solves, say) calls :func:`report` with the fraction of its
own work done, and :func:`portion` maps a part's 0..1 onto its share of the whole. Outside
:func:`reporting` a report is a no-op, as a stage is outside a recording.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any


@dataclass
class StageRecord:
    """One stage's own share: ``seconds`` [s], ``forward_equivalents`` (whole-session predictions),
    ``protocol_solves`` and ``sensitivity_columns`` (derivatives computed with them)."""

    name: str
    seconds: float = 0.0
    forward_equivalents: int = 0
    protocol_solves: int = 0
    sensitivity_columns: int = 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"name": self.name, "seconds": self.seconds, "forward_equivalents": self.forward_equivalents,
                "protocol_solves": self.protocol_solves, "sensitivity_columns": self.sensitivity_columns}


@dataclass
class StageClock:
    """The stages of one recording, in the order first opened (a name opened again adds to its
    record), and the method each parameter's derivative was computed by."""

    stages: dict[str, StageRecord] = field(default_factory=dict)
    methods: dict[str, str] = field(default_factory=dict)
    _open: list[tuple[str, float]] = field(default_factory=list)

    def _record(self, name: str) -> StageRecord:
        return self.stages.setdefault(name, StageRecord(name))

    def current(self) -> StageRecord:
        """The innermost open stage's record (``"other"`` when none is open)."""
        return self._record(self._open[-1][0] if self._open else "other")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``stages`` (list), ``methods``, the totals."""
        st = [s.to_dict() for s in self.stages.values()]
        return {"stages": st, "methods": dict(sorted(self.methods.items())),
                "seconds": sum(s["seconds"] for s in st),
                "forward_equivalents": sum(s["forward_equivalents"] for s in st)}


_CLOCK: ContextVar[StageClock | None] = ContextVar("skinkit_stage_clock", default=None)


@contextmanager
def recording() -> Iterator[StageClock]:
    """Record the stages marked inside the ``with`` block; yields the :class:`StageClock`."""
    clock = StageClock()
    token = _CLOCK.set(clock)
    t0 = time.perf_counter()
    try:
        yield clock
    finally:
        _CLOCK.reset(token)
        # what no stage claimed
        claimed = sum(s.seconds for s in clock.stages.values())
        rest = time.perf_counter() - t0 - claimed
        if rest > 0:
            clock._record("other").seconds += rest


@contextmanager
def stage(name: str) -> Iterator[None]:
    """Mark the ``with`` block as stage ``name`` (nothing happens outside a recording)."""
    clock = _CLOCK.get()
    if clock is None:
        yield
        return
    clock._record(name)
    t0 = time.perf_counter()
    clock._open.append((name, t0))
    inner_before = _inner_seconds(clock, name)
    try:
        yield
    finally:
        clock._open.pop()
        elapsed = time.perf_counter() - t0
        # charge only what the stages opened inside did not claim
        inner = _inner_seconds(clock, name) - inner_before
        clock._record(name).seconds += max(elapsed - inner, 0.0)


def _inner_seconds(clock: StageClock, name: str) -> float:
    return sum(s.seconds for k, s in clock.stages.items() if k != name)


def count(protocols: int, sensitivities: int, methods: Mapping[str, str] | None = None) -> None:
    """Report one whole-session prediction: ``protocols`` solved, ``sensitivities`` derivative
    columns asked for, and the method of each (``name -> "analytic" | "central-difference"``)."""
    clock = _CLOCK.get()
    if clock is None:
        return
    rec = clock.current()
    rec.forward_equivalents += 1
    rec.protocol_solves += int(protocols)
    rec.sensitivity_columns += int(sensitivities)
    for k, v in (methods or {}).items():
        # a parameter differentiated numerically anywhere is reported so
        if clock.methods.get(k) != "central-difference":
            clock.methods[k] = str(v)


#: where reported progress goes: ``sink(fraction in [0, 1] or None when unknown, note)``
Sink = Callable[[float | None, str], None]
_SINK: ContextVar[Sink | None] = ContextVar("skinkit_progress_sink", default=None)


@contextmanager
def reporting(sink: Sink | None) -> Iterator[None]:
    """Send what :func:`report` is told inside the ``with`` block to ``sink`` (None: nowhere)."""
    token = _SINK.set(sink)
    try:
        yield
    finally:
        _SINK.reset(token)


@contextmanager
def portion(lo: float, hi: float, note: str = "") -> Iterator[None]:
    """Inside the block a reported fraction ``f`` reaches the outer sink as ``lo + f (hi - lo)``:
    one part of a longer step reports its own 0..1 and the whole still advances monotonically.
    ``note``: what the part is, put before the notes reported inside."""
    outer = _SINK.get()
    if outer is None:
        yield
        return

    def inner(fraction: float | None, text: str) -> None:
        outer(None if fraction is None else lo + min(max(fraction, 0.0), 1.0) * (hi - lo),
              f"{note}: {text}" if note and text else (note or text))

    with reporting(inner):
        yield


@contextmanager
def feeding(progress: Callable[..., None] | None, name: str, lo: float = 0.0, hi: float = 1.0
            ) -> Iterator[None]:
    """Route what :func:`report` is told inside the block into a pipeline's
    ``progress(stage, fraction)`` callback as stage ``name``, over ``[lo, hi]`` of it (a callback
    with an ``update_note(stage, fraction, note)`` method, the command line's, gets the notes too).
    None: reports stay with the caller's sink, if any."""
    if progress is None:
        yield
        return
    update = getattr(progress, "update_note", None)

    def sink(fraction: float | None, note: str) -> None:
        f = None if fraction is None else lo + min(max(fraction, 0.0), 1.0) * (hi - lo)
        if callable(update):
            update(name, f, note)
        elif f is not None:
            progress(name, f)

    with reporting(sink):
        yield


def report(fraction: float | None, note: str = "") -> None:
    """Report the fraction of the current step done (None: unknown, the note alone) and a
    short note of what runs now (e.g. the protocol being solved)."""
    sink = _SINK.get()
    if sink is not None:
        sink(fraction, note)


def reporting_active() -> bool:
    """Whether anyone listens to :func:`report` (lets a caller skip work done only to report)."""
    return _SINK.get() is not None


__all__ = ["Sink", "StageClock", "StageRecord", "count", "feeding", "portion", "recording", "report",
           "reporting", "reporting_active", "stage"]
