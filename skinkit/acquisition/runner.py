"""The protocol runner: any driver, any protocol, samples streamed into the experiment store.

Each block the driver yields is appended and flushed before the next is requested, so a
fault, a dead link or a crash leaves every sample received so far in the file (the record
is then marked incomplete). The driver is left de-energised whatever happens.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from skinkit import jsonio
from skinkit.errors import SkinkitError
from skinkit.schemas import Protocol, RobotRecord
from skinkit.schemas.robot import FLAG_SAMPLES_LOST

DEFAULT_CHANNELS = (
    "motor_position",
    "motor_current",
    "motor_force",
    "tip_position",
    "tip_force",
    "tip_torque",
)


@dataclass
class RunSummary:
    """Outcome of one run: samples written, samples the link lost, fault message (or None)."""

    protocol: str
    samples: int = 0
    lost: int = 0
    duration_s: float = 0.0
    wall_s: float = 0.0
    fault: str | None = None
    driver_stats: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The run's accounting as a plain dict (JSON-ready)."""
        return {
            "protocol": self.protocol,
            "samples": self.samples,
            "lost": self.lost,
            "duration_s": self.duration_s,
            "wall_s": self.wall_s,
            "fault": self.fault,
            "driver": self.driver_stats,
        }


def _progress(enabled: bool):  # noqa: ANN202
    if not enabled:
        return None
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:.1f}/{task.total:.1f} s"),
        TextColumn("{task.fields[samples]} samples, {task.fields[lost]} lost"),
        TimeRemainingColumn(),
        transient=False,
    )


def run_protocol(
    driver: Any,
    protocol: Protocol,
    experiment: Any,
    *,
    channels: tuple[str, ...] = DEFAULT_CHANNELS,
    progress: bool | Callable[[float, float, int, int], None] = False,
    rate_hz: float | None = None,
) -> RunSummary:
    """Execute ``protocol`` through a connected, homed ``driver`` into ``experiment``.

    ``experiment`` is an open, writable :class:`skinkit.store.Experiment`. Returns a
    :class:`RunSummary`; re-raises the driver's :class:`SkinkitError` (after writing every
    sample received and emergency-stopping the driver) when the run faults. ``progress``: True
    shows a bar; a callable is told ``(seconds run, seconds of the protocol, samples, samples
    lost)`` after each block.
    """
    summary = RunSummary(protocol.name)
    # drivers check the programme against their limits here, before any record is created
    blocks = driver.run(protocol)
    total = protocol.duration_s or 0.0
    bar = _progress(progress is True)
    t0 = time.monotonic()
    task = None
    if bar is not None:
        bar.start()
        task = bar.add_task(protocol.name, total=max(total, 1e-9), samples=0, lost=0)
    try:
        with experiment.record_writer(protocol, channels=list(channels), rate_hz=rate_hz) as writer:
            try:
                for block in blocks:
                    if not isinstance(block, RobotRecord):
                        raise SkinkitError(
                            f"driver {getattr(driver, 'name', '?')} yielded "
                            f"{type(block).__name__}, not a RobotRecord"
                        )
                    writer.append(block)
                    summary.samples = writer.n_samples
                    summary.lost += int((block.flags & FLAG_SAMPLES_LOST).astype(bool).sum())
                    summary.duration_s = float(block.time_s[-1])
                    if bar is not None:
                        bar.update(
                            task,
                            completed=min(summary.duration_s, total or summary.duration_s),
                            samples=summary.samples,
                            lost=summary.lost,
                        )
                    if callable(progress):
                        progress(summary.duration_s, total, summary.samples, summary.lost)
            except BaseException as exc:
                summary.fault = str(exc) or type(exc).__name__
                try:
                    driver.emergency_stop()
                finally:
                    raise
    finally:
        summary.wall_s = time.monotonic() - t0
        stats = getattr(driver, "last_run", None)
        if stats is not None and hasattr(stats, "to_dict"):
            summary.driver_stats = stats.to_dict()
            summary.lost = max(summary.lost, int(stats.lost))
        if bar is not None:
            bar.stop()
        _store_accounting(experiment, summary)
    return summary


def _store_accounting(experiment: Any, summary: RunSummary) -> None:
    """Keep the link's sample accounting with the record (``extra`` attributes ``samples_lost``
    and ``link``), fault or not."""
    setter = getattr(experiment, "set_record_attrs", None)
    if setter is None:
        return
    try:
        setter(summary.protocol, samples_lost=int(summary.lost),
               link=json.loads(jsonio.dumps(summary.to_dict(), default=str)))
    except Exception:  # noqa: BLE001 - never mask the run's own error with an accounting failure
        pass
