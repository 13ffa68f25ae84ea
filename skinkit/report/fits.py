"""The model identifications (FE and forward-model fits, ``skinkit fit``): parameters ± standard
error, χ²/ν, the correlation matrix, the identifiability problems in words, the residual per
protocol and channel, measured against predicted over time, and the optimiser's path."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit.gap.html_series import section_series
from skinkit.report.common import (
    Section,
    e,
    f,
    figure,
    img,
    kv_table,
    mpl,
    note,
    num,
    pct,
    plural,
    png_uri,
    slug,
    t,
    table,
    unit_text,
    warn_list,
)
from skinkit.report.lumped import is_lumped
from skinkit.schemas import FitResult

#: a correlation at or above this (in magnitude) is printed bold in the matrix
STRONG_CORRELATION = 0.9


def _identifiable(fit: FitResult) -> dict[str, bool]:
    """Per free parameter: whether the identifiability analysis found it determined."""
    ident = fit.identifiability or {}
    given = ident.get("identifiable")
    if isinstance(given, dict):
        return {str(k): bool(v) for k, v in given.items()}
    problems = [pr for pr in ident.get("problems") or [] if isinstance(pr, dict)]
    flagged = {p for pr in problems if pr.get("kind") != "correlated" for p in pr.get("parameters") or []}
    return {n: n not in flagged for n in fit.parameters.free_names}


def _parameters(fit: FitResult) -> str:
    ident = _identifiable(fit)
    rows, classes = [], []
    for p in fit.parameters:
        se = f(fit.se.get(p.name)) if p.free else math.nan
        rel = se / abs(p.value) if p.free and p.value and math.isfinite(se) else math.nan
        if not p.free:
            state = "fixed"
        elif ident.get(p.name, True):
            state = "determined"
        else:
            state = "NOT identifiable from these protocols"
        se_text = "—" if not p.free else ("∞" if math.isinf(se) else num(se, 2))
        bounds = f"[{num(p.lower, 3)}, {num(p.upper, 3)}]" if p.free else "—"
        rows.append([t(p.name, p.name), t(num(p.value, 5), p.value), t(unit_text(p.unit)), t(se_text, se),
                     t("—" if math.isnan(rel) else f"{100 * rel:.2g} %", rel), t(bounds), t(state, state)])
        classes.append("sig" if state.startswith("NOT") else "")
    return table(["parameter", "value", "unit", "± standard error", "relative se", "bounds", "status"], rows,
                 row_classes=classes)


def _correlation_figure(names: list[str], corr: np.ndarray) -> str:
    n = len(names)
    size = max(3.2, 0.55 * n + 1.8)
    fig = figure(size + 0.9, size)
    ax = fig.add_subplot(1, 1, 1)
    im = ax.imshow(corr, cmap="RdBu_r", vmin=-1, vmax=1, aspect="auto")   # "equal" cuts labels
    ax.set_xticks(range(n), [mpl(x) for x in names], rotation=60, ha="right", fontsize=7)
    ax.set_yticks(range(n), [mpl(x) for x in names], fontsize=7)
    if n <= 14:
        for i in range(n):
            for j in range(n):
                v = round(float(corr[i, j]), 2) + 0.0   # no "-0.00"
                ax.text(j, i, f"{v:+.2f}", ha="center", va="center", fontsize=6 if n > 8 else 7,
                        color="white" if abs(v) > 0.6 else "black",
                        weight="bold" if abs(v) >= STRONG_CORRELATION and i != j else "normal")
    fig.colorbar(im, ax=ax, label="correlation [1]", shrink=0.8)
    return png_uri(fig)


def _identifiability(fit: FitResult) -> str:
    ident = fit.identifiability or {}
    problems = [pr for pr in ident.get("problems") or [] if isinstance(pr, dict)]
    out = "<h4>Identifiability</h4>"
    if problems:
        out += "<p>What the analysis at the optimum says (Eqs 7.15–7.18 of the thesis):</p>"
        out += warn_list([str(pr.get("message", pr)) for pr in problems])
    elif ident:
        out += "<p>Every free parameter is determined by these protocols; no pair trades off.</p>"
    else:
        return out + note("The fit stores no identifiability analysis.")
    dirs = [d for d in ident.get("weak_directions") or [] if isinstance(d, dict)]
    if dirs:
        items = []
        for d in dirs:
            couples = (d.get("couples") or {}).items()
            comps = " ".join(f"{'+' if v >= 0 else '−'}{abs(v):.2f}·{k}" for k, v in couples)
            items.append(f"eigenvalue {num(d.get('eigenvalue'), 3)} of the scaled Hessian along "
                         f"{comps or '—'}")
        out += ("<p>Weakest directions (smallest eigenvalues of the Hessian in scaled parameters; a tiny "
                "eigenvalue is a valley of the objective along which the parameters trade off):</p><ul>"
                + "".join(f"<li>{e(x)}</li>" for x in items) + "</ul>")
    metrics = ident.get("metrics") or {}
    if metrics:
        out += kv_table((str(k), num(v, 4)) for k, v in metrics.items())
    return out


def _residuals(fit: FitResult) -> str:
    out = "<h4>Residual per protocol and channel</h4>"
    parts = []
    total = sum(f(v) for v in fit.residual_by_protocol.values() if math.isfinite(f(v)))
    for axis, d in (("protocol", fit.residual_by_protocol), ("channel", fit.residual_by_channel)):
        if not d:
            continue
        rows = [[t(k, k), t(num(v, 5), f(v)),
                 t(pct(f(v) / total) if total > 0 else "—", f(v) / total if total > 0 else None)]
                for k, v in d.items()]
        parts.append(table([axis, "Σz² (noise-normalised)", "share of χ²"], rows))
    if fit.held_out:
        rows = [[t(k, k), t(num(v, 4), f(v))] for k, v in fit.held_out.items()]
        parts.append("<p>Held-out protocols (predicted, not fitted): RMS of the weighted residual, 1 at the "
                     "noise level.</p>" + table(["held-out protocol", "RMS [noise levels]"], rows))
    if not parts:
        return out + note("The fit stores no residual breakdown.")
    fig = ""
    if len(fit.residual_by_protocol) > 1:
        fig = img(_bars(fit.residual_by_protocol), "share of χ² per protocol")
    return out + "".join(parts) + fig


def _bars(d: dict[str, Any]) -> str:
    names = list(d)
    v = np.array([f(d[k]) for k in names])
    fig = figure(7.0, max(1.6, 0.32 * len(names) + 0.9))
    ax = fig.add_subplot(1, 1, 1)
    ax.barh(np.arange(len(names)), np.where(np.isfinite(v), v, 0.0), color="#2e86c1", height=0.7)
    ax.set_yticks(np.arange(len(names)), [mpl(x) for x in names], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("Σz² of the protocol (noise-normalised residual) [1]", fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    return png_uri(fig)


def _history(fit: FitResult) -> str:
    hist = [h for h in fit.extra.get("history") or [] if isinstance(h, dict)]
    obj = np.array([f(h.get("objective")) for h in hist])
    if len(obj) < 2 or not np.isfinite(obj).any():
        return ""
    fig = figure(6.0, 2.6)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(np.arange(1, len(obj) + 1), obj, "o-", ms=3)
    if np.nanmin(obj) > 0 and np.nanmax(obj) / np.nanmin(obj) > 20:
        ax.set_yscale("log")
    ax.set_xlabel("forward evaluation [count]", fontsize=8)
    ax.set_ylabel("objective [1 with the noise weighting]", fontsize=8)
    ax.grid(alpha=0.3)
    ax.tick_params(labelsize=7)
    return img(png_uri(fig), "the optimiser's path: objective per evaluation")


def _starts(fit: FitResult) -> str:
    if len(fit.starts) < 2:
        return ""
    rows = [[t(i + 1, i + 1), t(num(s.get("objective"), 6), f(s.get("objective"))),
             t("yes" if s.get("converged") else "no"),
             t(", ".join(f"{k} = {num(v, 4)}" for k, v in (s.get("parameters") or {}).items()))]
            for i, s in enumerate(fit.starts)]
    return "<h4>Starts</h4>" + table(["start", "objective", "converged", "result"], rows)


def _series(name: str, fit: FitResult, gaps: Mapping[str, Mapping[str, Any]]) -> str:
    """Measured against predicted over time: the fit's own series when it keeps one, else the
    calibrated prediction of a gap report of the same model on this file (the diagnosis
    calibrates the model on the same session; its χ²/ν is said beside this fit's)."""
    out = "<h4>Measured against predicted</h4>"
    series = fit.extra.get("series")
    if isinstance(series, Mapping) and series:
        return out + _nested_series({"series": series}, f"{slug(name)}-series")
    for gname, rep in gaps.items():
        gs = rep.get("series")
        if rep.get("model") != fit.model or not isinstance(gs, Mapping) or not gs:
            continue
        calibrated = _only(gs, "calibrated")
        chi = (rep.get("fit") or {}).get("chi2_per_dof")
        return (out + f"<p>The fit keeps no prediction; drawn is the calibrated model of gap report "
                f"<b>{e(gname)}</b> (the same model calibrated on this session by the diagnosis: χ²/ν "
                f"{e(num(chi, 4))}, this fit's {e(num(fit.chi2_per_dof, 4))}).</p>"
                + _nested_series({"series": calibrated}, f"{slug(name)}-series"))
    return out + note("The fit keeps no prediction and no gap report of its model is stored: measured "
                      "against predicted cannot be drawn (skinkit fit --out draws it beside the fit).")


def _only(series: Mapping[str, Any], label: str) -> dict[str, Any]:
    """``series`` (:mod:`skinkit.gap.series`) with the prediction ``label`` alone."""
    def channel(ch: Mapping[str, Any]) -> dict[str, Any]:
        return {**ch, "predicted": {k: v for k, v in (ch.get("predicted") or {}).items() if k == label}}

    return {p: {**v, "channels": {c: channel(ch) for c, ch in (v.get("channels") or {}).items()}}
            for p, v in series.items() if isinstance(v, Mapping)}


def _nested_series(report: Mapping[str, Any], section_id: str) -> str:
    """The measured-against-predicted section sat inside a fit's block (headings moved down)."""
    html = section_series(report, section_id)
    html = re.sub(r"<(/?)h3>", r"<\1h5>", html)
    return re.sub(r"<h2>.*?</h2>", "", html, count=1)


def _fit(name: str, fit: FitResult, gaps: Mapping[str, Mapping[str, Any]] | None = None) -> str:
    x = fit.extra
    chi = f(fit.chi2_per_dof)
    head = f'<div class="item" id="fit-{slug(name)}"><h3>{e(name)}: model {e(fit.model)}</h3>'
    line = (f"<p>χ²/ν = <b>{e(num(chi, 4))}</b> (1 at the noise level)"
            + (f" on {e(x['n_observations'])} observations" if "n_observations" in x else "")
            + f"; {'converged' if fit.converged else '<b>not converged</b>'}"
            + f"; {fit.n_forward} forward solves ({fit.n_sensitivity} with sensitivities)"
            + (f", {num(fit.wall_s, 3)} s" if fit.wall_s else "")
            + (f"; AIC {e(num(fit.aic, 6))}" if fit.aic is not None else "") + ".</p>")
    facts = [(k, str(x[k])) for k in ("weighting", "optimiser") if k in x]
    if fit.message:
        facts.append(("optimiser's message", fit.message))
    warns = []
    if not fit.converged:
        warns.append("The optimiser did not converge: the values are where it stopped.")
    if math.isfinite(chi) and chi > 2:
        warns.append(f"χ²/ν = {num(chi, 3)}: the model misses the data beyond the noise (see the gap "
                     "reports); the standard errors are inflated by √(χ²/ν).")
    body = head + line + warn_list(warns) + _parameters(fit)
    free = fit.parameters.free_names
    if fit.correlation is not None and len(free) > 1:
        body += "<h4>Correlation of the free parameters</h4>" + img(
            _correlation_figure(free, np.asarray(fit.correlation, float)), f"{name}: correlation matrix")
    body += _series(name, fit, gaps or {})
    body += _identifiability(fit) + _residuals(fit) + _history(fit) + _starts(fit)
    if facts:
        body += kv_table(facts)
    return body + "</div>"


def section(fits: dict[str, FitResult], gaps: Mapping[str, Mapping[str, Any]] | None = None) -> Section:
    """The model identifications among ``fits`` (name → stored FitResult; the lumped ones are
    left to :mod:`skinkit.report.lumped`); ``gaps``: the file's gap reports (name → JSON dict),
    whose calibrated predictions stand in for a fit that keeps none."""
    mine = {n: r for n, r in fits.items() if not is_lumped(r)}
    title = "Model fits (identification)"
    if not mine:
        return Section("fits", title, None, "omitted: the file holds no model identification (/fits)")
    intro = ("<p>Parameters identified by fitting a model's predictions of the session to its records "
             "(<code>skinkit fit</code>), SI units. The standard errors come from the Gauss–Newton "
             "covariance at the optimum, inflated by χ²/ν when the fit is worse than the noise.</p>")
    body = intro + "".join(_fit(n, r, gaps) for n, r in mine.items())
    what = ", ".join(f"{n} (χ²/ν {num(r.chi2_per_dof, 3)})" for n, r in mine.items())
    return Section("fits", title, body, f"{plural(len(mine), 'fit')}: {what}")
