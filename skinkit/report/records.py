"""The robot records: one table of every record, then per record its channels against time and
their statistics."""

from __future__ import annotations

from typing import Any

import numpy as np

from skinkit.report.common import (
    Section,
    decimate,
    e,
    f,
    figure,
    img,
    mpl,
    note,
    num,
    plural,
    png_uri,
    slug,
    t,
    table,
    warn_list,
)
from skinkit.schemas import RobotRecord
from skinkit.schemas.robot import FLAG_CAMERA_TRIGGER, FLAG_NAMES
from skinkit.store.experiment import Experiment

#: how a channel is drawn: the SI unit is scaled into the display unit
DISPLAY = {"m": ("mm", 1e3), "N m": ("N mm", 1e3)}
AXES = {"tip": ("x", "y", "z"), "motor": ("1", "2", "3")}


def _display(unit: str) -> tuple[str, float]:
    return DISPLAY.get(unit, (unit, 1.0))


def _axes(channel: str) -> tuple[str, ...]:
    return AXES["motor" if channel.startswith("motor") else "tip"]


def _live(x: np.ndarray) -> list[int]:
    """The columns of ``x`` ``(N, 3)`` that carry data (some finite sample, not all zero)."""
    return [k for k in range(x.shape[1])
            if np.isfinite(x[:, k]).any() and np.nanmax(np.abs(x[:, k])) > 0]


def _figure_record(rec: RobotRecord) -> str:
    """Every channel against time, one panel per channel, its live axes as lines."""
    chans = [c for c in rec.channels if _live(getattr(rec, c))] or rec.channels
    fig = figure(8.5, 1.2 + 1.9 * len(chans))
    s = decimate(rec.n_samples)
    tt = rec.time_s[s]
    trig = rec.time_s[(rec.flags & FLAG_CAMERA_TRIGGER) != 0]
    for i, c in enumerate(chans):
        ax = fig.add_subplot(len(chans), 1, i + 1)
        x = getattr(rec, c)
        unit, scale = _display(RobotRecord.CHANNELS[c])
        for k in _live(x):
            ax.plot(tt, x[s, k] * scale, lw=0.6, label=_axes(c)[k])
        ax.set_ylabel(f"{mpl(c.replace('_', ' '))} [{mpl(unit)}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        if len(_live(x)) > 1:
            ax.legend(fontsize=7, loc="upper right", ncols=3)
        if i == 0 and trig.size:
            ax.plot(trig, np.full(trig.size, 0.02), "|", color="k", ms=6, transform=ax.get_xaxis_transform(),
                    label="camera trigger")
        if i < len(chans) - 1:
            ax.tick_params(labelbottom=False)
    fig.axes[-1].set_xlabel("time [s]", fontsize=8)
    fig.suptitle(mpl(f"{rec.protocol.name}: {rec.n_samples} samples"
                     + (f", {len(trig)} camera triggers (ticks)" if trig.size else "")), fontsize=9)
    return png_uri(fig)


def _stats(rec: RobotRecord) -> str:
    rows = []
    for c in rec.channels:
        x = getattr(rec, c)
        unit, scale = _display(RobotRecord.CHANNELS[c])
        for k in _live(x):
            v = x[:, k][np.isfinite(x[:, k])] * scale
            rows.append([t(c, c), t(_axes(c)[k]), t(unit),
                         *(t(num(q, 4), float(q)) for q in (v.mean(), v.std(), v.min(), v.max(), np.ptp(v))),
                         t(num(100 * (1 - v.size / x.shape[0]), 2) + " %", 1 - v.size / x.shape[0])])
    if not rows:
        return note("No channel of this record carries data.")
    return table(["channel", "axis", "unit", "mean", "std", "min", "max", "peak to peak", "missing"], rows)


def _flags(rec: RobotRecord) -> str:
    counts = [(name, int(((rec.flags & bit) != 0).sum())) for bit, name in FLAG_NAMES.items()]
    counts = [(n, c) for n, c in counts if c]
    if not counts:
        return "<p>No sample carries a flag.</p>"
    return "<p>Flagged samples: " + ", ".join(f"{e(n)} {c}" for n, c in counts) + ".</p>"


def _record(exp: Experiment, info: dict[str, Any]) -> str:
    name = info["protocol"]
    rec = exp.read_record(name)
    head = f'<div class="item" id="record-{slug(name)}"><h3>{e(name)}</h3>'
    if rec.n_samples < 2:
        return head + note(f"{rec.n_samples} committed sample(s): nothing to draw.") + "</div>"
    desc = rec.protocol.description
    intro = f"<p>{e(desc)}</p>" if desc else ""
    warns = []
    if not info["complete"]:
        warns.append("The record is incomplete: its writer did not close it (only committed samples shown).")
    lost = info["extra"].get("samples_lost")
    if lost:
        warns.append(f"{lost} samples were lost on the link.")
    fig = img(_figure_record(rec), f"{name}: channels against time")
    return head + intro + warn_list(warns) + fig + _stats(rec) + _flags(rec) + "</div>"


def section(exp: Experiment) -> Section:
    """The robot records (``/records``): a table of all, then each record's channels against time
    (positions in mm), per-axis statistics and flag counts."""
    names = exp.record_names()
    if not names:
        return Section("records", "Robot records", None, "omitted: the file holds no robot record")
    infos = [exp.record_info(n) for n in names]
    rows = []
    for r in infos:
        lost = r["extra"].get("samples_lost")
        rows.append([t(r["protocol"], r["protocol"]), t(r["kind"] or "?"), t(r["samples"], r["samples"]),
                     t(num(r["rate_hz"], 6), f(r["rate_hz"])), t(num(r["duration_s"], 5), f(r["duration_s"])),
                     t(", ".join(f"{c} [{u}]" for c, u in r["units"].items())),
                     t(("yes" if r["complete"] else "no") + (f" ({lost} lost)" if lost else ""))])
    header = ["protocol", "kind", "samples", "rate [Hz]", "duration [s]", "channels", "complete"]
    overview = table(header, rows)
    body = overview + "".join(_record(exp, r) for r in infos)
    total = sum(r["duration_s"] for r in infos)
    return Section("records", "Robot records", body, f"{plural(len(names), 'record')}, {total:.4g} s in all")
