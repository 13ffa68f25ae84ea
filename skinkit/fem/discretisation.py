"""Discretisation error: refined copies of a model description and Richardson extrapolation.

The finite-element answer ``v(h)`` on a mesh of element size ``h`` converges as
``v(h) = v* + C h^p`` when ``h`` is small enough; solving on meshes refined by factors
``f_i`` (``h_i ∝ 1/f_i``, every element count multiplied by ``f_i``, the mapping of the
geometry and its grading unchanged) gives ``v*`` (the extrapolated value), ``p`` (the
observed order) and so the error ``|v_i - v*|`` of each level. At a bonded punch's edge the
stress is singular and ``p`` is about 1.3 on uniformly refined meshes, not the 2-3 of a
smooth solution: the order is measured (three levels), or given by the caller (two levels).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from skinkit.fem.errors import ModelError

#: element counts of each geometry kind and the default the mesh builders use when a key is
#: absent (skinkit.fem.model._mesh, skinkit.fem.twopad.twopad_from_spec)
COUNT_DEFAULTS: dict[str, dict[str, Any]] = {
    "disc": {"n_inner": 3, "n_ring": 3},
    "block": {"n": [4, 4]},
    "twopad": {"n_pad": 2, "n_gap": 6, "n_outer": 3, "n_side": 3},
}
#: element layers of a ``[[layers]]`` table without ``elements``
LAYER_ELEMENTS_DEFAULT = 2


def _whole(v: Any, entry: str) -> int:
    if isinstance(v, float) and v.is_integer():
        v = int(v)
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise ModelError(entry, f"must be a whole number at least 1, got {v!r}")
    return v


def refined_spec(spec: Mapping[str, Any], factor: int) -> dict[str, Any]:
    """A deep copy of a model description with every element count multiplied by ``factor``.

    Args:
        spec: a model description (the mapping :func:`skinkit.fem.model.read_model` returns).
        factor: whole number >= 1; the element size ``h`` of the copy is ``h / factor``.

    Counts: disc ``n_inner``, ``n_ring``; block ``n = [nx, ny]``; twopad ``n_pad``,
    ``n_gap``, ``n_outer``, ``n_side``; every layer's ``elements``. An absent count takes the
    mesh builder's default (:data:`COUNT_DEFAULTS`) before being multiplied. Gradings are
    functions of the position along a segment, not of the count, so they are kept: the
    refined mesh resolves the same mapped geometry with ``factor`` times more elements.
    A count that is not a whole number >= 1 raises :class:`ModelError` naming the entry.
    """
    f = _whole(factor, "refinement factor")
    s = copy.deepcopy(dict(spec))
    g = s.get("geometry")
    if not isinstance(g, Mapping):
        raise ModelError("geometry", f"expected a table, got {g!r}")
    g = s["geometry"] = dict(g)
    kind = g.get("kind", "disc")
    if kind not in COUNT_DEFAULTS:
        raise ModelError("geometry.kind", f"must be 'disc', 'block' or 'twopad', got {kind!r}")
    for key, default in COUNT_DEFAULTS[kind].items():
        v = g.get(key, default)
        if key == "n":
            if not isinstance(v, (list, tuple)) or len(v) != 2:
                raise ModelError("geometry.n", f"expected [nx, ny] element counts, got {v!r}")
            g[key] = [_whole(x, f"geometry.n[{i}]") * f for i, x in enumerate(v)]
        else:
            g[key] = _whole(v, f"geometry.{key}") * f
    layers = s.get("layers")
    if not isinstance(layers, list) or not layers:
        raise ModelError("layers", "needs at least one [[layers]] table")
    out = []
    for i, L in enumerate(layers):
        if not isinstance(L, Mapping):
            raise ModelError(f"layers[{i}]", f"expected a table, got {L!r}")
        L = dict(L)
        L["elements"] = _whole(L.get("elements", LAYER_ELEMENTS_DEFAULT), f"layers[{i}].elements") * f
        out.append(L)
    s["layers"] = out
    return s


def _order_from_ratio(ratio: float, h: Sequence[float]) -> float:
    """``p`` with ``(h1^p - h2^p) / (h2^p - h3^p) = ratio`` (h1 > h2 > h3), NaN if none.

    For a constant refinement ratio ``r = h1/h2 = h2/h3`` this is ``log(ratio) / log(r)``;
    otherwise the (monotone in p) equation is solved by bisection on ``p`` in (0, 20]."""
    h1, h2, h3 = h
    if not (ratio > 0 and math.isfinite(ratio)):
        return math.nan
    if math.isclose(h1 / h2, h2 / h3, rel_tol=1e-12):
        return math.log(ratio) / math.log(h1 / h2)

    def g(p: float) -> float:
        return (h1 ** p - h2 ** p) / (h2 ** p - h3 ** p) - ratio

    lo, hi = 1e-6, 20.0
    if g(lo) * g(hi) > 0:
        return math.nan
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if g(lo) * g(mid) <= 0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def richardson(values: Sequence[float | np.ndarray], factors: Sequence[float],
               order: float | None = None) -> dict[str, Any]:
    """Richardson extrapolation of solutions on meshes refined by ``factors``.

    Args:
        values: the same quantity on each mesh, coarse to fine: scalars or arrays of one
            shape ``S`` (a tip-force history ``(steps, 3)`` [N], point positions
            ``(steps, M, 3)`` [m], ...).
        factors: refinement factor of each mesh (``h ∝ 1/factor``), strictly increasing,
            e.g. ``[1, 2, 3]``.
        order: the convergence order ``p`` to assume. Required with two levels; with three
            or more, None measures it from the last three (given, it is used instead).

    Returns:
        ``extrapolated`` (shape ``S``): ``v*`` from the two finest levels;
        ``observed_order`` (float): ``p`` measured from the last three levels (NaN with two
        levels, or when the differences do not shrink monotonically);
        ``order`` (float): the ``p`` used (observed or given);
        ``errors``: per level, ``|v_i - v*|`` (shape ``S``);
        ``monotone`` (bool): the last three levels converge monotonically (always True with
        two levels). An array quantity has one order, from the norms of the differences
        between levels (exact for ``v = v* + C h^p`` with an array ``C``), so components
        that hardly change do not spoil it.

        When the order cannot be measured (not monotone, or no change between the finest
        levels), ``extrapolated`` is the finest value and ``errors`` are
        ``|v_i - v_fine| + |v_fine - v_prev|``, a conservative bound rather than an
        extrapolation.
    """
    if len(values) != len(factors):
        raise ValueError(f"{len(values)} values for {len(factors)} refinement factors")
    if len(values) < 2:
        raise ValueError("Richardson extrapolation needs at least two refinement levels")
    fac = [float(f) for f in factors]
    if any(not (b > a > 0) for a, b in zip(fac, fac[1:], strict=False)):
        raise ValueError(f"refinement factors must be positive and increasing, got {list(factors)}")
    v = [np.asarray(x, dtype=float) for x in values]
    if any(x.shape != v[0].shape for x in v):
        raise ValueError(f"values must share one shape, got {[x.shape for x in v]}")
    if len(v) == 2 and order is None:
        raise ValueError("with two refinement levels the convergence order must be given (order=)")
    if order is not None and not (order > 0 and math.isfinite(order)):
        raise ValueError(f"order must be a positive number, got {order!r}")
    h = [1.0 / f for f in fac]
    observed, monotone = math.nan, True
    if len(v) >= 3:
        d1, d2 = v[-2] - v[-3], v[-1] - v[-2]
        n1, n2 = float(np.linalg.norm(d1)), float(np.linalg.norm(d2))
        # same direction of change between successive levels: monotone convergence
        monotone = float(np.sum(d1 * d2)) > 0
        if monotone and n2 > 0:
            observed = _order_from_ratio(n1 / n2, h[-3:])
    p = float(order) if order is not None else observed
    fine, prev = v[-1], v[-2]
    if math.isfinite(p) and p > 0:
        ext = fine + (fine - prev) / ((h[-2] / h[-1]) ** p - 1.0)
        errors = [np.abs(x - ext) for x in v]
    else:
        ext = fine.copy()
        spread = np.abs(fine - prev)
        errors = [np.abs(x - fine) + spread for x in v]
    scalar = v[0].ndim == 0

    def out(x: np.ndarray) -> float | np.ndarray:
        return float(x) if scalar else x

    return {"extrapolated": out(ext), "observed_order": observed, "order": p,
            "errors": [out(e) for e in errors], "monotone": bool(monotone)}
