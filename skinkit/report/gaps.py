"""The gap reports (``/gaps/<name>``), each drawn by the gap report's own section renderers
(:mod:`skinkit.gap.html`: verdict, fit, measured against predicted, residual by
protocol/phase/channel, surface maps, the region scan's map when there was one, score ranking,
shrinkage, non-separable pairs, whiteness tests, naming rounds) nested in one section.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

from skinkit.gap import html as gap_html
from skinkit.gap.html_scan import section_scan
from skinkit.gap.html_series import section_series
from skinkit.report.common import Section, e, plural, slug
from skinkit.store.experiment import Experiment


def _scan(report: Mapping[str, Any]) -> str:
    """The region section, only for a report that scanned a region (the others have nothing to say)."""
    return section_scan(report) if report.get("region_scan") else ""


#: the gap report's sections, in its own order
RENDERERS = (gap_html._section_verdict, gap_html._section_fit, section_series, gap_html._section_residual,
             gap_html._section_maps, _scan, gap_html._section_scores, gap_html._section_shrinkage,
             gap_html._section_separation, gap_html._section_tests, gap_html._section_rounds)


def _nest(fragment: str, prefix: str) -> str:
    """A gap-report fragment made to sit inside this report: its ids prefixed (two reports in one
    page must not share ids) and its headings one level down (h2 → h3, h3 → h4)."""
    fragment = re.sub(r'(<section id=")([^"]+)"', lambda m: f'{m.group(1)}{prefix}-{m.group(2)}"', fragment)
    fragment = re.sub(r"<(/?)h3>", r"<\1h4>", fragment)
    return re.sub(r"<(/?)h2>", r"<\1h3>", fragment)


def _verdict_word(report: Mapping[str, Any]) -> str:
    named = [str(n) for n in report.get("named") or []]
    if named:
        return "named " + ", ".join(named)
    sig = (report.get("gap") or {}).get("significant")
    if sig is None:
        return "no verdict"
    return "significant gap, nothing named" if sig else "no significant gap"


def _gap(name: str, report: Mapping[str, Any]) -> str:
    prefix = f"gap-{slug(name)}"
    who = " · ".join(x for x in (f"model {report.get('model')}" if report.get("model") else "",
                                 f"session {report.get('session')}" if report.get("session") else "") if x)
    parts = "".join(_nest(r(report), prefix) for r in RENDERERS)
    return (f'<div class="item gapreport" id="{prefix}"><h3>{e(name)}</h3>'
            + (f'<p class="sub">{e(who)}</p>' if who else "") + parts + "</div>")


def section(exp: Experiment) -> Section:
    """The gap reports of the file."""
    names = exp.gap_names()
    if not names:
        return Section("gaps", "Gap reports", None, "omitted: the file holds no gap report (/gaps)")
    reports = {n: exp.read_gap(n) for n in names}
    bad = [n for n, r in reports.items() if not isinstance(r, Mapping)]
    if bad:
        from skinkit.errors import StoreError

        raise StoreError(str(exp.path), f"/gaps/{bad[0]}", "is not a gap report (its JSON is not an object)")
    body = ("<p>Where the calibrated model misses the session beyond the noise, which installed effect "
            "explains it, and how far the gap shrinks with it (<code>skinkit gap diagnose</code>).</p>"
            + "".join(_gap(n, r) for n, r in reports.items()))
    what = "; ".join(f"{n}: {_verdict_word(r)}" for n, r in reports.items())
    return Section("gaps", "Gap reports", body, f"{plural(len(names), 'report')} ({what})")
