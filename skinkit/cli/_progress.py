"""Progress of a long command, on stderr only (stdout carries the result, ``--json`` included).

On a terminal a bar per stage with its fraction, elapsed time and ETA (rich); when stderr is not a
terminal (a log file, CI) a plain line instead, written by a heartbeat thread at least every
:data:`HEARTBEAT_S` seconds — also through a step that reports no fraction for minutes — and, once
the run has lasted that long, whenever a stage starts:
``progress: STAGE  37 %  elapsed 0:01:12  ETA 0:02:03  NOTE``. A command done (or failed) within
the first heartbeat writes none: its result or its one-line error stays alone.

Every command takes ``--quiet`` (no progress: only results and errors) and ``--verbose`` (also
each stage's time and the notes of its sub-steps) — on the root group (``skinkit --quiet CMD``)
or after the command's name (``skinkit CMD --quiet``): :func:`add_output_options` gives them to
every command the registry loads; the choice is kept in the root context's ``meta``.

Deep code reports through :func:`skinkit.forward.stages.report`; :meth:`Progress.feeding`
routes those reports into a stage of the display.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, TextIO

import click

QUIET, NORMAL, VERBOSE = "quiet", "normal", "verbose"
#: key of the root context's ``meta`` holding the verbosity (one of the three above)
VERBOSITY_KEY = "skinkit.verbosity"
#: longest silence [s] of a log's progress (stderr not a terminal)
HEARTBEAT_S = 10.0
#: environment variable overriding :data:`HEARTBEAT_S` [s] (> 0), e.g. for a test
INTERVAL_ENV = "SKINKIT_PROGRESS_INTERVAL"


def _json_output() -> bool:
    """Whether the running command was asked for ``--json``."""
    ctx = click.get_current_context(silent=True)
    return bool(ctx is not None and ctx.params.get("as_json"))


def verbosity() -> str:
    """The running command's verbosity (``"normal"`` outside a command line)."""
    ctx = click.get_current_context(silent=True)
    return str(ctx.meta.get(VERBOSITY_KEY, NORMAL)) if ctx is not None else NORMAL


def heartbeat_s() -> float:
    """Longest silence [s] of a log's progress: :data:`INTERVAL_ENV` if set and positive."""
    try:
        value = float(os.environ.get(INTERVAL_ENV, ""))
    except ValueError:
        return HEARTBEAT_S
    return value if value > 0 else HEARTBEAT_S


def _clock(seconds: float) -> str:
    s = int(round(max(seconds, 0.0)))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def _set_verbosity(ctx: click.Context, param: click.Parameter, value: bool) -> None:
    """Option callback: record ``--quiet``/``--verbose`` in the root context's meta."""
    if not value:
        return
    want = QUIET if param.name == "quiet" else VERBOSE
    have = ctx.meta.get(VERBOSITY_KEY)
    if have not in (None, want):
        raise click.UsageError("--quiet and --verbose exclude each other", ctx=ctx)
    ctx.meta[VERBOSITY_KEY] = want


def output_options() -> list[click.Option]:
    """Fresh ``-q/--quiet`` and ``-v/--verbose`` options (eager, not passed to the callback)."""
    common: dict[str, Any] = {"is_flag": True, "expose_value": False, "is_eager": True,
                              "callback": _set_verbosity}
    return [click.Option(["-q", "--quiet"], help="no progress on stderr: only results and errors", **common),
            click.Option(["-v", "--verbose"], help="progress with each stage's time and sub-steps", **common)]


def add_output_options(cmd: click.Command) -> click.Command:
    """Give ``cmd`` (a command or group) ``--quiet`` and ``--verbose`` unless it has them;
    a short name it already uses for something else is left out. Idempotent; returns ``cmd``."""
    taken = {o for p in cmd.params for o in (*p.opts, *p.secondary_opts)}
    names = {p.name for p in cmd.params}
    for opt in output_options():
        if opt.name in names or opt.opts[-1] in taken:
            continue
        opt.opts = [o for o in opt.opts if o not in taken]
        cmd.params.append(opt)
    return cmd


class Progress:
    """Progress of one command: ``update(stage, fraction, note)``; use as a context manager.

    ``mode``: ``"quiet"``, ``"normal"`` or ``"verbose"`` (default: the command line's);
    ``stream``: where to write (default stderr); ``tty``: draw a bar (default: when the stream is
    a terminal); ``interval``: the heartbeat [s] of plain lines; ``transient``: a terminal's bars
    vanish when done; ``stage``: the stage shown from the start (a command that only says what
    it does, :meth:`say`)."""

    def __init__(self, mode: str | None = None, stream: TextIO | None = None, tty: bool | None = None,
                 interval: float | None = None, transient: bool = False, width: int = 28,
                 stage: str | None = None) -> None:
        self.mode = mode or verbosity()
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)()) if tty is None else tty
        self.interval = interval if interval is not None else heartbeat_s()
        self.transient, self.width = transient, width
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._bar: Any = None
        self._tasks: dict[str, Any] = {}
        self.t0 = time.monotonic()
        self.stage: str | None = None
        self.fraction: float | None = None
        self.note = ""
        self._stage_t0 = self.t0
        self._last_line = 0.0
        self.lines = 0   # progress lines written to a log
        self.times: dict[str, float] = {}   # seconds per stage, for --verbose
        self._first = stage

    # -- life ------------------------------------------------------------------------------
    def __enter__(self) -> Progress:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop(ok=exc[0] is None)

    def start(self) -> Progress:
        """Start showing progress (what ``with`` does); returns ``self``."""
        self.t0 = self._stage_t0 = self._last_line = time.monotonic()
        if self.mode == QUIET:
            return self
        if self.tty:
            self._start_bar()
        else:
            self._thread = threading.Thread(target=self._beat, name="skinkit-progress", daemon=True)
            self._thread.start()
        if self._first:
            self.update(self._first, None)
        return self

    def stop(self, ok: bool = True) -> None:
        """Stop showing progress (``ok``: the command succeeded, so a log says it is done)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        with self._lock:
            self._close_stage(time.monotonic())
            if self._bar is not None:
                self._bar.stop()
            if self.mode == VERBOSE and self.times:
                self._print("stage times: " + ", ".join(f"{k} {v:.1f} s" for k, v in self.times.items()))
            if self.lines and ok:
                self._print(f"progress: done in {_clock(time.monotonic() - self.t0)}")

    def _start_bar(self) -> None:
        from rich import progress as rp
        from rich.console import Console
        from rich.table import Column

        def fixed() -> Column:   # the times keep their width; the note gives way on a narrow terminal
            return Column(min_width=7, no_wrap=True)

        # markup off: a model's or protocol's name in brackets or braces is text
        self._bar = rp.Progress(rp.TextColumn(f"{{task.description:<{self.width}}}", markup=False),
                                rp.BarColumn(bar_width=20), rp.TaskProgressColumn(),
                                rp.TimeElapsedColumn(table_column=fixed()), rp.TextColumn("ETA"),
                                rp.TimeRemainingColumn(table_column=fixed()),
                                rp.TextColumn("{task.fields[note]}", markup=False,
                                              table_column=Column(no_wrap=True, overflow="ellipsis")),
                                console=Console(file=self.stream), transient=self.transient)
        self._bar.start()

    # -- reporting -------------------------------------------------------------------------
    def update(self, stage: str, fraction: float | None = None, note: str = "") -> None:
        """Stage ``stage`` is ``fraction`` (0..1; None: unknown) done, now at ``note``."""
        if self.mode == QUIET:
            return
        now = time.monotonic()
        with self._lock:
            new = stage != self.stage
            if new:
                self._close_stage(now)
                self.stage, self._stage_t0 = stage, now
            if self.mode == VERBOSE and note and note != self.note:
                self._print(f"  {stage}: {note} (at {_clock(now - self.t0)})")
            self.fraction = None if fraction is None else min(max(float(fraction), 0.0), 1.0)
            self.note = note
            if self._bar is not None:
                self._bar_update(stage, new)
            elif new and self.lines:   # a long run: its log shows each stage as it starts
                self._line(now)

    def __call__(self, stage: str, fraction: float | None = None) -> None:
        """The ``progress(stage, fraction)`` callback the pipelines take."""
        self.update(stage, fraction)

    def update_note(self, stage: str, fraction: float | None, note: str) -> None:
        """:meth:`update`, under the name :func:`skinkit.forward.stages.feeding` looks for."""
        self.update(stage, fraction, note)

    def say(self, text: str, stdout: bool = False) -> None:
        """A line of what the command does now, as such commands always wrote it: on stderr
        (``stdout``: on stdout, where a command's own account of its work goes); not with
        ``--quiet``, nor with ``--json``, whose stdout is the result and whose stderr is kept for
        progress and errors. It is also the current stage's note."""
        if self.mode == QUIET:
            return
        with self._lock:
            self.note = text.strip()
            if _json_output():
                return
            if stdout and self._bar is None:
                click.echo(text)
            else:
                self._print(text)
            self._last_line = time.monotonic()

    @contextmanager
    def feeding(self, stage: str) -> Iterator[None]:
        """Within the block, :func:`skinkit.forward.stages.report` advances ``stage``."""
        from skinkit.forward import stages  # imported here: `skinkit --help` imports no engine

        self.update(stage, 0.0)
        with stages.reporting(lambda f, note: self.update(stage, f, note)):
            yield

    # -- drawing (under the lock) ----------------------------------------------------------
    def _close_stage(self, now: float) -> None:
        if self.stage is None:
            return
        self.times[self.stage] = self.times.get(self.stage, 0.0) + (now - self._stage_t0)
        if self.mode == VERBOSE:
            self._print(f"  {self.stage}: {now - self._stage_t0:.1f} s")
        if self._bar is not None and self.stage in self._tasks:
            task = self._tasks[self.stage]
            self._bar.update(task, total=1.0, completed=1.0, note="")

    def _bar_update(self, stage: str, new: bool) -> None:
        if new and stage not in self._tasks:
            self._tasks[stage] = self._bar.add_task(stage[:self.width], total=None, note="")
        task = self._tasks[stage]
        if self.fraction is None:
            self._bar.update(task, note=self.note)
        else:
            self._bar.update(task, total=1.0, completed=self.fraction, note=self.note)

    def _eta(self, now: float) -> str:
        f = self.fraction
        if f is None or f <= 0.0:
            return "?"
        return _clock((now - self._stage_t0) * (1.0 - f) / f)

    def _line(self, now: float) -> None:
        pct = "" if self.fraction is None else f" {100 * self.fraction:3.0f} %"
        note = f"  {self.note}" if self.note else ""
        self._print(f"progress: {self.stage}{pct}  elapsed {_clock(now - self.t0)}  "
                    f"ETA {self._eta(now)}{note}")
        self._last_line = now
        self.lines += 1

    def _print(self, text: str) -> None:
        if self._bar is not None:
            self._bar.console.print(text, markup=False, highlight=False)
            return
        try:
            self.stream.write(text + "\n")
            self.stream.flush()
        except (OSError, ValueError):   # the log went away: progress is not worth failing for
            pass

    def _beat(self) -> None:
        """Heartbeat thread: a line whenever none was written for ``interval`` seconds."""
        while True:
            with self._lock:
                wait = self._last_line + self.interval - time.monotonic()
            if self._stop.wait(max(wait, 0.05)):
                return
            with self._lock:
                now = time.monotonic()
                if self.stage is not None and now - self._last_line >= self.interval:
                    self._line(now)


def progress(**kwargs: Any) -> Progress:
    """A :class:`Progress` for the running command (its verbosity); ``kwargs`` as the class."""
    return Progress(**kwargs)


__all__ = ["HEARTBEAT_S", "INTERVAL_ENV", "NORMAL", "QUIET", "VERBOSE", "VERBOSITY_KEY", "Progress",
           "add_output_options", "heartbeat_s", "output_options", "progress", "verbosity"]
