"""The gap report's region section: the per-point residual map with the found region's outline, and
the region scan's score map (from ``region_scan``, :mod:`skinkit.gap.scan`).

Drawn as inline SVG, not as an image, so that the outline is an element of the page (a circle of
class ``scan-region`` with the region's centre and size in millimetres as data attributes) and
a browser, or a test, can find it. Each panel shows the skin plane in millimetres, x to the right
and y up, on one scale for both panels:

* **residual**: every tracked point coloured by its χ²/dof before the named effects (the
  maps section's scale: logarithmic, white at the noise level 1), the scan's best region as a
  green circle and, when the candidate was refitted, the refitted region dashed (an ellipse of
  class ``refit-region`` with its semi-axes and angle as data attributes, when the effect was
  refitted in its elliptical form), and the scan's second place, when it had one that was also
  refitted from, as an orange circle of class ``rival-region``;
* **score map**: every scanned centre as a square of the grid's spacing, coloured by the largest
  score statistic over the sizes scanned there (darker: a larger LM), with the same outlines.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

#: the panel's side [px] and its margin [px]
SIDE, PAD = 360, 34
#: colours of the scan's best region, of the refitted region and of the scan's second place
BEST, REFIT, RIVAL = "#00c853", "#7d3c98", "#e67e22"


def _e(x: Any) -> str:
    return html.escape(str(x), quote=True)


def _hex(rgba: Sequence[float]) -> str:
    return "#" + "".join(f"{int(round(255 * max(0.0, min(1.0, c)))):02x}" for c in rgba[:3])


class _Frame:
    """Millimetres of the skin plane -> pixels of a panel (y up), one scale for x and y."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray) -> None:
        span = float(max(hi[0] - lo[0], hi[1] - lo[1], 1e-6))
        self.lo, self.scale = lo, (SIDE - 2 * PAD) / span
        self.hi = hi

    def x(self, v: float) -> float:
        return PAD + (v - self.lo[0]) * self.scale

    def y(self, v: float) -> float:
        return SIDE - PAD - (v - self.lo[1]) * self.scale

    def axes(self, title: str) -> str:
        """The panel's frame, title and axis labels (SVG elements)."""
        x0, x1, y0, y1 = self.x(self.lo[0]), self.x(self.hi[0]), self.y(self.lo[1]), self.y(self.hi[1])
        out = [f'<rect x="{x0:.1f}" y="{y1:.1f}" width="{x1 - x0:.1f}" height="{y0 - y1:.1f}" fill="none" '
               'stroke="#aab7b8" stroke-width="0.8"/>',
               f'<text x="{SIDE / 2:.0f}" y="16" text-anchor="middle" font-size="12">{_e(title)}</text>',
               f'<text x="{SIDE / 2:.0f}" y="{SIDE - 6}" text-anchor="middle" font-size="10">x [mm] '
               f'{self.lo[0]:.1f} to {self.hi[0]:.1f}</text>',
               f'<text x="10" y="{SIDE / 2:.0f}" font-size="10" transform="rotate(-90 10 {SIDE / 2:.0f})" '
               f'text-anchor="middle">y [mm] {self.lo[1]:.1f} to {self.hi[1]:.1f}</text>']
        return "".join(out)


def _outline(fr: _Frame, x: float, y: float, r: float, kind: str, b: float | None = None,
             angle: float = 0.0) -> str:
    """One region's outline (``kind`` "best", "refit" or "rival") with its centre marked; mm: a
    circle of radius ``r``, or with ``b`` an ellipse of semi-axes ``r``, ``b``, the first at
    ``angle`` [deg] from x."""
    colour, dash, cls = {"best": (BEST, "", "scan-region"), "rival": (RIVAL, "", "rival-region")}.get(
        kind, (REFIT, ' stroke-dasharray="5 3"', "refit-region"))
    cx, cy, rp = fr.x(x), fr.y(y), r * fr.scale
    mark = (f'<path d="M{cx - 5:.1f},{cy:.1f}h10M{cx:.1f},{cy - 5:.1f}v10" stroke="{colour}" '
            'stroke-width="1.5"/>')
    style = f'fill="none" stroke="{colour}" stroke-width="2.5"{dash}'
    if b is None:
        return (f'<circle class="{cls}" data-x-mm="{x:.4g}" data-y-mm="{y:.4g}" data-size-mm="{r:.4g}" '
                f'cx="{cx:.1f}" cy="{cy:.1f}" r="{rp:.1f}" {style}/>' + mark)
    # the page's y axis points down: an angle from x turns the other way on screen
    return (f'<ellipse class="{cls}" data-x-mm="{x:.4g}" data-y-mm="{y:.4g}" data-a-mm="{r:.4g}" '
            f'data-b-mm="{b:.4g}" data-angle-deg="{angle:.4g}" cx="{cx:.1f}" cy="{cy:.1f}" rx="{rp:.1f}" '
            f'ry="{b * fr.scale:.1f}" transform="rotate({-angle:.2f} {cx:.1f} {cy:.1f})" {style}/>' + mark)


def _refitted(report: Mapping[str, Any], scan: Mapping[str, Any]) -> tuple[float, ...] | None:
    """The candidate's refitted region (its last refit's values): ``(x, y, r)`` [mm] of a disc or,
    refitted in the shape scan's elliptical form, ``(x, y, a, b, angle)`` [mm, mm, mm, mm, deg];
    None when it was not refitted."""
    shape = (scan.get("shape") or {}).get("parameters") or []
    for names in ([list(shape)] if len(shape) == 5 else []) + [list(scan.get("parameters") or [])]:
        for c in report.get("candidates") or []:
            pars = c.get("parameters") or {}
            if c.get("effect") != scan.get("effect") or len(names) not in (3, 5) \
                    or not all(n in pars for n in names):
                continue
            try:
                v = [float(pars[n]["value"]) for n in names]
            except (TypeError, ValueError, KeyError):
                return None
            v = [t * 1e3 for t in v[:4]] + [math.degrees(t) for t in v[4:]]
            return tuple(v) if all(math.isfinite(t) for t in v) else None
    return None


def _points(report: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray] | None:
    """Tracked points ``(P, 2)`` [mm] and their χ²/dof before ``(P,)``, pooled over protocols (the
    mean where several protocols track the same points); None when the report has no map."""
    pm = (report.get("gap") or {}).get("point_map") or {}
    pts = report.get("points") or {}
    xy, vals = None, []
    for proto, v in pm.items():
        if proto not in pts:
            continue
        try:
            p = np.asarray(pts[proto], float)[:, :2] * 1e3
            a = np.array([np.nan if x is None else float(x) for x in v], float)
        except (TypeError, ValueError, IndexError):
            continue
        if len(p) != len(a):
            continue
        if xy is None:
            xy = p
        elif xy.shape != p.shape or not np.allclose(xy, p):
            continue
        vals.append(a)
    if xy is None or not vals:
        return None
    with np.errstate(all="ignore"):
        return xy, np.nanmean(np.vstack(vals), axis=0)


def _residual_panel(fr: _Frame, xy: np.ndarray, v: np.ndarray, outlines: str) -> str:
    from matplotlib import colormaps
    from matplotlib.colors import LogNorm

    ok = np.isfinite(v) & (v > 0)
    M = float(max(2.0, v[ok].max() if ok.any() else 2.0))
    norm, cmap = LogNorm(vmin=1.0 / M, vmax=M, clip=True), colormaps["RdBu_r"]
    dots = []
    for (x, y), c, good in zip(xy, v, ok, strict=True):
        fill = _hex(cmap(norm(c))) if good else "#ffffff"
        dots.append(f'<circle class="point" cx="{fr.x(x):.1f}" cy="{fr.y(y):.1f}" r="4" fill="{fill}" '
                    f'stroke="#1b2631" stroke-width="0.4"/>')
    return (f'<svg class="scan-map" data-panel="residual" width="{SIDE}" height="{SIDE}" '
            f'viewBox="0 0 {SIDE} {SIDE}" xmlns="http://www.w3.org/2000/svg" role="img" '
            f'aria-label="χ²/dof per tracked point with the found region">'
            + fr.axes(f"χ²/dof per point (1/{M:.3g} to {M:.3g}) and the region") + "".join(dots) + outlines
            + "</svg>")


def _score_panel(fr: _Frame, scan: Mapping[str, Any], outlines: str) -> str:
    from matplotlib import colormaps

    regs = scan.get("regions") or {}
    x = np.asarray(regs.get("x_m") or [], float) * 1e3
    y = np.asarray(regs.get("y_m") or [], float) * 1e3
    lm = np.asarray([np.nan if s is None else float(s) for s in regs.get("statistic") or []], float)
    h = float((scan.get("grid") or {}).get("spacing_m") or 0.0) * 1e3
    cells = []
    if x.size and x.size == lm.size == y.size and h > 0:
        best: dict[tuple[float, float], float] = {}
        for xi, yi, li in zip(np.round(x, 6), np.round(y, 6), lm, strict=True):
            if np.isfinite(li):
                best[(xi, yi)] = max(best.get((xi, yi), 0.0), li)
        top = max(best.values(), default=0.0) or 1.0
        cmap = colormaps["Greys"]
        for (xi, yi), li in best.items():
            # the square root spreads the colours: LM grows with the square of a signature's size
            c = _hex(cmap(0.08 + 0.85 * math.sqrt(max(li, 0.0) / top)))
            cells.append(f'<rect class="score" data-lm="{li:.4g}" x="{fr.x(xi - h / 2):.1f}" '
                         f'y="{fr.y(yi + h / 2):.1f}" width="{h * fr.scale:.1f}" height="{h * fr.scale:.1f}" '
                         f'fill="{c}"/>')
    return (f'<svg class="scan-map" data-panel="score" width="{SIDE}" height="{SIDE}" '
            f'viewBox="0 0 {SIDE} {SIDE}" xmlns="http://www.w3.org/2000/svg" role="img" '
            'aria-label="score statistic of every scanned centre">'
            + fr.axes("score LM per centre (largest over sizes)") + "".join(cells) + outlines + "</svg>")


def _fmt(x: Any, digits: int = 3) -> str:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return "n/a"
    return f"{v:.{digits}g}" if math.isfinite(v) else "n/a"


def _one(report: Mapping[str, Any], scan: Mapping[str, Any]) -> str:
    best = scan.get("best") or {}
    grid = scan.get("grid") or {}
    cost = scan.get("cost") or {}
    try:
        bx, by, br = (float(best[k]) * 1e3 for k in ("x_m", "y_m", "size_m"))
    except (KeyError, TypeError, ValueError):
        return f'<p class="note">The region scan of {_e(scan.get("effect"))} has no best region.</p>'
    fit = _refitted(report, scan)
    size = str((scan.get("parameters") or ["", "", "size"])[2]).partition(".")[2] or "size"
    p_adj = best.get("p_adjusted")
    lg = best.get("log10_p_adjusted")
    # an adjusted p that underflows is stated by its log, or as below the smallest double
    p_txt = (_fmt(p_adj) if p_adj not in (None, 0, 0.0)
             else f"10^{_fmt(lg, 4)}" if lg is not None else "< 1e-300")
    text = (f"<p>Region scan of <b>{_e(scan.get('effect'))}</b> (round {_e(scan.get('round', 1))}): "
            f"{_e(grid.get('regions'))} regions — {len(grid.get('centres_m') or [])} centres "
            f"{_fmt(float(grid.get('spacing_m') or 0) * 1e3)} mm apart over the tracked points, sizes "
            f"{', '.join(_fmt(s * 1e3) for s in grid.get('sizes_m') or [])} mm. Best region: x {bx:.3g} mm, "
            f"y {by:.3g} mm, {_e(size)} {br:.3g} mm (green), LM {_fmt(best.get('statistic'), 4)}, p adjusted "
            f"for the regions scanned {p_txt} (max-statistic over the scan). Cost: "
            f"{_e(cost.get('n_forward'))} prediction with {_e(cost.get('columns'))} sensitivity columns, "
            f"{_fmt(cost.get('wall_s'))} s"
            + (f", {_fmt(cost.get('forward_equivalents'))} plain predictions' time" if
               cost.get("forward_equivalents") is not None else "") + ".")
    kept = ((scan.get("rival") or {}).get("refits") or {}).get("kept") == "rival"
    at = "the second place (orange)" if kept else "the best centre"
    if fit is not None and len(fit) == 5:
        text += (f" Refitted as an ellipse (dashed), started from the best of the elongated shapes scored "
                 f"at {at}: x {fit[0]:.3g} mm, y {fit[1]:.3g} mm, semi-axes {fit[2]:.3g} and "
                 f"{fit[3]:.3g} mm, the first at {fit[4]:.3g}° from x.")
    elif fit is not None:
        text += f" Refitted (dashed): x {fit[0]:.3g} mm, y {fit[1]:.3g} mm, {_e(size)} {fit[2]:.3g} mm."
    rival = _rival(scan)
    text += "" if rival is None else rival[1]
    text += "</p>"
    pts = _points(report)
    reach = max(fit[2:4]) if fit is not None and len(fit) == 5 else fit[2] if fit else 0.0
    xs = [bx - br, bx + br] + ([fit[0] - reach, fit[0] + reach] if fit else [])
    ys = [by - br, by + br] + ([fit[1] - reach, fit[1] + reach] if fit else [])
    if rival is not None:
        (rx, ry, rr) = rival[0]
        xs, ys = xs + [rx - rr, rx + rr], ys + [ry - rr, ry + rr]
    regs = scan.get("regions") or {}
    h = float(grid.get("spacing_m") or 0.0) * 1e3 / 2
    xs += [float(v) * 1e3 + s for v in regs.get("x_m") or [] for s in (-h, h)]
    ys += [float(v) * 1e3 + s for v in regs.get("y_m") or [] for s in (-h, h)]
    if pts is not None:
        xs += pts[0][:, 0].tolist()
        ys += pts[0][:, 1].tolist()
    fr = _Frame(np.array([min(xs), min(ys)]), np.array([max(xs), max(ys)]))
    refit = "" if fit is None else _outline(fr, *fit[:3], "refit", *fit[3:])
    second = "" if rival is None else _outline(fr, *rival[0], "rival")
    outlines = _outline(fr, bx, by, br, "best") + refit + second
    panels = [] if pts is None else [_residual_panel(fr, pts[0], pts[1], outlines)]
    panels.append(_score_panel(fr, scan, outlines))
    return text + '<div class="scan-panels">' + "".join(panels) + "</div>"


def _rival(scan: Mapping[str, Any]) -> tuple[tuple[float, float, float], str] | None:
    """The scan's second place refitted from — ``((x, y, size) [mm], a sentence)`` — or None."""
    r = scan.get("rival")
    if not isinstance(r, Mapping) or not isinstance(r.get("refits"), Mapping):
        return None
    try:
        x, y, size = (float(r[k]) * 1e3 for k in ("x_m", "y_m", "size_m"))
    except (KeyError, TypeError, ValueError):
        return None
    f = r["refits"]
    d = f.get("delta_chi2")
    kept = _e(f.get("kept"))
    verdict = ("its refit alone succeeded, and is the one carried" if d is None else
               f"the two refits' χ² differ by {_fmt(abs(float(d)), 4)}: the {kept} place is carried"
               + ("" if f.get("separable") else ", but the data cannot tell the two apart (within the "
                  "AIC margin)"))
    share = _fmt(100 * float(r.get("share_of_best") or 0), 3)
    return (x, y, size), (f" A second place of its own scored {share} % of the best (orange, x {x:.3g} mm, "
                          f"y {y:.3g} mm): the candidate was refitted from there too; {verdict}.")


def section_scan(report: Mapping[str, Any]) -> str:
    """The region section of the gap report (module docstring)."""
    head = '<section id="scan"><h2>Where the region is: region scan</h2>'
    scans = [s for s in report.get("region_scan") or [] if isinstance(s, Mapping)]
    if not scans:
        return head + ('<p class="note">No region scan: no candidate effect declares a region, or the '
                       "session has no tracked points.</p></section>")
    return head + "".join(_one(report, s) for s in scans) + "</section>"


__all__ = ["section_scan"]
