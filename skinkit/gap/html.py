"""The self-contained HTML report of a gap diagnosis.

:func:`write_html` takes the report dict that ``skinkit gap diagnose --json`` prints (the pinned
shape of ``docs/guide/gap-diagnosis.md``, plus the optional keys ``gap.whiteness``, ``gap.cross_correlation``,
``gap.point_map``, ``points``, ``point_map_after``, ``separation``, ``rounds``, ``messages``)
and writes one HTML file that needs nothing else: the CSS is inline, the figures are PNGs
embedded as base64 ``data:`` URIs, the one script (table sorting) is inline. Any optional key —
and any pinned key — may be missing: its section then says so or is left out.

Sections, top to bottom: the verdict in plain words; the fit; measured against predicted over
time per protocol and channel (:mod:`skinkit.gap.html_series`, from ``series``); the residual
by protocol, phase, channel (and region, frequency) as χ²/dof per cell against the noise
level 1, with a ranked table; the residual maps per tracked point before and after the named
effect(s), drawn only where there are points (matplotlib, and a pyvista surface rendering when
VTK renders off screen here); the region scan's map with the found region's outline
(:mod:`skinkit.gap.html_scan`); the score ranking of the candidate effects; the shrinkage table;
the non-separable pairs with the protocol that would separate them; the whiteness and input
cross-correlation tests; the naming rounds; the raw JSON. Pre-stress is shown in one convention
(:func:`skinkit.gap.sentences.display_parameters`: λ1 ≥ λ2, θ of λ1 in degrees).

Figures are made on matplotlib's Agg canvas directly (no pyplot, no global backend state).
"""

from __future__ import annotations

import base64
import contextlib
import html
import io
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from skinkit import jsonio
from skinkit.errors import SchemaError, StoreError
from skinkit.gap.html_scan import section_scan
from skinkit.gap.html_series import section_series
from skinkit.gap.sentences import display_parameters
from skinkit.inverse.map_mask import hole_triangles
from skinkit.units import unit_suffix

#: the order in which the residual axes are shown (others, if any, follow alphabetically)
AXES = ("protocol", "phase", "channel", "region", "frequency")
#: how many significant cells the verdict names
N_VERDICT_CELLS = 3
#: colours: a significant cell, a cell at the noise level, a named effect, a refitted candidate
RED, GREY, GREEN, BLUE = "#c0392b", "#9aa5ad", "#1e8449", "#2e86c1"


# ---------------------------------------------------------------------------- formatting

def _e(x: Any) -> str:
    """Any value as escaped HTML text."""
    return html.escape(str(x), quote=True)


def _f(x: Any) -> float:
    """A float, NaN when ``x`` is None or not a number."""
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def _num(x: Any, digits: int = 3) -> str:
    """A number to ``digits`` significant digits; '—' for None/NaN."""
    v = _f(x)
    if math.isnan(v):
        return "—"
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    r = float(f"{v:.{digits}g}")
    if r == 0 or 1e-3 <= abs(r) < 1e6:   # plainly: 2100, 0.0123, rather than 2.1e+03
        return np.format_float_positional(r, trim="-")
    return f"{v:.{digits}g}"


def _p(x: Any) -> str:
    """A p-value: three decimals down to 0.001, then two significant digits."""
    v = _f(x)
    if math.isnan(v):
        return "—"
    return f"{v:.3f}" if v >= 1e-3 else f"{v:.2g}"


def _pct(x: Any) -> str:
    """A fraction as a percentage with one decimal ('—' for None/NaN)."""
    v = _f(x)
    return "—" if math.isnan(v) else f"{100 * v:.1f} %"


def _mpl(s: Any) -> str:
    """Text for a matplotlib label: '$' would start mathtext."""
    return str(s).replace("$", r"\$")


def _axis_name(c: Mapping[str, Any]) -> str:
    """The cell's axis, with its partition when the axis has more than one (phase: direction and
    cycle; region: radius, sector and those the model's geometry adds, e.g. twopad): shares add
    up to 1 within a partition."""
    axis, part = str(c.get("axis", "?")), c.get("partition")
    return f"{axis} ({part})" if part and str(part) != axis else axis


# ---------------------------------------------------------------------------- figures

def _figure(width: float, height: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _png_uri(fig: Any) -> str:
    """The figure as a base64 PNG data URI; the figure is cleared (its memory released)."""
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=100)
    finally:
        fig.clear()
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _array_uri(img: np.ndarray) -> str:
    """An ``(H, W, 3|4)`` uint8 image as a base64 PNG data URI."""
    from matplotlib.image import imsave

    buf = io.BytesIO()
    imsave(buf, img, format="png")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _img(uri: str, alt: str) -> str:
    return f'<figure><img src="{uri}" alt="{_e(alt)}"><figcaption>{_e(alt)}</figcaption></figure>'


# ---------------------------------------------------------------------------- tables

def _table(header: Sequence[str], rows: Iterable[Sequence[tuple[str, Any]]], *, sortable: bool = True,
           row_classes: Sequence[str] | None = None) -> str:
    """An HTML table. Each cell is (text already escaped, sort key or None); sortable tables sort
    on a header click by the keys (numbers numerically, missing last)."""
    cls = ' class="sortable"' if sortable else ""
    out = [f"<table{cls}><thead><tr>" + "".join(f"<th>{_e(h)}</th>" for h in header) + "</tr></thead><tbody>"]
    for k, row in enumerate(rows):
        rc = f' class="{row_classes[k]}"' if row_classes and row_classes[k] else ""
        tds = []
        for text, key in row:
            if isinstance(key, (int, float)) and not isinstance(key, bool):
                v = _f(key)
                attr = f' data-v="{v!r}"' if math.isfinite(v) else ' data-v=""'
            elif key is None:
                attr = ""
            else:
                attr = f' data-v="{_e(key)}"'
            tds.append(f"<td{attr}>{text}</td>")
        out.append(f"<tr{rc}>" + "".join(tds) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def _t(text: Any, key: Any = None) -> tuple[str, Any]:
    """A table cell from plain text (escaped here)."""
    return _e(text), key


# ---------------------------------------------------------------------------- the sections

def _cells(report: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    gap = report.get("gap") or {}
    return [c for c in (gap.get("cells") or []) if isinstance(c, Mapping)]


def _ranked(cells: list[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """Significant cells first, each group by share of the excess then χ²/dof, largest first."""
    def key(c: Mapping[str, Any]) -> tuple:
        share, r = _f(c.get("share")), _f(c.get("chi2_per_dof"))
        return (not c.get("significant"), -(0.0 if math.isnan(share) else share),
                -(0.0 if math.isnan(r) else r))
    return sorted(cells, key=key)


def _candidate(report: Mapping[str, Any], name: str) -> Mapping[str, Any] | None:
    for c in report.get("candidates") or []:
        if isinstance(c, Mapping) and c.get("effect") == name:
            return c
    return None


def _magnitudes(cand: Mapping[str, Any] | None) -> str:
    """'name = value ± se, ...' of a candidate's identified parameters ('' when none)."""
    params = display_parameters((cand or {}).get("parameters") or {})
    parts = []
    for name, pv in params.items():
        if isinstance(pv, Mapping):
            se = _f(pv.get("se"))
            interval = "" if math.isnan(se) else f" ± {_num(se, 2)}"
            unit = unit_suffix(pv.get("unit"))
            parts.append(f"{name} = {_num(pv.get('value'), 4)}{interval}{unit}")
        else:
            parts.append(f"{name} = {_num(pv)}")
    return ", ".join(parts)


def _pairs(report: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The non-separable pairs: ``separation`` when given, else from the candidates'
    ``not_separable_from`` (no protocol then). Each pair once."""
    out: list[dict[str, Any]] = []
    seen: set[frozenset] = set()
    for s in report.get("separation") or []:
        if not isinstance(s, Mapping):
            continue
        eff = [str(x) for x in (s.get("effects") or [])][:2]
        if len(eff) == 2 and frozenset(eff) not in seen:
            seen.add(frozenset(eff))
            out.append({"effects": eff, "protocol": s.get("protocol"), "cosine": s.get("cosine"),
                        "cosine_after": s.get("cosine_after")})
    for c in report.get("candidates") or []:
        if not isinstance(c, Mapping):
            continue
        for other in c.get("not_separable_from") or []:
            pair = [str(c.get("effect")), str(other)]
            if frozenset(pair) not in seen:
                seen.add(frozenset(pair))
                out.append({"effects": pair, "protocol": None, "cosine": None, "cosine_after": None})
    return out


def _verdict(report: Mapping[str, Any]) -> tuple[str, list[str]]:
    """The verdict's CSS class and its sentences (plain text, not yet escaped): the diagnosis's
    own sentences (``messages``, the ones stdout prints, from the final model's numbers), so
    that the page, stdout and the JSON cannot disagree."""
    gap = report.get("gap") or {}
    sig = gap.get("significant")
    if sig is None and not report.get("named") and not gap:
        return "unknown", ["The report carries no residual analysis: whether there is a gap cannot be said."]
    kind = "gap" if sig or report.get("named") else "ok"
    said = [str(m) for m in report.get("messages") or []]
    if not said:
        r = gap.get("chi2_per_dof")
        level = f"χ²/ν = {_num(r)}" if not math.isnan(_f(r)) else "χ²/ν not reported"
        said = [f"{'Significant gap' if sig else 'No significant gap'} ({level})."]
        for n in report.get("named") or []:
            c = _candidate(report, str(n)) or {}
            said.append(f"Named: {n} (it removes {_pct(c.get('share', c.get('shrinkage')))} of the excess).")
    return kind, said


def _section_verdict(report: Mapping[str, Any]) -> str:
    kind, sentences = _verdict(report)
    body = "".join(f"<p>{_e(s)}</p>" for s in sentences)
    return f'<section id="verdict" class="verdict {kind}"><h2>Verdict</h2>{body}</section>'


def _section_fit(report: Mapping[str, Any]) -> str:
    fit = report.get("fit") or {}
    if not fit:
        return '<section id="fit"><h2>The fit</h2><p class="note">No fit summary in the report.</p></section>'
    params = display_parameters(fit.get("parameters") or {})
    summary = (f"<p>χ²/ν of the fit: <b>{_e(_num(fit.get('chi2_per_dof')))}</b> (1 at the noise level); "
               f"forward solves: <b>{_e(fit.get('n_forward', '—'))}</b>.</p>")
    rows = [[_t(k, str(k)), _t(_num(v, 6), _f(v))] for k, v in params.items()]
    head = "fitted value (SI; pre-stress angle θ in °)" if any(str(k).endswith("θ") for k in params) \
        else "fitted value (SI)"
    table = (_table(["parameter", head], rows) if rows
             else '<p class="note">No parameters listed.</p>')
    return f'<section id="fit"><h2>The fit</h2>{summary}{table}</section>'


def _axis_order(cells: list[Mapping[str, Any]]) -> list[str]:
    present = {str(c.get("axis")) for c in cells}
    return [a for a in AXES if a in present] + sorted(present - set(AXES))


def _residual_figure(cells: list[Mapping[str, Any]]) -> str:
    """Bar charts of χ²/dof per cell, one panel per axis, the noise level 1 dashed, significant red."""
    axes = _axis_order(cells)
    heights = [max(1.2, 0.28 * sum(1 for c in cells if str(c.get("axis")) == a) + 0.8) for a in axes]
    fig = _figure(7.5, sum(heights))
    grid = fig.add_gridspec(len(axes), 1, height_ratios=heights)
    vals = [v for v in (_f(c.get("chi2_per_dof")) for c in cells) if math.isfinite(v)]
    top = max(vals + [1.0])
    log = top > 20   # a large gap would squash the cells near the noise level into the axis
    # one x range for every panel; on the log axis the bars grow from below the smallest cell
    left = min([0.5] + [0.7 * v for v in vals if v > 0]) if log else 0.0
    for k, a in enumerate(axes):
        ax = fig.add_subplot(grid[k])
        cs = [c for c in cells if str(c.get("axis")) == a]
        y = np.arange(len(cs))
        v = np.array([_f(c.get("chi2_per_dof")) for c in cs])
        ok = np.isfinite(v) & (v > left)
        colours = [RED if c.get("significant") else GREY for c in cs]
        ax.barh(y[ok], v[ok] - left, left=left, color=[col for col, o in zip(colours, ok, strict=True) if o],
                height=0.7)
        for i in np.flatnonzero(~np.isfinite(v)):
            ax.text(left, y[i], " no value", va="center", fontsize=7, color="0.4")
        ax.axvline(1.0, color="k", ls="--", lw=1)
        ax.set_yticks(y, [_mpl(c.get("label", "?")) for c in cs], fontsize=8)
        ax.set_ylim(len(cs) - 0.5, -0.5)   # the first cell on top
        if log:
            ax.set_xscale("log")
        ax.set_xlim(left, top * (2.0 if log else 1.08))
        ax.set_title(f"by {_mpl(a)}", fontsize=9, loc="left")
        ax.grid(axis="x", alpha=0.3)
        ax.tick_params(axis="x", labelsize=8)
    fig.axes[-1].set_xlabel("χ²/dof of the cell [1] (dashed: 1, the noise level; red: significant)",
                            fontsize=8)
    return _png_uri(fig)


def _section_residual(report: Mapping[str, Any]) -> str:
    cells = _cells(report)
    gap = report.get("gap") or {}
    head = '<section id="residual"><h2>Where: the residual by protocol, phase and channel</h2>'
    if not cells:
        return head + '<p class="note">No residual cells in the report.</p></section>'
    intro = (f"<p>Whole residual: χ²/ν = {_e(_num(gap.get('chi2_per_dof')))}"
             + (f", p = {_e(_p(gap.get('p_value')))}" if "p_value" in gap else "")
             + f"; {'significant' if gap.get('significant') else 'not significant'} against the noise. "
             "Each cell's χ²/dof is 1 at the noise level; a cell is significant after the correction "
             "for testing many cells. Share: the cell's part of the excess (above-noise) residual "
             "along its axis (within its partition, for the axes cut two ways). Click a column header to "
             "sort.</p>")
    ranked = _ranked(cells)
    rows = [[_t(i + 1, i + 1), _t(_axis_name(c), _axis_name(c)),
             _t(c.get("label", "?"), str(c.get("label", ""))),
             _t(_pct(c.get("share")), _f(c.get("share"))),
             _t(_num(c.get("chi2_per_dof")), _f(c.get("chi2_per_dof"))),
             _t(_p(c.get("p_value")), _f(c.get("p_value"))),
             _t("yes" if c.get("significant") else "no", 1 if c.get("significant") else 0)]
            for i, c in enumerate(ranked)]
    table = _table(["rank", "axis", "cell", "share of excess", "χ²/dof", "p-value", "significant"], rows,
                   row_classes=["sig" if c.get("significant") else "" for c in ranked])
    fig = _img(_residual_figure(cells), "χ²/dof per cell along each axis")
    return head + intro + fig + table + "</section>"


def _point_arrays(report: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Per protocol with a point map and positions: ``xy`` ``(P, 2)`` [mm], ``before`` and
    ``after`` (or None) ``(P,)`` χ²/dof. Protocols whose lengths disagree are left out."""
    gap = report.get("gap") or {}
    before = gap.get("point_map") or {}
    after = report.get("point_map_after") or {}
    points = report.get("points") or {}
    out = []
    for proto, vals in before.items():
        if proto not in points:
            continue
        try:
            xy = np.asarray(points[proto], float)
            b = np.array([_f(v) for v in vals], float)
            a = None if proto not in after else np.array([_f(v) for v in after[proto]], float)
        except (TypeError, ValueError):
            continue
        if xy.ndim != 2 or xy.shape[1] < 2 or len(xy) != len(b) or (a is not None and len(a) != len(b)):
            continue
        out.append({"protocol": str(proto), "xy": xy[:, :2] * 1e3, "before": b, "after": a})
    return out


def _map_range(maps: list[dict[str, Any]]) -> float:
    """M of the shared colour scale [1/M, M] (log, symmetric about the noise level 1)."""
    vals = np.concatenate([np.concatenate([m["before"]] + ([m["after"]] if m["after"] is not None else []))
                           for m in maps])
    vals = vals[np.isfinite(vals) & (vals > 0)]
    return float(max(2.0, vals.max() if vals.size else 2.0))


def _spread(xy: np.ndarray) -> bool:
    """Whether the points span an area (a triangulation through them exists)."""
    if len(xy) < 3:
        return False
    c = xy - xy.mean(axis=0)
    s = np.linalg.svd(c, compute_uv=False)
    return bool(s[-1] > 1e-9 * max(s[0], 1e-30))


def _maps_matplotlib(maps: list[dict[str, Any]], M: float) -> str:
    from matplotlib.colors import LogNorm
    from matplotlib.tri import Triangulation

    ncol = 2 if any(m["after"] is not None for m in maps) else 1
    fig = _figure(4.6 * ncol + 0.9, 3.9 * len(maps))
    norm = LogNorm(vmin=1.0 / M, vmax=M, clip=True)
    levels = np.geomspace(1.0 / M, M, 17)
    mappable = None
    for i, m in enumerate(maps):
        for j, (key, what) in enumerate((("before", "before"), ("after", "after the named effect"))[:ncol]):
            ax = fig.add_subplot(len(maps), ncol, i * ncol + j + 1)
            v = m[key]
            ax.set_title(f"{_mpl(m['protocol'])}: {what}", fontsize=9)
            ax.set_aspect("equal")
            pad = 0.06 * float(np.ptp(m["xy"], axis=0).max() or 1.0)   # edge points whole, not cut
            ax.set_xlim(m["xy"][:, 0].min() - pad, m["xy"][:, 0].max() + pad)
            ax.set_ylim(m["xy"][:, 1].min() - pad, m["xy"][:, 1].max() + pad)
            ax.set_xlabel("x [mm]", fontsize=8)
            ax.set_ylabel("y [mm]", fontsize=8)
            ax.tick_params(labelsize=7)
            if v is None:
                ax.text(0.5, 0.5, "no map after the named effect", ha="center", va="center",
                        transform=ax.transAxes, fontsize=8)
                ax.set_axis_off()
                continue
            ok = np.isfinite(v)
            if ok.sum() >= 3 and _spread(m["xy"][ok]):
                try:   # filled only among the points: not across the probe's footprint or a gap
                    tri = Triangulation(m["xy"][ok, 0], m["xy"][ok, 1])
                    tri.set_mask(hole_triangles(m["xy"][ok], tri.triangles))
                    ax.tricontourf(tri, np.clip(v[ok], 1.0 / M, M), levels=levels, norm=norm, cmap="RdBu_r",
                                   alpha=0.8)
                except (ValueError, RuntimeError):   # a degenerate triangulation: the scatter alone
                    pass
            mappable = ax.scatter(m["xy"][ok, 0], m["xy"][ok, 1], c=np.clip(v[ok], 1.0 / M, M), norm=norm,
                                  cmap="RdBu_r", s=36, edgecolors="k", linewidths=0.4)
            if (~ok).any():   # said in the title: a legend would hide points
                ax.scatter(m["xy"][~ok, 0], m["xy"][~ok, 1], marker="x", color="0.5", s=20)
                ax.set_title(f"{_mpl(m['protocol'])}: {what} (×: not observed)", fontsize=9)
    if mappable is not None:
        from matplotlib.ticker import NullFormatter

        cb = fig.colorbar(mappable, ax=fig.axes, label="χ²/dof per point [1] (white: 1, the noise level)",
                          shrink=0.8)
        # 0.5, 1, 2, 5 … written plainly rather than 5×10⁻¹, 10⁰, 2×10⁰
        ticks = [m * 10.0 ** k for k in range(-6, 7) for m in (1, 2, 5) if 1 / M <= m * 10.0 ** k <= M]
        cb.set_ticks(ticks, labels=[f"{t:g}" for t in ticks])
        cb.ax.yaxis.set_minor_formatter(NullFormatter())
    return _png_uri(fig)


def _maps_pyvista(maps: list[dict[str, Any]], M: float) -> str | None:
    """The same maps as surfaces triangulated through the points, lifted by log10 χ²/dof (above the
    translucent plane of the noise level where the model misses, below it where it fits better
    than the noise), coloured on the same scale, all panels seen from the same oblique camera;
    rendered by pyvista off screen. None whenever that is not possible here (no pyvista, no VTK
    rendering, too few points): the matplotlib maps stand alone then."""
    import importlib.util

    if importlib.util.find_spec("pyvista") is None:
        return None
    maps = [m for m in maps if _spread(m["xy"][np.isfinite(m["before"])])]   # a surface needs an area
    if not maps:
        return None
    try:
        import pyvista as pv

        # VTK's own log (e.g. "bad X server connection" before it falls back to off-screen
        # rendering) would reach the terminal of a CLI run: silenced while rendering
        quiet = getattr(pv, "vtk_verbosity", None)
        with quiet("off") if quiet is not None else contextlib.nullcontext():
            return _render_pyvista(pv, maps, M)
    except Exception:  # noqa: BLE001 - any VTK failure: the matplotlib maps stand alone
        return None


def _render_pyvista(pv: Any, maps: list[dict[str, Any]], M: float) -> str | None:
    """The relief maps of :func:`_maps_pyvista` rendered: a PNG data URI (None: a blank image)."""
    ncol = 2 if any(m["after"] is not None for m in maps) else 1
    pl = pv.Plotter(off_screen=True, shape=(len(maps), ncol), window_size=(480 * ncol, 400 * len(maps)),
                    border=False)
    try:
        lim = math.log10(M)
        label = "log10 chi2/dof"
        for i, m in enumerate(maps):
            lo, hi = m["xy"].min(axis=0), m["xy"].max(axis=0)
            height = 0.35 * float(np.max(hi - lo)) / lim   # [mm per decade]: a relief, not a tower
            for j, key in enumerate(("before", "after")[:ncol]):
                pl.subplot(i, j)
                pl.add_text(f"{m['protocol']}: {key}", font_size=9, position="upper_left")
                v = m[key]
                ok = np.zeros(len(m["xy"]), bool) if v is None else np.isfinite(v)
                if not _spread(m["xy"][ok]):
                    pl.add_text("no map after the named effect", font_size=8, position="lower_left")
                    continue
                z = np.log10(np.clip(v[ok], 1.0 / M, M))
                pts = np.column_stack([m["xy"][ok], z * height])
                flat = pv.PolyData(np.column_stack([m["xy"][ok], np.zeros(ok.sum())])).delaunay_2d()
                tris = flat.faces.reshape(-1, 4)[:, 1:]
                keep = tris[~hole_triangles(m["xy"][ok], tris)]   # no surface where no point is
                surf = pv.PolyData(pts, faces=np.column_stack([np.full(len(keep), 3), keep]).ravel())
                surf[label] = z
                pl.add_mesh(pv.Plane(center=(*((lo + hi) / 2), 0.0), i_size=float(hi[0] - lo[0]),
                                     j_size=float(hi[1] - lo[1])), color="grey", opacity=0.25)
                pl.add_mesh(surf, scalars=label, cmap="RdBu_r", clim=(-lim, lim), lighting=False,
                            scalar_bar_args={"title": label, "vertical": True, "position_x": 0.88,
                                             "position_y": 0.15, "height": 0.6, "width": 0.06,
                                             "title_font_size": 11, "label_font_size": 10})
                pl.add_points(pts, color="black", point_size=4, render_points_as_spheres=True)
        pl.subplot(0, 0)
        pl.view_vector((-0.6, -1.0, 0.9))
        pl.camera.zoom(0.85)
        pl.link_views()   # one camera: a flatter surface must not be drawn larger
        img = pl.screenshot(return_img=True)
    finally:
        pl.close()
    if img is None or np.asarray(img).size == 0 or float(np.asarray(img).std()) == 0.0:
        return None
    return _array_uri(np.asarray(img, dtype=np.uint8))


def _section_maps(report: Mapping[str, Any]) -> str:
    head = '<section id="maps"><h2>Residual surface maps, before and after</h2>'
    gap = report.get("gap") or {}
    if not gap.get("point_map"):
        return head + ('<p class="note">No per-point residual map in the report (no tracked points).</p>'
                       "</section>")
    maps = _point_arrays(report)
    if not maps:
        return head + ('<p class="note">The report has a per-point map but no matching reference positions '
                       '(<code>points</code>): it cannot be drawn.</p></section>')
    M = _map_range(maps)
    intro = (f"<p>χ²/dof of each tracked point (over its frames and components) at its reference position in "
             f"the skin frame, before and after the named effect(s); one colour scale for every panel, "
             f"logarithmic from {_e(_num(1 / M))} to {_e(_num(M))}, white at 1 (the noise level), red above, "
             "blue below. Grey crosses: points never observed.</p>")
    out = head + intro + _img(_maps_matplotlib(maps, M), "χ²/dof per tracked point, before and after")
    uri = _maps_pyvista(maps, M)
    if uri is not None:
        out += _img(uri, "the same maps as surfaces through the points, lifted by log10 χ²/dof above "
                         "(below) the grey plane of the noise level (pyvista)")
    return out + "</section>"


def _scores_figure(cands: list[Mapping[str, Any]], named: set[str]) -> str:
    fig = _figure(7.0, max(1.6, 0.34 * len(cands) + 1.0))
    ax = fig.add_subplot(1, 1, 1)
    y = np.arange(len(cands))
    s = np.array([_f(c.get("score")) for c in cands])
    s = np.where(np.isfinite(s), s, 0.0)
    colours = [GREEN if c.get("effect") in named else (BLUE if c.get("refitted") else GREY) for c in cands]
    ax.barh(y, np.maximum(s, 0.0), color=colours, height=0.7)
    ax.set_yticks(y, [_mpl(c.get("effect", "?")) for c in cands], fontsize=8)
    ax.invert_yaxis()
    top = float(s.max()) if s.size else 1.0
    for k, c in enumerate(cands):
        ax.text(max(s[k], 0.0) + 0.01 * max(top, 1e-12), k, f" p = {_p(c.get('p_value'))}", va="center",
                fontsize=7)
    ax.set_xlim(right=max(top, 1e-12) * 1.3)
    ax.set_xlabel("score (Lagrange-multiplier) statistic at the effect's null value [1] "
                  "(green: named; blue: refitted)", fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    return _png_uri(fig)


def _section_scores(report: Mapping[str, Any]) -> str:
    head = '<section id="scores"><h2>Which: the score ranking of the candidate effects</h2>'
    cands = [c for c in report.get("candidates") or [] if isinstance(c, Mapping)]
    if not cands:
        return head + '<p class="note">No candidate effects in the report.</p></section>'
    named = {str(n) for n in report.get("named") or []}
    cands = sorted(cands, key=lambda c: -(_f(c.get("score")) if math.isfinite(_f(c.get("score"))) else -1.0))
    intro = ("<p>Each installed effect that applies to the model is tested at its null value by a score "
             "(Lagrange-multiplier) test with the fitted parameters' directions projected out (no refit); "
             "the top candidates are then refitted and compared by AIC (ΔAIC: the refit's AIC less the "
             "model's without the effect) and by the share of the excess residual they remove (an added "
             "effect is a cause when its share reaches the report's min_share, else a minor "
             "contribution).</p>")
    rows = []
    for i, c in enumerate(cands):
        eff = str(c.get("effect", "?"))
        role = str(c.get("role") or ("cause" if eff in named else ""))
        rows.append([_t(i + 1, i + 1), _t(eff + (f" ({role})" if role else ""), eff),
                     _t(_num(c.get("score")), _f(c.get("score"))), _t(_num(c.get("dof")), _f(c.get("dof"))),
                     _t(_p(c.get("p_value")), _f(c.get("p_value"))),
                     _t("yes" if c.get("refitted") else "no", 1 if c.get("refitted") else 0),
                     _t(_num(c.get("delta_aic"), 4), _f(c.get("delta_aic"))),
                     _t(_pct(c.get("share", c.get("shrinkage"))), _f(c.get("share", c.get("shrinkage")))),
                     _t(_magnitudes(c) or "—", None),
                     _t(", ".join(str(x) for x in c.get("not_separable_from") or []) or "—", None)])
    table = _table(["rank", "effect (role)", "score", "q (its dof)", "p-value", "refitted", "ΔAIC", "share",
                    "identified magnitude (value ± se)", "not separable from"], rows,
                   row_classes=["named" if str(c.get("effect")) in named else "" for c in cands])
    return head + intro + _img(_scores_figure(cands, named), "score statistic per candidate effect") + table \
        + "</section>"


def _fraction(cell: Mapping[str, Any]) -> float:
    """The fraction of a cell's excess residual removed: the diagnosis's own figure when the cell
    carries one (``shrinkage`` or ``fraction``: from χ² − dof, each state with its own dof), else
    from its χ²/dof before and after, (max(b−1,0) − max(a−1,0)) / max(b−1,0) (NaN without excess)."""
    for key in ("shrinkage", "fraction"):
        if key in cell:
            return _f(cell.get(key))
    b, a = _f(cell.get("before")), _f(cell.get("after"))
    eb = max(b - 1.0, 0.0)
    return math.nan if not eb > 0 or math.isnan(a) else (eb - max(a - 1.0, 0.0)) / eb


def _section_shrinkage(report: Mapping[str, Any]) -> str:
    head = '<section id="shrinkage"><h2>How far: the shrinkage of the gap</h2>'
    shr = report.get("shrinkage") or {}
    if not shr:
        return head + '<p class="note">No shrinkage in the report (no effect named).</p></section>'
    named = ", ".join(str(n) for n in report.get("named") or []) or "none"
    intro = (f"<p>Named effect(s): <b>{_e(named)}</b>. Fraction of the excess (above-noise) residual "
             f"removed: <b>{_e(_pct(shr.get('overall')))}</b> on the fitted protocols, "
             f"<b>{_e(_pct(shr.get('held_out')))}</b> on the held-out ones. Per cell: χ²/dof before and "
             "after; "
             "fraction = (excess before − excess after) / excess before, the excess being χ²/dof − 1.</p>")
    cells = [c for c in shr.get("cells") or [] if isinstance(c, Mapping)]
    if not cells:
        return head + intro + "</section>"
    rows = [[_t(c.get("axis", "?"), str(c.get("axis", ""))), _t(c.get("label", "?"), str(c.get("label", ""))),
             _t(_num(c.get("before")), _f(c.get("before"))), _t(_num(c.get("after")), _f(c.get("after"))),
             _t(_pct(_fraction(c)), _fraction(c))] for c in cells]
    return head + intro + _table(["axis", "cell", "before", "after", "fraction removed"], rows) + "</section>"


def _section_separation(report: Mapping[str, Any]) -> str:
    pairs = _pairs(report)
    head = '<section id="separation"><h2>Effects that these protocols cannot tell apart</h2>'
    if not pairs:
        return head + '<p class="note">No non-separable pair: every candidate leaves its own signature.</p>' \
            "</section>"
    intro = ("<p>Two effects are not separable when their (projected) sensitivities point in nearly the same "
             "direction (|cosine| near 1) on the session's protocols. The protocol is the one of the library "
             "under which their signatures differ most, with the |cosine| once it is added.</p>")
    rows = [[_t(p["effects"][0], p["effects"][0]), _t(p["effects"][1], p["effects"][1]),
             _t(_num(p.get("cosine")), _f(p.get("cosine"))),
             _t(p.get("protocol") or "not given", str(p.get("protocol") or "")),
             _t(_num(p.get("cosine_after")), _f(p.get("cosine_after")))] for p in pairs]
    header = ["effect", "not separable from", "|cosine| on these protocols",
              "protocol that would separate them", "|cosine| with it"]
    return head + intro + _table(header, rows) + "</section>"


def _section_tests(report: Mapping[str, Any]) -> str:
    gap = report.get("gap") or {}
    parts = []
    for key, title, flag, yes in (("whiteness", "Whiteness of the residual", "white", "white"),
                                  ("cross_correlation", "Residual against the drive input", "independent",
                                   "independent")):
        d = gap.get(key)
        if not isinstance(d, Mapping) or not d:
            continue
        rows = []
        for name, t in d.items():
            t = t if isinstance(t, Mapping) else {}
            ok = t.get(flag)
            lags = t.get("lags")
            lags = ", ".join(str(x) for x in lags) if isinstance(lags, (list, tuple)) else lags
            rows.append([_t(name, str(name)), _t(_num(t.get("statistic")), _f(t.get("statistic"))),
                         _t("—" if lags is None else lags, _f(lags) if not isinstance(lags, str) else lags),
                         _t(_p(t.get("p_value")), _f(t.get("p_value"))),
                         _t("—" if ok is None else (yes if ok else f"not {yes}"),
                            None if ok is None else int(ok))])
        header = ["protocol/channel", "statistic", "lags", "p-value", "verdict"]
        failed = ["sig" if r[-1][1] == 0 else "" for r in rows]
        parts.append(f"<h3>{_e(title)}</h3>" + _table(header, rows, row_classes=failed))
    if not parts:
        return ""
    intro = ("<p>Portmanteau tests on each protocol's and channel's residual: a white residual has no "
             "structure left in time; a residual correlated with the drive input has a dynamic the model "
             "lacks.</p>")
    return '<section id="tests"><h2>Whiteness and input cross-correlation</h2>' + intro + "".join(parts) \
        + "</section>"


def _section_rounds(report: Mapping[str, Any]) -> str:
    rounds = [r for r in report.get("rounds") or [] if isinstance(r, Mapping)]
    if not rounds:
        return ""
    rows = []
    for k, r in enumerate(rounds):
        effects = ", ".join(str(x) for x in r.get("model_effects") or []) or "none"
        why = r.get("not_named") or {}
        notes = "; ".join([f"{e}: {w}" for e, w in why.items()] if isinstance(why, Mapping) else [str(why)])
        if r.get("note"):
            notes = "; ".join(x for x in (notes, str(r["note"])) if x)
        n = r.get("round", k + 1)
        rows.append([_t(n, _f(n)), _t(effects, effects),
                     _t(_num(r.get("chi2_per_dof")), _f(r.get("chi2_per_dof"))),
                     _t(r.get("named") or "—", str(r.get("named") or "")), _t(notes or "—", None)])
    table = _table(["round", "effects in the model", "χ²/ν", "named", "why the others were not named"], rows)
    items = "".join(f"<li><pre>{_e(jsonio.dumps(r, indent=1, default=_json_default))}</pre></li>"
                    for r in rounds)
    return ('<section id="rounds"><h2>Naming rounds</h2><p>After an effect is named the diagnosis is '
            "repeated on the model with it, to look for a second.</p>" + table
            + f"<details><summary>the rounds in full</summary><ol>{items}</ol></details></section>")


def _json_default(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return str(x)


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1100px;
margin:1.5em auto;padding:0 1em;color:#1b2631;line-height:1.45}
h1{font-size:1.5em;margin-bottom:.2em}h2{font-size:1.2em;border-bottom:1px solid #d5d8dc;padding-bottom:.2em;
margin-top:1.8em}h3{font-size:1em}
.sub{color:#566573;margin-top:0}.note{color:#566573;font-style:italic}
.verdict{border-left:6px solid #7f8c8d;background:#f4f6f6;padding:.4em 1em;margin-top:1em}
.verdict.ok{border-color:#1e8449;background:#eafaf1}.verdict.gap{border-color:#c0392b;background:#fdedec}
.verdict h2{border:none;margin-top:.3em}
table{border-collapse:collapse;margin:.8em 0;font-size:.9em}
th,td{border:1px solid #d5d8dc;padding:.25em .6em;text-align:left}
th{background:#eaecee}table.sortable th{cursor:pointer}
tr.sig td{background:#fdedec}tr.named td{background:#eafaf1;font-weight:600}
figure{margin:1em 0}img{max-width:100%;height:auto}figcaption{font-size:.85em;color:#566573}
pre{font-size:.8em;overflow-x:auto}nav a{margin-right:.8em}
"""

# sorts a table on a header click by the cells' data-v (numbers numerically, missing last); clicking
# the same header again reverses the order
_JS = """
document.querySelectorAll("table.sortable").forEach(function(t){
 t.querySelectorAll("th").forEach(function(th,i){th.addEventListener("click",function(){
  var b=t.tBodies[0],r=Array.prototype.slice.call(b.rows),d=th.dataset.d==="1"?-1:1;
  th.dataset.d=d===1?"1":"0";
  function k(x){var v=x.cells[i].dataset.v;if(v===undefined)v=x.cells[i].textContent;return v;}
  r.sort(function(x,y){var a=k(x),c=k(y);if(a==="")return 1;if(c==="")return -1;
   var na=Number(a),nc=Number(c);
   return d*(!isNaN(na)&&!isNaN(nc)?na-nc:a.localeCompare(c));});
  r.forEach(function(x){b.appendChild(x);});});});});
"""


def render_html(report: Mapping[str, Any], *, title: str | None = None) -> str:
    """The report (module docstring; a dict or a ``GapReport``) as one self-contained HTML
    document (a string)."""
    if not isinstance(report, Mapping) and callable(getattr(report, "to_dict", None)):
        report = report.to_dict()   # a skinkit.schemas.GapReport
    if not isinstance(report, Mapping):
        raise SchemaError("gap report", f"expected the report's JSON dict, got {type(report).__name__}")
    model, session = report.get("model"), report.get("session")
    if title is None:
        title = "Gap diagnosis" + (f": {model}" if model else "") + (f" on {session}" if session else "")
    sections = [f(report) for f in (_section_verdict, _section_fit, section_series, _section_residual,
                                    _section_maps, section_scan,
                                    _section_scores, _section_shrinkage, _section_separation, _section_tests,
                                    _section_rounds)]
    nav = "".join(f'<a href="#{i}">{_e(t)}</a>' for i, t in
                  (("verdict", "verdict"), ("fit", "fit"), ("series", "measured vs predicted"),
                   ("residual", "where"), ("maps", "maps"), ("scan", "region"),
                   ("scores", "which"), ("shrinkage", "how far"), ("separation", "not separable")))
    raw = jsonio.dumps(report, indent=1, default=_json_default)
    sub = " · ".join(x for x in (f"model {model}" if model else "", f"session {session}" if session else "")
                     if x)
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>"
            f"<h1>{_e(title)}</h1>" + (f'<p class="sub">{_e(sub)}</p>' if sub else "") + f"<nav>{nav}</nav>"
            + "".join(sections)
            + '<section id="raw"><h2>The report as JSON</h2><details><summary>show</summary>'
            f"<pre>{_e(raw)}</pre></details></section>"
            f"<script>{_JS}</script></body></html>\n")


def write_html(report: Mapping[str, Any], path: str | os.PathLike, *, title: str | None = None) -> Path:
    """Write the gap report ``report`` (the dict of ``skinkit gap diagnose --json``, or a
    :class:`skinkit.schemas.GapReport`; optional keys may be missing) as one self-contained HTML
    file at ``path`` (parent folders are made) and return its path. ``title``: the page's title
    (default: "Gap diagnosis: MODEL on SESSION").

    Raises :class:`skinkit.errors.SchemaError` when ``report`` is neither a mapping nor has a
    ``to_dict``, and
    :class:`skinkit.errors.StoreError` when ``path`` is a folder or cannot be written.
    """
    path = Path(path)
    if path.is_dir():
        raise StoreError(str(path), "", "is a folder; give the HTML file's path")
    text = render_html(report, title=title)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise StoreError(str(path), "", f"cannot write the HTML report: {exc.strerror or exc}") from exc
    return path


__all__ = ["render_html", "write_html"]
