"""The "measured against predicted" section of the HTML reports: per protocol one figure, a row
per channel and a column per component, the measured samples against each model's prediction over
time, drawn from the compact series of :mod:`skinkit.gap.series` (a report's ``series`` key).

Used by the gap report (:mod:`skinkit.gap.html`) and by the session report's fits and gap
sections. Figures are made on matplotlib's Agg canvas directly (no pyplot, no global state) and
embedded as base64 PNG ``data:`` URIs.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Mapping
from typing import Any

import numpy as np

#: display unit and factor of each SI unit a channel may carry (millimetres read better than metres)
DISPLAY_UNIT = {"m": ("mm", 1e3), "N": ("N", 1.0)}
#: colours of the predictions, in the order the series lists them (the measured samples are grey)
COLOURS = ("#c0392b", "#2e86c1", "#1e8449", "#8e44ad")


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _values(rows: Any, scale: float) -> np.ndarray:
    """A list of samples (None: not measured) as floats [display unit], NaN for None."""
    return np.array([np.nan if v is None else float(v) for v in rows or []], float) * scale


def _png_uri(fig: Any) -> str:
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=90)
    finally:
        fig.clear()
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _shown(ch: Mapping[str, Any]) -> list[int]:
    """The components of a channel with any finite sample, measured or predicted."""
    out = []
    for j, _ in enumerate(ch.get("components") or []):
        series = [ch.get("measured") or []] + list((ch.get("predicted") or {}).values())
        if any(j < len(s) and np.isfinite(_values(s[j], 1.0)).any() for s in series):
            out.append(j)
    return out


def series_figure(protocol: str, channels: Mapping[str, Mapping[str, Any]]) -> str | None:
    """One protocol's figure: rows = channels, columns = components; measured as grey dots,
    each prediction as a line; time [s] across, the channel's quantity and unit up. A PNG data
    URI, or None when no channel has a finite sample."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows = [(name, ch, _shown(ch)) for name, ch in channels.items() if isinstance(ch, Mapping)]
    rows = [r for r in rows if r[2]]
    if not rows:
        return None
    ncol = max(len(r[2]) for r in rows)
    fig = Figure(figsize=(3.6 * ncol + 0.6, 2.3 * len(rows) + 0.5), layout="constrained")
    FigureCanvasAgg(fig)
    for i, (name, ch, comps) in enumerate(rows):
        unit, scale = DISPLAY_UNIT.get(str(ch.get("unit")), (str(ch.get("unit") or "1"), 1.0))
        t = _values(ch.get("time_s"), 1.0)
        for k, j in enumerate(comps):
            ax = fig.add_subplot(len(rows), ncol, i * ncol + k + 1)
            meas = ch.get("measured") or []
            if j < len(meas):
                ax.plot(t, _values(meas[j], scale), ".", color="0.55", ms=2.5, label="measured")
            drawn = 0
            for c, (label, pred) in enumerate((ch.get("predicted") or {}).items()):
                if j < len(pred) and np.isfinite(_values(pred[j], 1.0)).any():
                    drawn += 1
                    ax.plot(t, _values(pred[j], scale), "-", color=COLOURS[c % len(COLOURS)], lw=1.2,
                            label=f"predicted: {label}".replace("$", r"\$"))
            if not drawn:   # a component the model does not predict (off its axis): said, not blank
                ax.text(0.5, 0.95, "not predicted", transform=ax.transAxes, ha="center", va="top",
                        fontsize=7, color="0.3")
            comp = ch["components"][j]
            ax.set_ylabel(f"{ch.get('quantity', name)} {comp} [{unit}]", fontsize=7)
            ax.set_xlabel("time [s]", fontsize=7)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
            if i == 0 and k == 0:
                ax.legend(fontsize=6, loc="best")
    fig.suptitle(f"{protocol}: measured against predicted".replace("$", r"\$"), fontsize=9)
    return _png_uri(fig)


def section_series(report: Mapping[str, Any], section_id: str = "series") -> str:
    """The section (HTML): a heading, a sentence on what is drawn, and per protocol of
    ``report["series"]`` its figure in a ``<div class="series" data-protocol="...">``; a note
    when the report keeps no series."""
    head = f'<section id="{_e(section_id)}"><h2>Measured against predicted over time</h2>'
    series = report.get("series")
    if not isinstance(series, Mapping) or not series:
        return head + ('<p class="note">The report keeps no predicted time series: measured against '
                       "predicted cannot be drawn.</p></section>")
    intro = ("<p>Per protocol, every channel the models predict: the measured samples (grey dots) "
             "against each model's prediction (lines), on at most 500 evenly spread samples. Tracked "
             "points are drawn as the mean displacement of the points from their reference positions "
             "(over the points measured and predicted at each frame); forces in N, positions and "
             "displacements in mm.</p>")
    parts = []
    for proto, entry in series.items():
        chans = entry.get("channels") if isinstance(entry, Mapping) else None
        uri = series_figure(str(proto), chans) if isinstance(chans, Mapping) else None
        held_out = isinstance(entry, Mapping) and entry.get("held_out")
        held = " (held out: predicted, not fitted)" if held_out else ""
        body = (f'<figure><img src="{uri}" alt="{_e(proto)}: measured against predicted">'
                f"<figcaption>{_e(proto)}{_e(held)}: measured against predicted</figcaption></figure>"
                if uri else '<p class="note">No finite sample to draw.</p>')
        parts.append(f'<div class="series" data-protocol="{_e(proto)}"><h3>{_e(proto)}{_e(held)}</h3>'
                     f"{body}</div>")
    return head + intro + "".join(parts) + "</section>"


__all__ = ["section_series", "series_figure"]
