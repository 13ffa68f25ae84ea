"""Standard errors that count what overlapping subsets share.

A subset tracker's position is a weighted mean over its subset, a square of side w on the skin
(the track's ``window_m``). Two points whose subsets overlap share the image noise and the
deformation their subsets misread, so their errors correlate — for the mean of white noise over
two uniform squares offset by (Δx, Δy), exactly by the overlap fraction

    ρ(Δ) = (1 − |Δx|/w)₊ (1 − |Δy|/w)₊ .

The fit's χ² and its covariance (JᵀJ)⁻¹ count every tracked position as independent: with points
closer than a subset (the demo's are 0.3 mm apart under 2.7 mm subsets, and their errors against
the lab's truth correlate at about 0.8 between neighbours) that overstates what the points know.
The sandwich covariance A⁻¹ (Jᵀ C J) A⁻¹, A = JᵀJ (Huber 1967; White, Econometrica 48, 1980),
with C the overlap correlation between the residuals of one frame and component of one track,
restores it. Residuals of different frames, components, tracks and channels stay independent;
the whitening along frames is taken to commute with C (exact when every point has the same σ).

Only point channels with a ``window_m`` are corrected: a track made by subset correlation
declares its subset's footprint; synthetic tracks with independent noise declare none.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from skinkit.schemas import Channel, Observations


def overlap_matrix(reference: np.ndarray, window_m: float) -> sparse.csr_matrix:
    """``(P, P)`` sparse off-diagonal part of ρ between the points ``reference`` ``(P, ≥2)`` [m]
    (their x, y) for subsets of side ``window_m`` [m]."""
    xy = np.asarray(reference, float)[:, :2]
    P = len(xy)
    pairs = cKDTree(xy).query_pairs(r=window_m * np.sqrt(2.0), output_type="ndarray")
    if pairs.size == 0:
        return sparse.csr_matrix((P, P))
    d = np.abs(xy[pairs[:, 0]] - xy[pairs[:, 1]])
    rho = np.clip(1 - d[:, 0] / window_m, 0, None) * np.clip(1 - d[:, 1] / window_m, 0, None)
    keep = rho > 0
    i, j, v = pairs[keep, 0], pairs[keep, 1], rho[keep]
    return sparse.coo_matrix((np.r_[v, v], (np.r_[i, j], np.r_[j, i])), shape=(P, P)).tocsr()


def _block_meat(J: np.ndarray, ch: Channel) -> np.ndarray | None:
    """Σ over frames and components of J_tkᵀ R J_tk for one point channel's rows ``J``, R the
    off-diagonal overlap; None when its rows cannot be matched to the channel's entries."""
    mask = ch.fit_mask()
    if int(mask.sum()) != J.shape[0] or ch.reference is None:
        return None
    R = overlap_matrix(ch.reference, float(ch.window_m))
    p, t, k = np.nonzero(mask)                  # the objective's row order (C order over the mask)
    P, n = mask.shape[0], J.shape[1]
    out = np.zeros((n, n))
    group = t * mask.shape[2] + k
    for g in np.unique(group):
        rows = np.flatnonzero(group == g)
        Jp = np.zeros((P, n))
        Jp[p[rows]] = J[rows]
        out += Jp.T @ (R @ Jp)
    return out


def overlap_meat(J: np.ndarray, blocks: Sequence[tuple[str, str, slice]],
                 observations: Observations) -> tuple[np.ndarray | None, dict[str, Any]]:
    """``(JᵀCJ, facts)`` for the fit's whitened Jacobian ``J`` ``(m, n)`` and its residual blocks
    (protocol, channel, rows); JᵀCJ is None when no block is a subset track. ``facts``:
    ``corrected`` (protocol/channel blocks counted), ``skipped`` (blocks whose rows did not match
    their channel's entries)."""
    meat = J.T @ J
    corrected, skipped = [], []
    for proto, cname, sl in blocks:
        ch = observations[proto].channels.get(cname)
        if ch is None or not ch.is_points or ch.window_m is None:
            continue
        extra = _block_meat(J[sl], ch)
        if extra is None:
            skipped.append(f"{proto}/{cname}")
            continue
        meat = meat + extra
        corrected.append(f"{proto}/{cname}")
    return (meat if corrected else None), {"corrected": corrected, "skipped": skipped}


__all__ = ["overlap_matrix", "overlap_meat"]
