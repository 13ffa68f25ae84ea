"""Plots of a fit: measured against predicted, where the residual sits, what the data determine.

Every function writes one PNG and returns its path. Matplotlib figures are made with the Agg
canvas directly (no pyplot, no global backend state, nothing opened on a screen); the residual
map is rendered by pyvista off screen, with a matplotlib scatter as the fallback when VTK
cannot render on the machine (the figure's title then says so, and a warning is issued).

* :func:`fit_plots` — for a :class:`skinkit.schemas.FitResult` on a session:
  ``loops.png`` (tip force against tip displacement per protocol, along the drive's main axis,
  measured and predicted), ``trajectories.png`` (displacement magnitude of a few
  representative tracked points over time, measured and predicted), ``residual_map.png``
  (tracked points at their reference positions coloured by their RMS noise-normalised
  residual, over the session's surface profile when it has one) and ``correlation.png``
  (the correlation matrix of the free parameters);
* :func:`grid_plot` — an objective grid (:func:`skinkit.inverse.grid.objective_grid`):
  contours of Δ(2φ), the valley floor (the thesis's red line of Fig 7-10), the minimum, and
  the fit's 95 % indifference ellipses when a covariance is attached;
* :func:`profile_plot` — a profile likelihood (:func:`skinkit.inverse.grid.profile_likelihood`)
  against its quadratic (Wald) approximation.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.inverse.map_mask import hole_triangles
from skinkit.schemas import Channel, FitResult, Observations, Prediction

#: how many tracked points a trajectory panel shows
N_TRAJECTORIES = 4


def _figure(n_panels: int, width: float = 4.2, height: float = 3.4,
            cols: int | None = None) -> tuple[Any, list]:
    from matplotlib.figure import Figure

    cols = cols or min(n_panels, 3)
    rows = math.ceil(n_panels / cols)
    fig = Figure(figsize=(width * cols, height * rows), layout="constrained")
    axes = [fig.add_subplot(rows, cols, k + 1) for k in range(n_panels)]
    return fig, axes


def _save(fig: Any, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def _on_times(ch: Channel, values: np.ndarray, t: np.ndarray, k: int) -> np.ndarray:
    """Component ``k`` of a tip channel's ``values`` on the times ``t`` (NaN where not valid)."""
    v = np.where(ch.valid[:, k], values[:, k], np.nan)
    if ch.time_s.shape == t.shape and np.array_equal(ch.time_s, t):
        return v
    ok = np.isfinite(v)
    if ok.sum() < 2:
        return np.full(t.shape, np.nan)
    return np.interp(t, ch.time_s[ok], v[ok], left=np.nan, right=np.nan)


def _main_axis(ch: Channel) -> int:
    """The component along which a tip channel moves most (its largest valid range)."""
    rng = [np.ptp(ch.values[ch.valid[:, k], k]) if ch.valid[:, k].any() else -1.0 for k in range(3)]
    return int(np.argmax(rng))


def _smoothed(v: np.ndarray, t: np.ndarray, window_s: float) -> np.ndarray:
    """``v`` ``(T,)`` by local quadratic regression over ``window_s`` (valid samples only)."""
    from skinkit.forward.drive import smooth_at

    ok = np.isfinite(v)
    if ok.sum() < 5:
        return v
    return np.where(ok, smooth_at(t[ok], v[ok], t, window_s), np.nan)


#: window [s] of the local quadratic regression drawn as the drive of the predicted loop
#: (the finite-element model's own drive regression at its default 0.5 s step)
DRIVE_WINDOW_S = 0.5


def loops_plot(observations: Observations, prediction: Prediction, path: Path,
               title: str = "") -> Path | None:
    """Tip force against tip displacement per protocol, along the main axis of the channel that
    drove the model: measured (grey), and predicted (red: the predicted channel against the
    recorded drive, smoothed as the finite-element model smooths it, :data:`DRIVE_WINDOW_S`,
    so the drive's sensor noise does not blur the predicted curve). None when no protocol has
    both tip channels."""
    panels = [p for p in observations if {"tip_force", "tip_position"} <= set(p.channels)]
    if not panels:
        return None
    fig, axes = _figure(len(panels))
    for ax, po in zip(axes, panels, strict=True):
        f, x = po.channels["tip_force"], po.channels["tip_position"]
        pp = prediction.protocols.get(po.name, {})
        drive = prediction.inputs.get(po.name, "tip_force" if "tip_position" in pp else "tip_position")
        k = _main_axis(po.channels[drive])
        t = f.time_s
        mx, mf = _on_times(x, x.values, t, k), _on_times(f, f.values, t, k)
        big = np.nanmax(np.abs(mx)) if np.isfinite(mx).any() else 0.0
        scale, unit = (1e3, "mm") if big >= 1e-3 else (1e6, "µm")
        ax.plot(mx * scale, mf, color="0.55", lw=0.8, alpha=0.8, label="measured")
        px, pf = mx, mf
        if drive == "tip_force":
            pf = _smoothed(mf, t, DRIVE_WINDOW_S)
        else:
            px = _smoothed(mx, t, DRIVE_WINDOW_S)
        if "tip_position" in pp:
            cp = pp["tip_position"]
            px = _on_times(x, np.where(_predicted(cp, x), cp.values, np.nan), t, k)
        if "tip_force" in pp:
            cp = pp["tip_force"]
            pf = _on_times(f, np.where(_predicted(cp, f), cp.values, np.nan), t, k)
        if "tip_position" in pp or "tip_force" in pp:
            ax.plot(px * scale, pf, color="C3", lw=1.4, label="predicted")
        axis = "xyz"[k]
        ax.set_xlabel(f"tip displacement {axis} [{unit}]")
        ax.set_ylabel(f"tip force {axis} [N]")
        ax.set_title(f"{po.name}{' (held out)' if po.held_out else ''} — driven by {drive.replace('_', ' ')}",
                     fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def _predicted(cp: Any, ch: Channel) -> np.ndarray:
    return np.ones(ch.values.shape, bool) if cp.predicted is None else np.asarray(cp.predicted, bool)


def _point_channels(observations: Observations,
                    prediction: Prediction) -> list[tuple[str, str, Channel, Any]]:
    out = []
    for po in observations:
        for cname in ("points", "points_2d"):
            cp = prediction.protocols.get(po.name, {}).get(cname)
            if cname in po.channels and cp is not None:
                out.append((po.name, cname, po.channels[cname], cp))
    return out


def _displacement(ch: Channel, values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``(P, T)`` displacement magnitude from the reference (or the first frame) [m]."""
    k = values.shape[-1]
    ref = ch.reference[:, :k] if ch.reference is not None else ch.values[:, 0, :]
    d = np.linalg.norm(values - ref[:, None, :], axis=-1)
    return np.where(valid.all(axis=-1), d, np.nan)


def trajectories_plot(observations: Observations, prediction: Prediction, path: Path,
                      title: str = "") -> Path | None:
    """Displacement magnitude over time of :data:`N_TRAJECTORIES` tracked points per protocol
    (the most displaced, and points at two thirds, one third and a tenth of its displacement):
    measured as markers, predicted as lines. None without a tracked-point channel."""
    chans = _point_channels(observations, prediction)
    if not chans:
        return None
    fig, axes = _figure(len(chans))
    for ax, (proto, cname, ch, cp) in zip(axes, chans, strict=True):
        meas = _displacement(ch, ch.values, ch.valid)
        pv = _predicted(cp, ch)
        pred = _displacement(ch, np.where(pv, cp.values, np.nan), ch.valid & pv)
        dmax = np.nan_to_num(np.nanmax(np.where(np.isfinite(meas), meas, -np.inf), axis=1), neginf=0.0)
        order = np.argsort(-dmax)
        picks: list[int] = []
        for q in (0.0, 1 / 3, 2 / 3, 0.9):   # spread over the ranking, most displaced first
            i = int(order[min(int(q * len(order)), len(order) - 1)])
            if i not in picks:
                picks.append(i)
        for c, i in enumerate(picks[:N_TRAJECTORIES]):
            ax.plot(ch.time_s, meas[i] * 1e6, "o", ms=3, color=f"C{c}", alpha=0.7)
            ax.plot(ch.time_s, pred[i] * 1e6, "-", lw=1.2, color=f"C{c}", label=f"point {i}")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("displacement magnitude [µm]")
        held = " (held out)" if observations[proto].held_out else ""
        ax.set_title(f"{proto}{held} {cname}: markers measured, lines predicted", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def point_residuals(observations: Observations, prediction: Prediction) -> list[dict[str, Any]]:
    """Per protocol and point channel: ``reference`` ``(P, 3)`` [m] and ``rms`` ``(P,)``, the RMS
    noise-normalised residual of each point over its frames and components (NaN: never
    observed)."""
    out = []
    for proto, cname, ch, cp in _point_channels(observations, prediction):
        m = cp.mask(ch)
        r = ch.normalised(cp.values, m)
        n = m.sum(axis=(1, 2))
        with np.errstate(invalid="ignore", divide="ignore"):
            rms = np.sqrt(np.where(m, r ** 2, 0.0).sum(axis=(1, 2)) / n)
        ref = ch.reference if ch.reference is not None else np.nan_to_num(ch.values[:, 0, :])
        if ref.shape[1] == 2:
            ref = np.column_stack([ref, np.zeros(len(ref))])
        out.append({"protocol": proto, "channel": cname, "reference": ref,
                    "rms": np.where(n > 0, rms, np.nan)})
    return out


def _pool(panels: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One panel when every protocol tracked the same points (RMS pooled over protocols)."""
    if len(panels) < 2:
        return panels
    ref = panels[0]["reference"]
    if not all(p["reference"].shape == ref.shape and np.allclose(p["reference"], ref) for p in panels):
        return panels
    ms = np.array([p["rms"] ** 2 for p in panels])
    return [{"protocol": f"{len(panels)} protocols pooled", "channel": panels[0]["channel"], "reference": ref,
             "rms": np.sqrt(np.nanmean(ms, axis=0))}]


def residual_map(observations: Observations, prediction: Prediction, path: Path,
                 title: str = "") -> Path | None:
    """Tracked points at their reference positions coloured by their RMS noise-normalised
    residual (1 = at the noise level), over the session's surface profile (grey) or, without
    one, over a surface triangulated through the points. pyvista off screen; a matplotlib
    scatter if VTK cannot render (said in the title and by a warning). None without points."""
    panels = _pool(point_residuals(observations, prediction))
    if not panels:
        return None
    vmax = max(float(np.nanmax(p["rms"])) if np.isfinite(p["rms"]).any() else 1.0 for p in panels)
    vmax = max(vmax, 1.0)
    profile = None if observations.profile is None else observations.profile.points
    try:
        return _residual_map_pyvista(panels, profile, vmax, Path(path), title)
    except Exception as exc:  # noqa: BLE001 - any VTK failure: fall back and say why
        reason = f"{type(exc).__name__}: {exc}".splitlines()[0][:120]
        warnings.warn(f"residual map: pyvista could not render ({reason}); drawn with matplotlib instead",
                      RuntimeWarning, stacklevel=2)
        return _residual_map_matplotlib(panels, profile, vmax, Path(path),
                                        f"{title} [matplotlib fallback: pyvista could not render: {reason}]")


def _residual_map_pyvista(panels: list[dict[str, Any]], profile: np.ndarray | None, vmax: float, path: Path,
                          title: str) -> Path:
    import pyvista as pv

    cols = min(len(panels), 2)
    rows = math.ceil(len(panels) / cols)
    pl = pv.Plotter(off_screen=True, shape=(rows, cols), window_size=(620 * cols, 520 * rows), border=False)
    try:
        for k, p in enumerate(panels):
            pl.subplot(k // cols, k % cols)
            pts = p["reference"] * 1e3   # mm: the camera and the axes read better
            label = "RMS residual / noise"
            if profile is not None and len(profile) >= 3:
                pl.add_mesh(pv.PolyData(profile * 1e3).delaunay_2d(), color="lightgrey", opacity=0.5)
            elif len(pts) >= 3 and np.ptp(pts[:, 0]) > 0 and np.ptp(pts[:, 1]) > 0:
                surf = pv.PolyData(pts).delaunay_2d()
                tris = surf.faces.reshape(-1, 4)[:, 1:]
                keep = tris[~hole_triangles(pts[:, :2], tris)]   # no colour where no point is
                surf = pv.PolyData(pts, faces=np.column_stack([np.full(len(keep), 3), keep]).ravel())
                surf[label] = np.nan_to_num(p["rms"], nan=0.0)
                pl.add_mesh(surf, scalars=label, cmap="viridis", clim=(0, vmax), opacity=0.45,
                            show_scalar_bar=False)
            cloud = pv.PolyData(pts)
            cloud[label] = p["rms"]
            pl.add_mesh(cloud, scalars=label, cmap="viridis", clim=(0, vmax), nan_color="red",
                        render_points_as_spheres=True, point_size=14,
                        scalar_bar_args={"title": label, "vertical": True, "position_x": 0.84,
                                         "position_y": 0.2, "height": 0.6, "width": 0.08,
                                         "title_font_size": 12, "label_font_size": 11})
            pl.add_text(f"{p['protocol']} ({p['channel']})", font_size=9, position="upper_left")
            if k == 0 and title:
                pl.add_text(title, font_size=9, position="upper_right")
            pl.show_grid(xtitle="x [mm]", ytitle="y [mm]", ztitle="z [mm]", font_size=8)
            pl.view_xy()
            pl.camera.zoom(0.85)   # room for the axis labels and the colour bar
        path.parent.mkdir(parents=True, exist_ok=True)
        pl.screenshot(str(path))
    finally:
        pl.close()
    if not path.is_file() or path.stat().st_size == 0:
        raise RuntimeError("the screenshot is empty")
    return path


def _residual_map_matplotlib(panels: list[dict[str, Any]], profile: np.ndarray | None, vmax: float,
                             path: Path, title: str) -> Path:
    fig, axes = _figure(len(panels), width=5.0, height=4.4, cols=min(len(panels), 2))
    for ax, p in zip(axes, panels, strict=True):
        if profile is not None:
            ax.plot(profile[:, 0] * 1e3, profile[:, 1] * 1e3, ",", color="0.7")
        sc = ax.scatter(p["reference"][:, 0] * 1e3, p["reference"][:, 1] * 1e3, c=p["rms"], cmap="viridis",
                        vmin=0, vmax=vmax, s=40, edgecolors="k", linewidths=0.3)
        fig.colorbar(sc, ax=ax, label="RMS residual [noise levels]")
        ax.set_aspect("equal")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.set_title(f"{p['protocol']} ({p['channel']})", fontsize=9)
    fig.suptitle(title, fontsize=8)
    return _save(fig, path)


def correlation_plot(names: list[str], correlation: np.ndarray, path: Path, title: str = "") -> Path:
    """The correlation matrix of the free parameters as a heat map (−1 blue to +1 red), values written in."""
    C = np.asarray(correlation, float)
    n = len(names)
    fig, (ax,) = _figure(1, width=max(3.5, 0.9 * n + 2.2), height=max(3.0, 0.8 * n + 1.6))
    im = ax.imshow(C, cmap="RdBu_r", vmin=-1, vmax=1)
    ax.set_xticks(range(n), names, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(n), names, fontsize=8)
    for i in range(n):
        for j in range(n):
            ax.text(j, i, f"{C[i, j]:+.2f}", ha="center", va="center", fontsize=8,
                    color="white" if abs(C[i, j]) > 0.6 else "black")
    fig.colorbar(im, ax=ax, label="correlation [1]")
    ax.set_title(title or "correlation of the estimates", fontsize=9)
    return _save(fig, path)


def fit_plots(model: Any, observations: Observations, result: FitResult, out_dir: Path) -> list[Path]:
    """The plots of a fit (module docstring), written to ``out_dir``; their paths.

    ``model``: the forward model that was fitted; ``observations``: the session (held-out
    protocols are drawn too, and titled so); ``result``: the fit (its parameters, and the
    correlation matrix of its free parameters). One forward prediction at the fitted
    parameters. Plots that have nothing to show (no tracked points, a single free parameter's
    correlation) are not written.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    pred = model.predict(result.parameters, observations)
    name = getattr(model, "name", result.model)
    made = [loops_plot(observations, pred, out_dir / "loops.png", f"{name}: tip force against displacement"),
            trajectories_plot(observations, pred, out_dir / "trajectories.png", f"{name}: tracked points"),
            residual_map(observations, pred, out_dir / "residual_map.png", f"{name}: residual per point")]
    names = list(result.extra.get("free") or result.parameters.free_names)
    if result.correlation is not None and len(names) >= 2:
        made.append(correlation_plot(names, np.asarray(result.correlation), out_dir / "correlation.png",
                                     f"{name}: correlation of the estimates"))
    return [p for p in made if p is not None]


def _ellipse(centre: np.ndarray, cov: np.ndarray, level: float, n: int = 200) -> np.ndarray:
    """``(n, 2)`` points of {c + δ : δᵀ C⁻¹ δ = level}."""
    w, V = np.linalg.eigh(np.asarray(cov, float))
    t = np.linspace(0, 2 * np.pi, n)
    circle = np.stack([np.cos(t), np.sin(t)])
    return (centre[:, None] + V @ (np.sqrt(np.maximum(w, 0.0) * level)[:, None] * circle)).T


def grid_plot(grid: dict[str, Any], path: Path) -> Path:
    """An objective grid: filled contours of Δ(2φ) = 2(φ − φ_min) (Δχ² with the noise
    weighting), the lines Δ(2φ) = χ²₂ at 68, 95 and 99.7 % (times the inflation s when a fit's
    covariance is attached), the valley floor (for each value of the first parameter, the
    grid's best second one: the thesis's red line), the grid's minimum (×), its centre (+),
    points the model could not solve (grey ×), and — when attached
    (:func:`skinkit.inverse.grid.attach_covariance`) — the fit's 95 % indifference ellipses:
    solid, the others held fixed (it should trace the 95 % contour where φ is quadratic),
    dashed, the others re-fitted (the fit's standard errors)."""
    from matplotlib.colors import Normalize

    a, b = grid["pair"]
    pa, pb = grid["parameters"][a], grid["parameters"][b]
    X, Y = np.asarray(pa["values"], float), np.asarray(pb["values"], float)
    phi = np.array([[np.nan if v is None else v for v in row] for row in grid["objective"]], float)
    ref = np.nanmin(phi)
    if grid.get("centre_objective") is not None:
        ref = min(ref, grid["centre_objective"])
    D = 2 * (phi - ref)
    s = float(grid.get("inflation", 1.0))
    fig, (ax,) = _figure(1, width=6.0, height=5.0)
    ok = np.isfinite(D)
    top = float(np.nanmax(D)) if ok.any() else 1.0
    filled = ax.contourf(X, Y, np.log10(1 + np.where(ok, D, top)).T, levels=20, cmap="viridis_r",
                         norm=Normalize(0, math.log10(1 + max(top, 1e-12))))
    fig.colorbar(filled, ax=ax, label="log10(1 + Δ(2φ))")
    levels = np.array([2.30, 5.99, 11.8]) * s
    if ok.sum() >= 4 and np.nanmax(D) > levels[0]:
        cs = ax.contour(X, Y, np.where(ok, D, np.nan).T, levels=levels, colors="white",
                        linewidths=[0.8, 1.6, 0.8])
        ax.clabel(cs, fmt={lv: f"{q}" for lv, q in zip(cs.levels, ("68 %", "95 %", "99.7 %"), strict=False)},
                  fontsize=7)
    floor = [(X[i], Y[int(np.nanargmin(phi[i]))]) for i in range(len(X)) if np.isfinite(phi[i]).any()]
    if floor:
        fx, fy = np.array(floor).T
        ax.plot(fx, fy, "-", color="red", lw=1.2, label="valley floor")
    bad = ~ok
    if bad.any():
        ii, jj = np.nonzero(bad)
        ax.plot(X[ii], Y[jj], "x", color="0.5", ms=5, label="not solved")
    i, j = grid["minimum"]["index"]
    ax.plot(X[i], Y[j], "x", color="red", ms=10, mew=2, label="grid minimum")
    ax.plot(pa["centre"], pb["centre"], "+", color="black", ms=10, mew=1.5, label="centre")
    if grid.get("covariance_conditional") is not None:
        c = np.asarray(grid["ellipse_centre"], float)
        level = float(grid.get("ellipse_level", 5.991))
        for key, style, lab in (("covariance_conditional", "-", "95 % ellipse, others fixed"),
                                ("covariance_marginal", "--", "95 % ellipse, others re-fitted")):
            if grid.get(key) is not None:
                e = _ellipse(c, np.asarray(grid[key], float), level)
                ax.plot(e[:, 0], e[:, 1], style, color="orange", lw=1.5, label=lab)
    from matplotlib.ticker import MaxNLocator

    if pa["scaling"] == "log":
        ax.set_xscale("log")
    else:
        ax.xaxis.set_major_locator(MaxNLocator(5))   # long SI tick labels must not overlap
    if pb["scaling"] == "log":
        ax.set_yscale("log")
    ax.set_xlim(X.min(), X.max())
    ax.set_ylim(Y.min(), Y.max())
    ax.set_xlabel(f"{a} [{pa['unit']}]")
    ax.set_ylabel(f"{b} [{pb['unit']}]")
    ax.set_title(f"{grid.get('model', '')}\nobjective over {a}, {b} ({grid.get('weighting', '')} weighting, "
                 f"others fixed)", fontsize=9)
    ax.legend(fontsize=7, loc="best")
    return _save(fig, Path(path))


def profile_plot(profile: dict[str, Any], path: Path) -> Path:
    """A profile likelihood: left, Δ(2φ) against the value with the threshold χ²₁(0.95) s and
    the quadratic (Wald) parabola ((v − θ̂)/se)² s; right, the signed root against the value
    with ±1.96 and the Wald line (v − θ̂)/se. The profile interval is shaded."""
    name, unit = profile["parameter"], profile["unit"]
    v = np.asarray(profile["values"], float)
    d2 = np.array([np.nan if x is None else x for x in profile["delta_2phi"]], float)
    r = np.array([np.nan if x is None else x for x in profile["signed_root"]], float)
    theta, se, s = profile["estimate"], profile.get("se"), float(profile["inflation"])
    fig, (ax1, ax2) = _figure(2, width=4.8, height=3.8)
    vv = np.linspace(v.min(), v.max(), 200)
    ax1.plot(v, d2, "o-", color="C0", label="profile")
    ax2.plot(v, r, "o-", color="C0", label="profile")
    if se is not None and math.isfinite(se) and se > 0:
        ax1.plot(vv, s * ((vv - theta) / se) ** 2, "--", color="0.4", label="quadratic (Wald)")
        ax2.plot(vv, (vv - theta) / se, "--", color="0.4", label="Wald")
    ax1.axhline(profile["threshold"], color="C3", lw=1, label=f"χ²₁(0.95)·s = {profile['threshold']:.2f}")
    lv = math.sqrt(3.841458820694124)
    for y in (-lv, lv):
        ax2.axhline(y, color="C3", lw=1)
    lo, hi = profile["interval"]
    for ax in (ax1, ax2):
        ax.axvline(theta, color="0.6", lw=0.8)
        ax.axvspan(lo if lo is not None else v.min(), hi if hi is not None else v.max(), color="C2",
                   alpha=0.15, label="95 % interval")
        ax.set_xlabel(f"{name} [{unit}]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    ax1.set_ylabel("Δ(2φ) (Δχ² with the noise weighting)")
    ax2.set_ylabel("signed root √(Δ(2φ)/s)")
    top = max(np.nanmax(d2) if np.isfinite(d2).any() else 1.0, profile["threshold"])
    ax1.set_ylim(bottom=0, top=top * 1.1)
    others = ", ".join(profile.get("free") or []) or "none"
    fig.suptitle(f"{profile.get('model', '')}: profile of {name} (re-fitted: {others})", fontsize=9)
    return _save(fig, Path(path))


__all__ = ["correlation_plot", "fit_plots", "grid_plot", "loops_plot", "point_residuals", "profile_plot",
           "residual_map", "trajectories_plot"]
