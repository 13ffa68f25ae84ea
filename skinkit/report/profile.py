"""The surface profiles: each point cloud from above (coloured by height), in perspective and
from the side, with its quality measure and its uncertainty."""

from __future__ import annotations

import numpy as np

from skinkit.report.common import (
    MAX_PLOT_POINTS,
    Section,
    e,
    figure,
    img,
    mpl,
    note,
    num,
    plural,
    png_uri,
    slug,
    t,
    table,
)
from skinkit.schemas import SurfaceProfile
from skinkit.store.experiment import Experiment


def _subsample(n: int) -> np.ndarray:
    """Indices of at most MAX_PLOT_POINTS of ``n`` points, spread evenly (for drawing only)."""
    return np.unique(np.linspace(0, n - 1, min(n, MAX_PLOT_POINTS)).astype(int))


def _figure(prof: SurfaceProfile, name: str) -> str:
    pts = prof.points[_subsample(prof.n_points)] * 1e3
    q = prof.quality[_subsample(prof.n_points)]
    ok = np.isfinite(pts).all(axis=1)
    pts, q = pts[ok], q[ok]
    fig = figure(10.0, 7.2)
    ax = fig.add_subplot(2, 2, 1)
    sc = ax.scatter(pts[:, 0], pts[:, 1], c=pts[:, 2], s=4, cmap="viridis")
    fig.colorbar(sc, ax=ax, label="z [mm]")
    ax.set_aspect("equal")
    ax.set_title("from above, coloured by height", fontsize=9)
    ax.set_xlabel("x [mm]", fontsize=8)
    ax.set_ylabel("y [mm]", fontsize=8)
    ax3 = fig.add_subplot(2, 2, 2, projection="3d")
    ax3.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=pts[:, 2], s=2, cmap="viridis")
    ax3.set_title("in perspective (z exaggerated to fill the box)", fontsize=9)
    for lab, setter in (("x [mm]", ax3.set_xlabel), ("y [mm]", ax3.set_ylabel), ("z [mm]", ax3.set_zlabel)):
        setter(lab, fontsize=7)
    ax3.tick_params(labelsize=6)
    ax = fig.add_subplot(2, 2, 3)
    ax.scatter(pts[:, 0], pts[:, 2], s=2, c="0.3")
    ax.set_title("from the side (x–z)", fontsize=9)
    ax.set_xlabel("x [mm]", fontsize=8)
    ax.set_ylabel("z [mm]", fontsize=8)
    ax = fig.add_subplot(2, 2, 4)
    sc = ax.scatter(pts[:, 0], pts[:, 1], c=q, s=4, cmap="magma")
    fig.colorbar(sc, ax=ax, label=mpl(prof.quality_name))
    ax.set_aspect("equal")
    ax.set_title(f"quality: {mpl(prof.quality_name)}", fontsize=9)
    ax.set_xlabel("x [mm]", fontsize=8)
    for a in fig.axes:
        a.tick_params(labelsize=7)
    fig.suptitle(mpl(f"{name}: {prof.n_points} points"
                     + (f" ({len(pts)} drawn)" if len(pts) < prof.n_points else "")), fontsize=9)
    return png_uri(fig)


def _stats(prof: SurfaceProfile) -> str:
    p = prof.points[np.isfinite(prof.points).all(axis=1)] * 1e3
    rows = []
    if len(p):
        for k, ax in enumerate("xyz"):
            rows.append([t(f"{ax} [mm]"), t(num(p[:, k].min(), 4)), t(num(p[:, k].max(), 4)),
                         t(num(np.ptp(p[:, k]), 4)), t(num(p[:, k].mean(), 4))])
    for label, v in ((prof.quality_name, prof.quality), ("uncertainty [px]", prof.uncertainty_px)):
        if v is not None and np.isfinite(v).any():
            w = v[np.isfinite(v)]
            rows.append([t(label), *(t(num(q, 4)) for q in (w.min(), w.max(), np.ptp(w), w.mean()))])
    return table(["quantity", "min", "max", "range", "mean"], rows, sortable=False)


def _profile(exp: Experiment, name: str) -> str:
    prof = exp.read_profile(name)
    head = f'<div class="item" id="profile-{slug(name)}"><h3>{e(name)}</h3>'
    bad = int((~np.isfinite(prof.points).all(axis=1)).sum())
    intro = f"<p>{prof.n_points} points" + (f", {bad} of them not finite" if bad else "") + ".</p>"
    if prof.n_points - bad < 3:
        return head + intro + note("Too few points to draw.") + "</div>"
    return head + intro + img(_figure(prof, name), f"profile {name}: views of the point cloud") + \
        _stats(prof) + "</div>"


def section(exp: Experiment) -> Section:
    """The surface profiles (``/profiles``)."""
    names = exp.profile_names()
    if not names:
        return Section("profiles", "Surface profiles", None, "omitted: the file holds no surface profile")
    body = "<p>Point clouds in the world frame of the rig (of the session for a virtual lab) [mm].</p>"
    body += "".join(_profile(exp, n) for n in names)
    what = f"{plural(len(names), 'profile')} ({', '.join(names)})"
    return Section("profiles", "Surface profiles", body, what)
