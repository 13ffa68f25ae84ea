"""What every section of the session report shares: the :class:`Section` it returns, and the
HTML and figure helpers of the gap report (:mod:`skinkit.gap.html`), re-exported so that the
two reports look alike and the helpers live in one place.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from skinkit import jsonio
from skinkit.gap.html import _CSS, _JS
from skinkit.gap.html import _array_uri as array_uri
from skinkit.gap.html import _e as e
from skinkit.gap.html import _f as f
from skinkit.gap.html import _figure as figure
from skinkit.gap.html import _img as img
from skinkit.gap.html import _mpl as mpl
from skinkit.gap.html import _num as num
from skinkit.gap.html import _p as p
from skinkit.gap.html import _pct as pct
from skinkit.gap.html import _png_uri as png_uri
from skinkit.gap.html import _t as t
from skinkit.gap.html import _table as table
from skinkit.units import is_dimensionless_text

__all__ = ["CSS", "JS", "MAX_PLOT_POINTS", "MAX_PLOT_SAMPLES", "MAX_VALUE_CHARS", "Section", "array_uri",
           "decimate", "e", "f", "figure", "img", "kv_table", "mpl", "note", "num", "p", "pct", "plural",
           "png_uri", "quantity_text", "slug", "t", "table", "unit_text", "value_text", "warn_list"]

#: at most this many samples of a signal are drawn (more add nothing at a figure's resolution)
MAX_PLOT_SAMPLES = 20_000
#: at most this many points of a cloud are drawn
MAX_PLOT_POINTS = 20_000
#: longest value text shown in a table cell (long arrays are cut, the file has them whole)
MAX_VALUE_CHARS = 160


@dataclass
class Section:
    """One section of the report.

    Attributes:
        id: the HTML id of the ``<section>`` (``#id`` links to it).
        title: its heading.
        html: the section's body (already escaped HTML); None when the file has nothing for it.
        summary: one line for the contents list: what the section shows, or why it is omitted.
    """

    id: str
    title: str
    html: str | None
    summary: str

    def render(self) -> str:
        """The whole ``<section>`` element ('' for an omitted section)."""
        if self.html is None:
            return ""
        return f'<section id="{e(self.id)}" class="part"><h2>{e(self.title)}</h2>{self.html}</section>'


def slug(text: str) -> str:
    """``text`` as a fragment of an HTML id: letters, digits, '-' and '_' only."""
    s = re.sub(r"[^A-Za-z0-9_-]+", "-", str(text)).strip("-")
    return s or "x"


def plural(n: int, word: str, words: str | None = None) -> str:
    """'1 record', '3 records'."""
    return f"{n} {word if n == 1 else (words or word + 's')}"


def kv_table(rows: Iterable[tuple[str, Any]]) -> str:
    """A two-column table (name, value) of plain values, not sortable."""
    return table(["", "value"], ([t(k), t(v if isinstance(v, str) else num(v, 6))] for k, v in rows),
                 sortable=False)


def value_text(v: Any, digits: int = 4, limit: int = MAX_VALUE_CHARS) -> str:
    """Any JSON value as short plain text: numbers rounded, lists of numbers rounded each,
    other containers as compact JSON; cut at ``limit`` characters (the file has it whole)."""
    s = _value_text(v, digits)
    return s if len(s) <= limit else s[:limit] + " …"


def _value_text(v: Any, digits: int) -> str:

    if isinstance(v, bool) or v is None:
        return str(v)
    if isinstance(v, (int, float, np.number)):
        return num(v, digits)
    if isinstance(v, (list, tuple)) and v and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                   for x in v):
        return "[" + ", ".join(num(x, digits) for x in v) + "]"
    if isinstance(v, (list, tuple, Mapping)):
        return jsonio.dumps(v, default=str)
    return str(v)


def unit_text(unit: str | None) -> str:
    """A unit for a unit column: ``""`` for a dimensionless quantity (no bare ``1``)."""
    return "" if is_dimensionless_text(unit) else str(unit).strip()


def quantity_text(v: Any, unit: str | None, digits: int = 4) -> str:
    """A value with its unit for people: ``"12.5 kPa"``; a dimensionless value bare."""
    u = unit_text(unit)
    s = value_text(v, digits)
    return f"{s} {u}" if u else s


def decimate(n: int, limit: int = MAX_PLOT_SAMPLES) -> slice:
    """A stride that keeps at most ``limit`` of ``n`` samples (for drawing only)."""
    return slice(None, None, max(1, math.ceil(n / limit)))


def note(text: str) -> str:
    """A grey italic remark (escaped here)."""
    return f'<p class="note">{e(text)}</p>'


def warn_list(items: Sequence[str]) -> str:
    """Warnings as a highlighted list ('' when none)."""
    if not items:
        return ""
    return '<ul class="warn">' + "".join(f"<li>{e(x)}</li>" for x in items) + "</ul>"


#: styles of the session report, added to the gap report's
CSS = _CSS + """
.part{margin-top:2.2em}.part>h2{font-size:1.35em;border-bottom:2px solid #aab7b8}
.item{margin-left:.4em}
ol.contents li{margin:.15em 0}ol.contents .omitted{color:#7f8c8d}
ul.warn{background:#fef5e7;border-left:5px solid #e67e22;padding:.4em 1.6em;list-style:square}
.gapreport section h3{font-size:1.05em}
.meta td:first-child{font-weight:600}
.thumbs figure{display:inline-block;margin:.3em .6em .3em 0;vertical-align:top}
"""
JS = _JS
