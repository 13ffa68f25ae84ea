"""What a person sees of a gap report in Python: ``repr`` (at most
:data:`~skinkit.schemas.display.MAX_LINES` lines: the calibration, where the gap is, the effects
named with their parameters, the best candidates), a notebook table of the candidates, and two
pandas tables: the residual's cells and the candidates (:func:`gap_frame`).

Every residual is noise-normalised, so χ²/ν = 1 is the noise level (see
:class:`skinkit.schemas.GapReport`). The report is read by its attributes (duck typing).
"""

from __future__ import annotations

from typing import Any

from skinkit.schemas.display import MAX_LINES, frame, html_table, more, num, percent, table
from skinkit.units import unit_suffix

#: candidates listed by ``repr`` and the notebook view (the DataFrame has them all)
MAX_CANDIDATES = 5
#: the tables :meth:`GapReport.to_dataframe` makes, and their columns
CELL_COLUMNS = ("axis", "label", "share", "chi2_per_dof", "p_value", "significant", "chi2", "dof", "n",
                "chi2_per_dof_after")
CANDIDATE_COLUMNS = ("effect", "named", "role", "score", "dof", "p_value", "significant", "refitted",
                     "delta_aic", "shrinkage", "parameters")
TABLES = ("candidates", "cells")


def cell_records(report: Any) -> list[dict[str, Any]]:
    """One record per cell of the calibrated model's residual (per protocol, channel, phase,
    frequency band, ...): its ``share`` of the excess, ``chi2_per_dof``, ``p_value``,
    ``significant``, ``chi2``, ``dof``, ``n`` (samples), and ``chi2_per_dof_after`` (once the
    named effects are added; None without)."""
    after = {(c.get("axis"), c.get("label")): c.get("after") for c in report.shrinkage.get("cells") or []
             if isinstance(c, dict)}
    out = []
    for c in report.gap.get("cells") or []:
        rec = {k: c.get(k) for k in CELL_COLUMNS[:-1]}
        rec["chi2_per_dof_after"] = after.get((c.get("axis"), c.get("label")))
        out.append(rec)
    return out


def _parameters_text(params: dict[str, Any] | None) -> str:
    """``"g1 = 0.33 ± 0.013, tau1 = 2.1 ± 0.23 s"`` from a candidate's ``parameters``."""
    if not params:
        return ""
    return ", ".join(f"{k} = {num(v.get('value'))} ± {num(v.get('se'))}{unit_suffix(v.get('unit', '1'))}"
                     for k, v in params.items())


def candidate_records(report: Any) -> list[dict[str, Any]]:
    """One record per candidate effect of the first round, ranked by its score test:
    ``effect``, ``named`` (named a cause of the gap), ``role``, ``score``, ``dof``, ``p_value``,
    ``significant``, ``refitted``, ``delta_aic``, ``shrinkage`` (fraction of the excess removed)
    and ``parameters`` (the refit's values ± se, as text)."""
    named = set(report.named)
    return [{"effect": c.effect, "named": c.effect in named, "role": c.extra.get("role"), "score": c.score,
             "dof": c.dof, "p_value": c.p_value, "significant": c.extra.get("significant"),
             "refitted": c.refitted, "delta_aic": c.delta_aic, "shrinkage": c.shrinkage,
             "parameters": _parameters_text(c.parameters)} for c in report.candidates]


def _where(report: Any) -> str:
    """The significant cells, largest share of the excess first (at most three)."""
    cells = [c for c in report.gap.get("cells") or [] if c.get("significant") and c.get("share")]
    cells.sort(key=lambda c: -float(c["share"]))
    return ", ".join(f"{c.get('label')} {percent(c['share'])}" for c in cells[:3])


def _named_lines(report: Any) -> list[str]:
    if not report.named:
        return ["  named: none"]
    by = {c.effect: c for c in report.candidates}
    after = (report.extra.get("remaining") or {}).get("chi2_per_dof")
    sh = report.shrinkage
    lines = [f"  named: {', '.join(report.named)}; χ²/ν after {num(after)}, excess removed "
             f"{percent(sh.get('overall'))} (held out {percent(sh.get('held_out'))})"]
    for e in report.named[:2]:
        text = _parameters_text(by[e].parameters) if e in by else ""
        if text:
            lines.append(f"    {text}")
    return lines


def _candidate_rows(report: Any) -> list[list[str]]:
    return [[r["effect"], num(r["score"], ".4g"), num(r["p_value"], ".2g"), num(r["delta_aic"], ".1f"),
             percent(r["shrinkage"]) if r["refitted"] else "—", r["role"] or ""]
            for r in candidate_records(report)[:MAX_CANDIDATES]]


_CANDIDATE_HEADER = ["effect", "score", "p", "ΔAIC", "removed", "role"]


def gap_lines(report: Any) -> list[str]:
    """The text of ``repr(GapReport)`` (at most :data:`MAX_LINES` lines)."""
    fit = report.fit
    lines = [f"GapReport {report.model} on {report.session or '(observations)'}",
             f"  calibration: {len(fit.get('parameters') or {})} free parameter(s), "
             f"χ²/ν {num(fit.get('chi2_per_dof'))}"]
    gap = report.gap
    state = "significant" if report.significant else "at the noise level"
    where = _where(report)
    lines.append(f"  gap: {state} (χ²/ν {num(gap.get('chi2_per_dof'))}, p {num(gap.get('p_value'), '.2g')})"
                 + (f"; in {where} of the excess" if where else ""))
    lines += _named_lines(report)
    n = len(report.candidates)
    if n:
        lines += table(_candidate_rows(report), _CANDIDATE_HEADER)
        lines += more(min(n, MAX_CANDIDATES), n, "to_dataframe('candidates')")
    warnings = report.extra.get("warnings") or []
    tail = [f"{len(warnings)} warning(s)"] if warnings else []
    if report.extra.get("messages"):
        tail.append("the verdict in words: .extra['messages']")
    if tail:
        lines.append("  " + "; ".join(tail))
    return lines[:MAX_LINES]


def gap_html(report: Any) -> str:
    """The notebook view of a gap report: its candidates in a table, the verdict below."""
    state = "significant gap" if report.significant else "no significant gap"
    notes = ([str(m) for m in report.extra.get("messages") or []]
             or [f"named: {', '.join(report.named) or 'none'}"])
    return html_table(f"GapReport {report.model}: {state}", _CANDIDATE_HEADER, _candidate_rows(report), notes)


def gap_frame(report: Any, which: str = "candidates") -> Any:
    """A DataFrame of the report's ``"candidates"`` (columns :data:`CANDIDATE_COLUMNS`) or of the
    residual's ``"cells"`` (columns :data:`CELL_COLUMNS`)."""
    if which == "candidates":
        return frame(candidate_records(report), CANDIDATE_COLUMNS)
    if which == "cells":
        return frame(cell_records(report), CELL_COLUMNS)
    raise ValueError(f"to_dataframe: the table is one of {list(TABLES)}, got {which!r}")


__all__ = ["CANDIDATE_COLUMNS", "CELL_COLUMNS", "TABLES", "candidate_records", "cell_records", "gap_frame",
           "gap_html", "gap_lines"]
