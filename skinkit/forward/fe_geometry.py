"""Geometry parameters of the FE forward model: their design velocities and point terms.

An effect declares in ``geometry`` the parameters that only move the mesh's nodes (a layer's
thickness); the forward model differentiates them by the shape derivative
(:mod:`skinkit.fem.shape`) instead of central differences of whole solves. What that needs
besides the solve is geometry:

* the design velocity ``V = dX/dp`` of every node (and of every node's depth, which fields by
  depth read): read off the meshes the model builds — fitted to the session's surface when
  it is — at neighbouring values of p. Node positions are piecewise linear in the layer
  thicknesses, so the difference is exact to rounding (~1e-9 relative); on a fitted mesh the
  deeper nodes' share of the surface's offset is smooth in them, and the central
  difference's error ~(step / thickness)² stays below 1e-9;
* the tracked points' reference positions' velocity ``dX_pt/dp``: they are located anew on
  each of those meshes (on the top surface, then ``point_depth`` below it), as a solve would;
* a distributed support's spring stiffnesses (face areas over the compliance): from the
  model built on the mesh moved by ±h V.

Nothing here solves the model.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

#: step of the design velocity's differences, as a share of the parameter's scale (its value,
#: or 1 % of its range at 0): far below any element's size, far above rounding
GEOMETRY_STEP = 1e-4


@dataclass
class GeometryDesign:
    """One geometry parameter's design velocity, per unit of it.

    Attributes:
        nodes: ``(N, 3)`` dX/dp of the mesh's nodes [m per unit].
        depth: ``(N,)`` d(depth)/dp of the nodes [m per unit].
        points: protocol -> ``(P, 3)`` dX_pt/dp of its tracked points' reference positions, in
            the order of the protocol's embedding [m per unit].
    """

    nodes: np.ndarray
    depth: np.ndarray
    points: dict[str, np.ndarray]


def geometry_parameters(effects: Sequence[Any]) -> set[str]:
    """Model names ``"<effect>.<local>"`` of the parameters effects declare in ``geometry``."""
    return {f"{e.name}.{k}" for e in effects for k in getattr(e.plugin, "geometry", ()) if k in e.declared}


def stencil(p: Any) -> tuple[list[tuple[float, float]], float]:
    """``([(coefficient, value), ...], h)``: ``dX/dp ≈ Σ coefficient X(value)`` for parameter ``p``
    (a :class:`skinkit.schemas.Parameter`): central with step h inside the bounds, the
    second-order one-sided formula into the admissible range at a bound."""
    scale = abs(p.value) if p.value != 0 else (
        0.01 * (p.upper - p.lower) if math.isfinite(p.upper - p.lower) else 1.0)
    h = GEOMETRY_STEP * max(scale, 1e-12)
    if p.value - h >= p.lower and p.value + h <= p.upper:
        return [(0.5 / h, p.value + h), (-0.5 / h, p.value - h)], h
    s = 1.0 if p.value - h < p.lower else -1.0
    return [(-1.5 * s / h, p.value), (2.0 * s / h, p.value + s * h), (-0.5 * s / h, p.value + 2 * s * h)], h


def layout(model: Any, params: Any, observations: Any, inst_names: Sequence[str]):
    """``(mesh, {protocol: (P, 3)})``: the FE forward ``model``'s mesh at ``params`` (fitted as a
    solve's) and each protocol's tracked points located in it, at their reference positions [m],
    in the order of the protocol's embedding (``FEForwardModel._solve_all``)."""
    from skinkit.fem.embed import located
    from skinkit.forward import instrument as inst_mod

    spec = model.description(params)
    mesh, _, depth = model._surface(spec, observations)
    entries = inst_mod.parse(spec.get("instrument"))
    points = {}
    for po in observations:
        parts = [located(mesh, *model._embed_channel(mesh, c, depth, f"session protocol {po.name!r}.{c.name}",
                                                     entries, inst_names)[0])
                 for c in po.channels.values() if c.is_points]
        points[po.name] = np.concatenate(parts) if parts else np.zeros((0, 3))
    return mesh, points


def _depth(mesh: Any) -> np.ndarray:
    return mesh.depth if mesh.depth is not None else mesh.nodes[:, 2].max() - mesh.nodes[:, 2]


def design(build: Any, name: str, value_of: Any, base: Any) -> GeometryDesign:
    """The design velocity of geometry parameter ``name`` at ``value_of`` (a ParameterSet).

    ``build(params) -> (mesh, {protocol: (P, 3) tracked points' reference positions})`` builds
    the model's mesh and locates the points at parameters ``params`` (:func:`layout`); ``base``
    is that mesh at ``value_of`` (the topology every neighbour must share)."""
    from skinkit.errors import ForwardError

    p = value_of.param(name)
    weights, _ = stencil(p)
    nodes = np.zeros_like(base.nodes)
    depth = np.zeros(base.n_nodes)
    points: dict[str, np.ndarray] = {}
    for c, v in weights:
        mesh, pts = build(value_of.with_values({name: v}))
        if mesh.nodes.shape != base.nodes.shape or not np.array_equal(mesh.elements, base.elements):
            raise ForwardError(name, "declared a geometry parameter but changes the mesh's topology")
        nodes += c * mesh.nodes
        depth += c * _depth(mesh)
        for proto, x in pts.items():
            points[proto] = points.get(proto, 0.0) + c * x
    return GeometryDesign(nodes, depth, points)


def velocities(spec: Mapping[str, Any], mesh: Any, shapes: Mapping[str, tuple[np.ndarray, np.ndarray]],
               model: Any) -> dict[str, Any]:
    """The solver's design velocities (:class:`skinkit.fem.shape.DesignVelocity`) of a job's
    geometry parameters ``shapes`` (name -> ``(nodes (N, 3), depth (N,))`` velocities) on the
    job's ``mesh`` and built ``model``: with a distributed support, its springs' stiffness
    derivative from the models built on the mesh moved by ±h V (h V at most 1e-7 of the mesh)."""
    from skinkit.fem.model import build_model
    from skinkit.fem.shape import DesignVelocity

    springs = bool(model.bc.springs)
    out = {}
    for nm, (V, Vd) in shapes.items():
        dk = None
        if springs:
            h = 1e-7 * float(np.ptp(mesh.nodes, axis=0).max()) / max(float(np.abs(V).max()), 1e-300)
            ks = [build_model(spec, require_load=False, mesh=mesh.with_nodes(mesh.nodes + s * h * V))
                  .bc.compile().spring_k for s in (1.0, -1.0)]
            dk = (ks[0] - ks[1]) / (2 * h)
        out[nm] = DesignVelocity(np.asarray(V, float), np.asarray(Vd, float), dk)
    return out


def add_point_terms(d_pts: np.ndarray, cols: Sequence[str], shape_points: Mapping[str, np.ndarray],
                    shapes: Mapping[str, Any], emb: Any, X: np.ndarray, us: Sequence[np.ndarray]) -> None:
    """Add the geometric part of the tracked points' derivatives to ``d_pts`` ``(n, P, 3, n_par)``
    (in place; row 0 the unloaded state, row i + 1 at displacement ``us[i]``): for each geometry
    parameter in ``cols``, the points' reference motion and the displacement field read at
    moved local coordinates (:meth:`skinkit.fem.embed.Embedding.moved`)."""
    for j, nm in enumerate(cols):
        if nm not in shapes:
            continue
        V, dX = shapes[nm].nodes, shape_points[nm]
        d_pts[0, :, :, j] += dX
        for i, u in enumerate(us):
            d_pts[i + 1, :, :, j] += emb.moved(X, u, V, dX)


__all__ = ["GEOMETRY_STEP", "GeometryDesign", "add_point_terms", "design", "geometry_parameters", "layout",
           "stencil", "velocities"]
