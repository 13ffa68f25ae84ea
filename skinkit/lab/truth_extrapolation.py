"""The virtual lab's truth extrapolated to a vanishing element size (Richardson).

A truth solved on a finite mesh carries its own discretisation error, and a fit reads it. Its
standard errors are a small fraction of the noise level (thousands of samples), so even a truth
error well below the noise per sample biases the estimates by standard errors: on the two-pad
coverage case a truth 5x finer than the model, whose own error is under 0.72 noise levels,
still leaves the subdermal modulus about 1.8 standard errors off, where the fit of the same
model to the extrapolated solution is within them. Refining further soon costs more than a
machine has; extrapolation costs two coarser solves.

**Family.** The truth's own node placement (:func:`skinkit.lab.truth_mesh.own_gradings`: no node where
the model's mesh or its refinement check put one) with every element count — in-plane and through
each layer — multiplied by k (the same function). Gradings are functions of the position along
a segment, so the members differ only in size: the setting Richardson extrapolation assumes.

**Order and limit.** For members k = F − 2, F − 1, F (a, b, c) and each protocol and channel, the
error model y_k = y∞ − C k^(−p) gives the observed order p from the norms of the successive changes,
‖y_b − y_a‖ / ‖y_c − y_b‖ = (a^(−p) − b^(−p)) / (b^(−p) − c^(−p)), and the limit
y∞ = y_c + (y_c − y_b) c^(−p) / (b^(−p) − c^(−p)) (Richardson, generalised to non-integer ratios;
Roache, *Verification and Validation in Computational Science and Engineering*, 1998). A ratio
above the asymptotic range (p > :data:`ORDER_MAX`) takes that order; one below it (the changes
do not shrink as an order of :data:`ORDER_MIN` would: the members are not in the asymptotic range,
and a limit at that order would amplify the last change several-fold) is not extrapolated: the
finest member is kept, its error stated as an order 1 would make it, b/(c − b) |y_c − y_b|
(not a bound there), and the report says so (``clipped``, ``extrapolated`` false).

**Tracked points by their motion.** A points channel ``(P, F, 3)`` is extrapolated in its motion
since the first frame, then put back on the finest member's first frame: on a curved top each
member embeds the material points on its own approximation of the surface, a static offset per
point (microns) that the fit never sees (a session's track is referred to its first frame) and
that would otherwise swamp the convergence of the motion.

**Its own error, estimated.** p is fitted to norms; where the error's shape still changes from
member to member the asymptotic form does not hold point by point. The coarsest member predicted
from the two finer ones and p, ŷ_a = y∞ − (y∞ − y_c)(c/a)^p, departs from the solved one by what
the form misses there; scaled by (b/c)^p, the resolved error's shrinkage from the middle member to
the finest, it is the estimate the truth file states (``truth_rms``), besides the correction
itself (the error of the finest member alone, ``correction_rms``). An estimate, not a bound: on
members with a second error term of order 2.5 beside one of order 1, as large as the first on the
coarsest member, a tenth of it or between, the limit's error is 0.5 to 0.95 times the estimate and
0.6 to 0.05 times the finest member's (``tests/lab/test_truth_extrapolation.py``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.optimize import brentq

from skinkit.lab.truth_mesh import TruthMeshError

#: the observed orders accepted as asymptotic: a quadratic element converges near 1 at a bonded
#: edge (a singularity) and at 3 in displacement where the field is smooth
ORDER_MIN, ORDER_MAX = 0.5, 4.0
#: the coarsest finest member: three members 1, 2, 3 times the model's counts
MIN_FACTOR = 3


def members(factor: int) -> tuple[int, int, int]:
    """The three member factors extrapolated from, the finest ``factor`` (>= :data:`MIN_FACTOR`)."""
    if isinstance(factor, bool) or not isinstance(factor, int) or factor < MIN_FACTOR:
        raise TruthMeshError(f"an extrapolated truth needs a factor of at least {MIN_FACTOR} (three "
                             f"members 1..3 times the model's element counts), got {factor!r}")
    return factor - 2, factor - 1, factor


def _ratio(p: float, a: float, b: float, c: float) -> float:
    return (a ** -p - b ** -p) / (b ** -p - c ** -p)


def observed_order(ya: np.ndarray, yb: np.ndarray, yc: np.ndarray,
                   ks: tuple[int, int, int]) -> tuple[float | None, bool]:
    """``(p, clipped)``: the order whose error model matches the norms of the successive changes
    (module docstring), clipped to [:data:`ORDER_MIN`, :data:`ORDER_MAX`]; ``(None, False)`` when
    the finer change is nil (nothing to extrapolate)."""
    ok = np.isfinite(ya) & np.isfinite(yb) & np.isfinite(yc)
    d1 = float(np.linalg.norm((yb - ya)[ok]))
    d2 = float(np.linalg.norm((yc - yb)[ok]))
    if d2 == 0.0 or d1 == 0.0:
        return None, False
    a, b, c = (float(k) for k in ks)
    r = d1 / d2
    lo, hi = _ratio(ORDER_MIN, a, b, c), _ratio(ORDER_MAX, a, b, c)
    if r <= lo:
        return ORDER_MIN, True
    if r >= hi:
        return ORDER_MAX, True
    return float(brentq(lambda p: _ratio(p, a, b, c) - r, ORDER_MIN, ORDER_MAX, xtol=1e-12)), False


def extrapolate(solved: Mapping[int, Mapping[str, Mapping[str, np.ndarray]]], ks: tuple[int, int, int],
                noise: Mapping[str, float]) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, Any]]:
    """The limit of the members' noiseless channels ``solved[k][protocol][channel]`` and its figures.

    Returns ``(values, report)``: ``values[protocol][channel]`` the extrapolated channel (a drive
    channel, equal on every member, as solved); ``report``: per channel (over protocols)
    ``truth_rms`` (the extrapolated truth's estimated error), ``correction_rms`` (the finest
    member's own error, extrapolated), each ``..._over_noise`` against ``noise[channel]`` [unit],
    and ``orders``: per ``protocol/channel`` the observed order, whether it was clipped and
    whether the channel was extrapolated."""
    a, b, c = ks
    values: dict[str, dict[str, np.ndarray]] = {}
    acc: dict[str, dict[str, list[np.ndarray]]] = {}
    orders: dict[str, dict[str, Any]] = {}
    for proto, chans in solved[c].items():
        values[proto] = {}
        for name, yc_ in chans.items():
            yc = np.asarray(yc_, float)
            ya, yb = (np.asarray(solved[k][proto][name], float) for k in (a, b))
            base = None
            if yc.ndim == 3 and yc.shape[1] > 1:
                base = yc[:, :1].copy()
                ya, yb, yc = ya - ya[:, :1], yb - yb[:, :1], yc - base
            p, clipped = observed_order(ya, yb, yc, ks)
            if p is None:
                values[proto][name] = yc if base is None else yc + base
                continue
            part = acc.setdefault(name, {"truth": [], "correction": []})
            ok = np.isfinite(ya) & np.isfinite(yb) & np.isfinite(yc)
            extrapolated = not (clipped and p == ORDER_MIN)
            orders[f"{proto}/{name}"] = {"order": p, "clipped": clipped, "extrapolated": extrapolated}
            if not extrapolated:
                values[proto][name] = yc if base is None else yc + base
                part["truth"].append(((yc - yb)[ok] * b / (c - b)).ravel())
                part["correction"].append(np.zeros(int(ok.sum())))
                continue
            w = c ** -p / (b ** -p - c ** -p)
            inf = yc + (yc - yb) * w
            values[proto][name] = inf if base is None else inf + base
            ya_hat = inf - (inf - yc) * (c / a) ** p
            part["truth"].append(((ya - ya_hat)[ok] * (b / c) ** p).ravel())
            part["correction"].append(((inf - yc)[ok]).ravel())
    report: dict[str, Any] = {"members": list(ks), "orders": orders, "channels": {}}
    for name, parts in acc.items():
        sig = noise.get(name)
        row: dict[str, float | None] = {}
        for key, arrs in parts.items():
            rms = float(np.sqrt(np.mean(np.concatenate(arrs) ** 2)))
            row[f"{key}_rms"] = rms
            row[f"{key}_over_noise"] = rms / sig if sig else None
        report["channels"][name] = row
    return values, report


__all__ = ["MIN_FACTOR", "ORDER_MAX", "ORDER_MIN", "extrapolate", "members", "observed_order"]
