"""Figures for people who would rather look than read (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from skinkit.schemas import SurfaceProfile


def plot_profile(profile: SurfaceProfile, path: str | Path, title: str = "") -> Path:
    """Save a two-panel figure of a profile: height map and integer-shift uncertainty [mm, px]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    P = profile.points * 1e3
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), constrained_layout=True)
    sc = axes[0].scatter(P[:, 0], P[:, 1], c=P[:, 2], s=4, cmap="viridis")
    fig.colorbar(sc, ax=axes[0], label="height z [mm]")
    axes[0].set_title("surface height")
    if profile.uncertainty_px is not None:
        isu = np.asarray(profile.uncertainty_px)
        sc2 = axes[1].scatter(P[:, 0], P[:, 1], c=isu, s=4, cmap="magma_r", vmin=1, vmax=max(8.0, isu.max()))
        fig.colorbar(sc2, ax=axes[1], label="integer-shift uncertainty [px]")
        axes[1].set_title(f"ISU: mean {isu.mean():.2f} px, sd {isu.std():.2f} px")
    for ax in axes:
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.set_aspect("equal")
    if title:
        fig.suptitle(title)
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
