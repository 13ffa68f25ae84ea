"""The lumped (system-identification) fits: K, B, I of the linear model, the Wiener or Hammerstein
nonlinearity; each with its standard errors, its VAF and the identification's warnings.

They are the ``/fits/<name>`` whose :class:`FitResult` carries a variance accounted for (an
``extra`` key starting with ``vaf``), as ``skinkit demo`` stores them; the other fits are model
identifications (:mod:`skinkit.report.fits`).
"""

from __future__ import annotations

import math
from typing import Any

from skinkit.report.common import Section, e, f, note, num, plural, slug, t, table, unit_text, warn_list
from skinkit.schemas import FitResult
from skinkit.store.experiment import Experiment


def is_lumped(fit: FitResult) -> bool:
    """Whether ``fit`` is a system identification (it reports a VAF)."""
    return any(str(k).lower().startswith("vaf") for k in fit.extra)


def _se(fit: FitResult, name: str, index: int | None) -> float:
    """A parameter's standard error [SI]: from ``se``, else the covariance's diagonal; NaN if neither."""
    if name in fit.se:
        return f(fit.se[name])
    if fit.covariance is not None and index is not None:
        v = float(fit.covariance[index][index])
        return math.sqrt(v) if v >= 0 else math.nan
    return math.nan


def _vafs(fit: FitResult) -> list[tuple[str, float]]:
    out = []
    for k, v in fit.extra.items():
        if str(k).lower().startswith("vaf"):
            label = "VAF" + str(k)[3:].removesuffix("_pct").replace("_", " ")
            out.append((label, f(v)))
    return out


def _warnings(fit: FitResult) -> list[str]:
    w: Any = fit.extra.get("warnings", fit.extra.get("issues", []))
    return [str(x) for x in w] if isinstance(w, (list, tuple)) else [str(w)]


def _fit(name: str, fit: FitResult) -> str:
    free = fit.parameters.free_names
    rows = []
    for p in fit.parameters:
        se = _se(fit, p.name, free.index(p.name) if p.name in free else None)
        rel = se / abs(p.value) if p.value and math.isfinite(se) else math.nan
        rows.append([t(p.name, p.name), t(num(p.value, 5), p.value), t(unit_text(p.unit)),
                     t(num(se, 2), se), t("—" if math.isnan(rel) else f"{100 * rel:.2g} %", rel)])
    vafs = ", ".join(f"{e(k)} <b>{num(v, 4)} %</b>" for k, v in _vafs(fit))
    samples = f"; {fit.n_evaluations} samples" if fit.n_evaluations else ""
    head = (f'<div class="item" id="lumped-{slug(name)}"><h3>{e(name)}: model {e(fit.model)}</h3>'
            f"<p>{vafs}{samples}.</p>")
    warns = _warnings(fit)
    body = table(["parameter", "value", "unit", "standard error", "relative se"], rows)
    body += warn_list(warns) if warns else "<p>No warning was raised while identifying.</p>"
    if fit.message:
        body += note(fit.message)
    return head + body + "</div>"


def section(exp: Experiment, fits: dict[str, FitResult]) -> Section:
    """The lumped fits among ``fits`` (name → stored FitResult)."""
    mine = {n: r for n, r in fits.items() if is_lumped(r)}
    if not mine:
        return Section("lumped", "Lumped fits (system identification)", None,
                       "omitted: the file holds no lumped (system-identification) fit")
    intro = ("<p>Parameters identified from a robot record by system identification (SI units); the "
             "standard error is the identification's own. VAF: the percentage of the measured output's "
             "variance the model accounts for.</p>")
    body = intro + "".join(_fit(n, r) for n, r in mine.items())
    vafs = [v for r in mine.values() for _, v in _vafs(r)[:1]]
    what = ", ".join(f"{n} (VAF {num(v, 3)} %)" for n, v in zip(mine, vafs, strict=False))
    return Section("lumped", "Lumped fits (system identification)", body,
                   f"{plural(len(mine), 'fit')}: {what}")
