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
from fractions import Fraction
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
#: a block with ``fit_indenter = true`` counts as a disc does
FITTED_BLOCK_COUNTS: dict[str, Any] = {"n_inner": 2, "n_ring": 2}
#: element layers of a ``[[layers]]`` table without ``elements``
LAYER_ELEMENTS_DEFAULT = 2


def _whole(v: Any, entry: str) -> int:
    if isinstance(v, float) and v.is_integer():
        v = int(v)
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise ModelError(entry, f"must be a whole number at least 1, got {v!r}")
    return v


def parse_factor(text: str | int | float | Fraction) -> Fraction:
    """A refinement factor: a whole number (``2``) or a fraction (``"1/2"``, ``"3/2"``, 0.5), > 0."""
    try:
        f = Fraction(str(text).strip()) if not isinstance(text, Fraction) else text
    except (ValueError, ZeroDivisionError):
        raise ModelError("refinement factor",
                         f"expected a number or a fraction like 1/2, got {text!r}") from None
    if not f > 0:
        raise ModelError("refinement factor", f"must be positive, got {text!r}")
    return f


def _scaled(v: Any, f: Fraction, entry: str) -> int:
    n = _whole(v, entry) * f
    if n.denominator != 1:
        raise ModelError(entry, f"{v} elements cannot be scaled by {f} (not a whole number): "
                         "coarsen only meshes whose counts the factor divides")
    return int(n)


def refined_spec(spec: Mapping[str, Any], factor: int | Fraction | str) -> dict[str, Any]:
    """A deep copy of a model description with every element count multiplied by ``factor``.

    Args:
        spec: a model description (the mapping :func:`skinkit.fem.model.read_model` returns).
        factor: a whole number >= 1, or a fraction (``Fraction(1, 2)``, ``"1/2"``: a coarsened
            copy; every count times it must be a whole number >= 1); the element size ``h``
            of the copy is ``h / factor``.

    Counts: disc ``n_inner``, ``n_ring``; block ``n = [nx, ny]``; twopad ``n_pad``,
    ``n_gap``, ``n_outer``, ``n_side``; every layer's ``elements``. An absent count takes the
    mesh builder's default (:data:`COUNT_DEFAULTS`) before being multiplied. Gradings are
    functions of the position along a segment, not of the count, so they are kept: the
    refined mesh resolves the same mapped geometry with ``factor`` times more elements.
    A count that is not a whole number >= 1 raises :class:`ModelError` naming the entry.
    """
    f = parse_factor(factor)
    s = copy.deepcopy(dict(spec))
    g = s.get("geometry")
    if not isinstance(g, Mapping):
        raise ModelError("geometry", f"expected a table, got {g!r}")
    g = s["geometry"] = dict(g)
    kind = g.get("kind", "disc")
    if kind not in COUNT_DEFAULTS:
        raise ModelError("geometry.kind", f"must be 'disc', 'block' or 'twopad', got {kind!r}")
    counts = COUNT_DEFAULTS[kind]
    if kind == "block" and g.get("fit_indenter") is True:
        counts = FITTED_BLOCK_COUNTS
    for key, default in counts.items():
        v = g.get(key, default)
        if key == "n":
            if not isinstance(v, (list, tuple)) or len(v) != 2:
                raise ModelError("geometry.n", f"expected [nx, ny] element counts, got {v!r}")
            g[key] = [_scaled(x, f, f"geometry.n[{i}]") for i, x in enumerate(v)]
        else:
            g[key] = _scaled(v, f, f"geometry.{key}")
    layers = s.get("layers")
    if not isinstance(layers, list) or not layers:
        raise ModelError("layers", "needs at least one [[layers]] table")
    out = []
    for i, L in enumerate(layers):
        if not isinstance(L, Mapping):
            raise ModelError(f"layers[{i}]", f"expected a table, got {L!r}")
        L = dict(L)
        L["elements"] = _scaled(L.get("elements", LAYER_ELEMENTS_DEFAULT), f, f"layers[{i}].elements")
        out.append(L)
    s["layers"] = out
    return s


#: every key of ``[geometry]`` that shapes the mesh (counts, gradings, layouts), per kind,
#: with the builder's default (skinkit.fem.model._mesh, skinkit.fem.twopad.twopad_from_spec)
MESH_KEYS: dict[str, dict[str, Any]] = {
    "disc": {"n_inner": 3, "n_ring": 3, "grading": 1.6, "inner_grading": 1.0, "layer_grading": 1.0,
             "o_grid": False},
    "block": {"n": [4, 4], "layer_grading": 1.0, "fit_indenter": False},
    "block_fitted": {"n_inner": 2, "n_ring": 2, "grading": 1.0, "inner_grading": 1.0,
                     "layer_grading": 1.0, "fit_indenter": True},
    "twopad": {"n_pad": 2, "n_gap": 6, "n_outer": 3, "n_side": 3, "grading": 1.6, "pad_grading": 1.0,
               "layer_grading": 1.0},
}


def pin_mesh(spec: Mapping[str, Any], elements: Sequence[int], **geometry: Any) -> dict[str, Any]:
    """A deep copy of a model description whose mesh is set explicitly, whatever the file says.

    For a consumer that needs a given mesh (a benchmark, the virtual lab's truth, a test
    that must stay fast and reproducible) and must not follow a change of an example file's
    mesh: every mesh-shaping key of the geometry's kind (:data:`MESH_KEYS`) is written,
    ``geometry``'s value where given and the builder's default otherwise, and layer ``i``
    gets ``elements[i]`` element layers.

    Args:
        spec: a model description (:func:`skinkit.fem.model.read_model`).
        elements: element layers of each ``[[layers]]`` table, top down.
        **geometry: mesh keys of the kind (``n_inner=1, n_ring=2, grading=1.6``, ...);
            a key of another kind raises :class:`ModelError`.
    """
    s = copy.deepcopy(dict(spec))
    g = dict(s.get("geometry", {}))
    kind = g.get("kind", "disc")
    if kind == "block" and geometry.get("fit_indenter", False):
        kind = "block_fitted"
    keys = MESH_KEYS.get(kind)
    if keys is None:
        raise ModelError("geometry.kind", f"must be 'disc', 'block' or 'twopad', got {kind!r}")
    bad = sorted(set(geometry) - set(keys))
    if bad:
        raise ModelError(f"geometry.{bad[0]}", f"not a mesh key of kind {g.get('kind', 'disc')!r}; "
                         f"they are {sorted(keys)}")
    for group in MESH_KEYS.values():
        for k in group:
            if k not in ("kind",):
                g.pop(k, None)
    g.update({k: copy.deepcopy(geometry.get(k, v)) for k, v in keys.items()})
    s["geometry"] = g
    layers = s.get("layers")
    if not isinstance(layers, list) or len(layers) != len(elements):
        raise ModelError("layers", f"{len(elements)} element counts given for "
                         f"{len(layers) if isinstance(layers, list) else 0} layers")
    s["layers"] = [dict(L, elements=int(e)) for L, e in zip(layers, elements, strict=True)]
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


#: convergence order assumed when only two refinement levels are solved: the lowest order a
#: bonded probe's edge gives on these meshes (the issue's study measured 1.3 with uniform
#: refinement), so the estimate errs on the large side
ASSUMED_ORDER = 1.0


def _history(info: Mapping[str, Any], key: str) -> np.ndarray | None:
    """``(steps, 3)`` history of a summary's per-step vector ``key`` (None entries -> NaN)."""
    rows = [st.get(key) for st in info["steps"]]
    if any(r is None for r in rows):
        return None
    return np.array([[np.nan if x is None else x for x in r] for r in rows], dtype=float)


def _points(info: Mapping[str, Any]) -> np.ndarray | None:
    rows = [st.get("points_m") for st in info["steps"]]
    return None if any(r is None for r in rows) else np.array(rows, dtype=float)


def _nan_none(x: Any) -> Any:
    if isinstance(x, float):
        return None if not math.isfinite(x) else x
    if isinstance(x, np.ndarray):
        return [_nan_none(v) for v in x.tolist()] if x.ndim else _nan_none(float(x))
    if isinstance(x, list):
        return [_nan_none(v) for v in x]
    return x


def estimate(infos: Sequence[Mapping[str, Any]], factors: Sequence[int], order: float | None = None
             ) -> dict[str, Any]:
    """Discretisation error of a solve's reported quantities from its refined repeats.

    Args:
        infos: the JSON summaries (:func:`skinkit.fem.run.solve_model`) of the same model on
            meshes refined by ``factors`` (coarse to fine), same load steps.
        factors: refinement factors, e.g. ``[1, 2]`` or ``[1, 2, 3]``.
        order: convergence order to assume; None: measured with three or more levels,
            :data:`ASSUMED_ORDER` with two.

    Returns:
        ``factors``, ``dof`` (per level), and for each of ``tip_force_N``,
        ``tip_displacement_m`` (``(steps, 3)`` histories [N], [m]) and ``points_m``
        (``(steps, M, 3)`` [m], when points are tracked):

        - ``extrapolated``: the Richardson value (same shape);
        - ``estimated_error``: per level, ``|v - v*|`` (same shape; for points the length of
          the position error, ``(steps, M)`` [m]);
        - ``relative_error`` (tip quantities): per level, the largest error over the steps
          divided by the largest magnitude of the extrapolated history (0 for a prescribed
          quantity), or ``max_error_m`` (points): per level, the largest position error [m];
        - ``observed_order`` (None unless measured), ``order`` (the one used), ``order_assumed``.
    """
    out: dict[str, Any] = {"method": "richardson", "factors": [int(f) for f in factors],
                           "dof": [int(i["dof"]) for i in infos]}
    assumed = order is None and len(infos) < 3
    p = ASSUMED_ORDER if assumed else order
    for key in ("tip_force_N", "tip_displacement_m", "points_m"):
        vals = [_points(i) if key == "points_m" else _history(i, key) for i in infos]
        if any(v is None for v in vals):
            continue
        r = richardson(vals, factors, p)
        ext = np.asarray(r["extrapolated"])
        q: dict[str, Any] = {"extrapolated": _nan_none(ext),
                             "observed_order": _nan_none(r["observed_order"]),
                             "order": _nan_none(r["order"]), "order_assumed": bool(assumed)}
        if key == "points_m":
            errs = [np.linalg.norm(e, axis=-1) for e in r["errors"]]
            q["estimated_error"] = [_nan_none(e) for e in errs]
            q["max_error_m"] = [float(np.nanmax(e)) if e.size else 0.0 for e in errs]
        else:
            errs = [np.linalg.norm(e, axis=-1) for e in r["errors"]]
            scale = float(np.nanmax(np.linalg.norm(ext, axis=-1)))
            q["estimated_error"] = [_nan_none(e) for e in r["errors"]]
            q["relative_error"] = [float(np.nanmax(e)) / scale if scale > 0 else 0.0 for e in errs]
        out[key] = q
    return out


def meets(est: Mapping[str, Any], level: int, tolerance: float | None, point_tolerance: float | None,
          quantity: str) -> bool:
    """Whether level ``level`` (index into ``est["factors"]``) of :func:`estimate` meets the
    relative ``tolerance`` on ``quantity`` (``"tip_force_N"`` or ``"tip_displacement_m"``)
    and the ``point_tolerance`` [m] on tracked points (None: not asked)."""
    ok = True
    if tolerance is not None:
        ok &= est[quantity]["relative_error"][level] <= tolerance
    if point_tolerance is not None and "points_m" in est:
        ok &= est["points_m"]["max_error_m"][level] <= point_tolerance
    return bool(ok)
