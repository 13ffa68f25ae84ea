"""The surface tracks: each tracked point's displacement from its first observed position — the
map at the frame of largest motion, the in-plane trajectories, and displacement against time."""

from __future__ import annotations

from typing import Any

import numpy as np

from skinkit.report.common import (
    Section,
    e,
    figure,
    img,
    kv_table,
    mpl,
    note,
    num,
    plural,
    png_uri,
    slug,
    value_text,
)
from skinkit.schemas import SurfaceTrack
from skinkit.store.experiment import Experiment

#: at most this many trajectories are drawn, and this many points' components against time
MAX_TRAJECTORIES = 400
N_TIME_SERIES = 4


def displacements(track: SurfaceTrack) -> tuple[np.ndarray, np.ndarray]:
    """Each point's reference position ``(P, 3)`` [m] (where it was first observed; NaN if never)
    and displacement from it ``(P, F, 3)`` [m] (NaN where not observed)."""
    pts = np.where(track.valid[:, :, None], track.points, np.nan)
    seen = track.valid.any(axis=1)
    first = np.argmax(track.valid, axis=1)
    ref = np.where(seen[:, None], pts[np.arange(len(pts)), first], np.nan)
    return ref, pts - ref[:, None, :]


def _figure(track: SurfaceTrack, name: str) -> str:
    ref, u = displacements(track)
    mag = np.linalg.norm(u, axis=2) * 1e3                        # (P, F) [mm]
    with np.errstate(all="ignore"):
        mean_mag = np.nanmean(np.where(np.isfinite(mag), mag, np.nan), axis=0)
    k = int(np.nanargmax(np.where(np.isfinite(mean_mag), mean_mag, -1.0)))
    xy = ref[:, :2] * 1e3
    ok = np.isfinite(xy).all(axis=1) & np.isfinite(mag[:, k])
    fig = figure(10.0, 7.6)
    # the map at the frame of largest mean motion
    ax = fig.add_subplot(2, 2, 1)
    sc = ax.scatter(xy[ok, 0], xy[ok, 1], c=mag[ok, k], s=14, cmap="viridis")
    fig.colorbar(sc, ax=ax, label="|u| [mm]")
    uk = u[ok, k, :2] * 1e3
    if ok.sum() and np.abs(uk).max() > 0:
        ax.quiver(xy[ok, 0], xy[ok, 1], uk[:, 0], uk[:, 1], color="k", width=0.003, alpha=0.7)
    ax.set_aspect("equal")
    ax.set_title(f"displacement at frame {k} (t = {num(track.time_s[k])} s)", fontsize=9)
    ax.set_xlabel("x [mm]", fontsize=8)
    ax.set_ylabel("y [mm]", fontsize=8)
    # in-plane trajectories, magnified so the largest is a tenth of the field
    ax = fig.add_subplot(2, 2, 2)
    span = float(np.ptp(xy[ok], axis=0).max()) if ok.sum() > 1 else 1.0
    top = float(np.nanmax(mag)) if np.isfinite(mag).any() else 0.0
    gain = 0.1 * span / top if top > 0 and span > 0 else 1.0
    idx = np.flatnonzero(np.isfinite(xy).all(axis=1))
    idx = idx[np.unique(np.linspace(0, len(idx) - 1, min(len(idx), MAX_TRAJECTORIES)).astype(int))] \
        if len(idx) else idx
    for i in idx:
        path = xy[i] + gain * u[i, :, :2] * 1e3
        ax.plot(path[:, 0], path[:, 1], lw=0.6, color="C0")
    ax.plot(xy[idx, 0], xy[idx, 1], ".", color="k", ms=2)
    ax.set_aspect("equal")
    ax.set_title(f"in-plane trajectories, displacement ×{num(gain, 2)}", fontsize=9)
    ax.set_xlabel("x [mm]", fontsize=8)
    # displacement against time
    ax = fig.add_subplot(2, 2, 3)
    with np.errstate(all="ignore"):
        ax.plot(track.time_s, mean_mag, color="k", label="mean over points")
        ax.plot(track.time_s, np.nanmax(np.where(np.isfinite(mag), mag, -np.inf), axis=0), color="C3",
                label="largest")
    ax.set_xlabel("time [s]", fontsize=8)
    ax.set_ylabel("|u| [mm]", fontsize=8)
    ax.legend(fontsize=7)
    ax.set_title("displacement magnitude against time", fontsize=9)
    ax = fig.add_subplot(2, 2, 4)
    peak = np.where(np.isfinite(mag), mag, -1.0).max(axis=1)
    order = np.argsort(-peak)
    picks = order[np.unique(np.linspace(0, max(0, int(np.isfinite(mag).any(axis=1).sum()) - 1),
                                        N_TIME_SERIES).astype(int))]
    for n, i in enumerate(picks):
        for c, style in zip(range(3), ("-", "--", ":"), strict=True):
            ax.plot(track.time_s, u[i, :, c] * 1e3, style, color=f"C{n}", lw=0.9,
                    label=f"point {i}" if c == 0 else None)
    ax.set_xlabel("time [s]", fontsize=8)
    ax.set_ylabel("u [mm] (x solid, y dashed, z dotted)", fontsize=8)
    ax.legend(fontsize=7)
    ax.set_title("components of a few points (largest to smallest motion)", fontsize=9)
    for a in fig.axes:
        a.tick_params(labelsize=7)
    fig.suptitle(mpl(f"{name}: {track.n_points} points × {track.n_frames} frames"), fontsize=9)
    return png_uri(fig)


def _facts(track: SurfaceTrack, attrs: dict[str, Any]) -> str:
    ref, u = displacements(track)
    mag = np.linalg.norm(u, axis=2)
    rows: list[tuple[str, Any]] = [
        ("points × frames", f"{track.n_points} × {track.n_frames}"),
        ("time span [s]", f"{num(track.time_s[0])} to {num(track.time_s[-1])}"),
        ("observations valid", f"{100 * track.valid.mean():.1f} %"),
        ("points valid in every frame", f"{int(track.valid.all(axis=1).sum())}"),
        ("largest displacement [mm]", num(np.nanmax(mag) * 1e3 if np.isfinite(mag).any() else np.nan, 4)),
    ]
    rows += [(str(k), value_text(v)) for k, v in attrs.items()]
    return kv_table(rows)


def _track(exp: Experiment, name: str) -> str:
    track = exp.read_track(name)
    attrs = exp.track_attrs(name)
    head = f'<div class="item" id="track-{slug(name)}"><h3>{e(name)}</h3>'
    if not track.valid.any():
        return head + _facts(track, attrs) + note("No point was observed in any frame.") + "</div>"
    return head + _facts(track, attrs) + img(_figure(track, name), f"track {name}: displacements") + "</div>"


def section(exp: Experiment) -> Section:
    """The surface tracks (``/tracks``)."""
    names = exp.track_names()
    if not names:
        return Section("tracks", "Surface tracks", None, "omitted: the file holds no surface track")
    body = ("<p>Displacement u of each tracked point from its first observed position (world frame, "
            "mm).</p>" + "".join(_track(exp, n) for n in names))
    return Section("tracks", "Surface tracks", body, f"{plural(len(names), 'track')} ({', '.join(names)})")
