"""The two-pad extension geometry: a layered block of skin with two rigid pads glued on top.

An extensometer (e.g. Jacquet et al.'s ultra-light device) glues two square pads on the
skin, holds one and pulls the other along the line joining them. The model is a
rectangular block ``[-Lx/2, Lx/2] x [-Ly/2, Ly/2] x [-H, 0]`` (skin frame: x along the pull,
y in-plane, z out of the skin, origin on the surface midway between the pads) of 27-node
hexahedra in layers from the top down, like :func:`skinkit.fem.mesh.block_mesh`. The fixed
pad is centred at ``x = -(gap + pad)/2``, the moving pad at ``x = +(gap + pad)/2``, both at
``y = 0``; every pad edge lies on element boundaries, and the in-plane element size grows
from the pads towards the far sides (power-law grading, as :func:`skinkit.fem.mesh.disc_mesh`
grades its rings).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from skfem import MeshHex

from skinkit.fem.errors import ModelError
from skinkit.fem.mesh import FEMesh, _from_linear, _layer_coords, _near, _region_by_z

#: default layers (name, thickness [m], element layers), top down
DEFAULT_LAYERS: tuple[tuple[str, float, int], ...] = (("skin", 0.0015, 2), ("subdermal", 0.0035, 2))

#: default side of the square pads [m] and distance between their facing edges [m]
PAD_SIZE, GAP = 0.008, 0.032

_KEYS = {"kind", "size", "pad_size", "gap", "n_pad", "n_gap", "n_outer", "n_side", "grading",
         "pad_grading", "layer_grading"}


def _graded(a: float, b: float, n: int, grading: float, fine: str) -> np.ndarray:
    """``n + 1`` element boundaries from ``a`` to ``b``, finer at ``fine`` (``"a"``, ``"b"``,
    ``"both"`` or ``"none"``); spacing grows as a power ``grading`` of the distance."""
    s = np.linspace(0.0, 1.0, n + 1)
    if fine == "a":
        w = s ** grading
    elif fine == "b":
        w = 1.0 - (1.0 - s) ** grading
    elif fine == "both":
        # symmetric: each half graded from its end towards the middle
        t = 2.0 * s - 1.0
        w = 0.5 * (1.0 + np.sign(t) * (1.0 - (1.0 - np.abs(t)) ** grading))
    else:
        w = s
    return a + (b - a) * w


def _axis(breaks: Sequence[float], counts: Sequence[int], fines: Sequence[str], grading: float,
          pad_grading: float = 1.0) -> np.ndarray:
    # each segment without its end point, then the last break: every break appears exactly once
    # (a + (b - a) * 1 may differ from b by rounding, which would make a sliver element);
    # "edges" is a pad: finer at both ends by pad_grading (uniform at 1, as before)
    parts = [(_graded(breaks[i], breaks[i + 1], counts[i], pad_grading, "both") if fines[i] == "edges"
              else _graded(breaks[i], breaks[i + 1], counts[i], grading, fines[i]))[:-1]
             for i in range(len(counts))]
    return np.concatenate(parts + [[breaks[-1]]])


def twopad_mesh(size: Sequence[float] = (0.100, 0.050), pad_size: float = PAD_SIZE, gap: float = GAP,
                layers: Sequence[tuple[str, float, int]] = DEFAULT_LAYERS, n_pad: int = 2, n_gap: int = 6,
                n_outer: int = 3, n_side: int = 3, grading: float = 1.6, pad_grading: float = 1.0,
                layer_grading: float = 1.0) -> FEMesh:
    """The two-pad extension geometry (module docstring).

    Args:
        size: in-plane extent ``[Lx, Ly]`` [m] of the modelled region (default 100 x 50 mm).
        pad_size: side of the square pads [m] (8 mm).
        gap: initial distance between the pads' facing edges along x [m] (32 mm).
        layers: ``(name, thickness [m], element layers)`` from the top (z = 0) down.
        n_pad: elements across a pad, in x and in y.
        n_gap: elements along x between the pads (graded finer towards both pads).
        n_outer: elements along x from a pad to the far side (graded finer at the pad).
        n_side: elements along y from the pads' band to each far side (finer at the band).
        grading: spacing exponent >= 1 (1: uniform); a segment of ``n`` elements has
            boundaries at ``(k/n)^grading`` of its length from its fine end.
        pad_grading: exponent >= 1 grading the elements across each pad towards the pad's
            edges (where the bonded pad makes the stress singular); 1: uniform.
        layer_grading: exponent >= 1 grading each layer's elements towards its top; 1: uniform.

    Returns:
        A :class:`FEMesh` with regions named after ``layers`` and node sets ``top``,
        ``bottom``, ``xmin``, ``xmax``, ``ymin``, ``ymax``, ``sides``, ``pad_fixed`` (top
        nodes under the fixed pad), ``pad_moving`` and ``indenter`` (the same: top nodes
        under the moving pad, the engine's rigid region). With the defaults and 2 + 2
        element layers: 16 x 8 x 4 elements, 5,049 nodes.
    """
    Lx, Ly = (float(v) for v in size)
    a, g = float(pad_size), float(gap)
    if min(Lx, Ly, a, g) <= 0:
        raise ModelError("geometry", f"size {tuple(size)}, pad_size {a} and gap {g} must be positive")
    if g + 2 * a >= Lx:
        raise ModelError("geometry.size", f"Lx = {Lx} m must exceed gap + 2 pads = {g + 2 * a} m")
    if a >= Ly:
        raise ModelError("geometry.size", f"Ly = {Ly} m must exceed the pad size {a} m")
    for key, gv in (("grading", grading), ("pad_grading", pad_grading), ("layer_grading", layer_grading)):
        if not gv >= 1:
            raise ModelError(f"geometry.{key}", f"must be at least 1 (1 is uniform), got {gv}")
    for key, n in (("n_pad", n_pad), ("n_gap", n_gap), ("n_outer", n_outer), ("n_side", n_side)):
        if int(n) != n or n < 1:
            raise ModelError(f"geometry.{key}", f"must be a whole number at least 1, got {n}")
    if not layers:
        raise ModelError("layers", "needs at least one [[layers]] table")
    h, e = 0.5 * g, 0.5 * g + a
    # the pads' segments are graded towards both their edges ("edges"), the others by grading
    xs = _axis([-0.5 * Lx, -e, -h, h, e, 0.5 * Lx], [n_outer, n_pad, n_gap, n_pad, n_outer],
               ["b", "edges", "both", "edges", "a"], grading, pad_grading)
    ys = _axis([-0.5 * Ly, -0.5 * a, 0.5 * a, 0.5 * Ly], [n_side, n_pad, n_side], ["b", "edges", "a"],
               grading, pad_grading)
    z = _layer_coords([t for _, t, _ in layers], [k for _, _, k in layers], layer_grading)
    nodes, t, el = _from_linear(MeshHex.init_tensor(xs, ys, z))
    ifaces = list(np.cumsum([-th for _, th, _ in layers])[:-1])
    region = _region_by_z(nodes, el, ifaces)
    H = float(sum(th for _, th, _ in layers))
    x, y, zz = nodes.T
    L = max(Lx, Ly)
    top = _near(zz, 0.0, L)
    # a node is under a pad when inside its square footprint (edges included: they are mesh lines)
    tol = 1e-9 * L
    in_band = np.abs(y) <= 0.5 * a + tol
    sets = {"top": top, "bottom": _near(zz, -H, L),
            "xmin": _near(x, -0.5 * Lx, L), "xmax": _near(x, 0.5 * Lx, L),
            "ymin": _near(y, -0.5 * Ly, L), "ymax": _near(y, 0.5 * Ly, L),
            "pad_fixed": top & in_band & (x >= -e - tol) & (x <= -h + tol),
            "pad_moving": top & in_band & (x >= h - tol) & (x <= e + tol)}
    sets["sides"] = sets["xmin"] | sets["xmax"] | sets["ymin"] | sets["ymax"]
    sets["indenter"] = sets["pad_moving"]
    return FEMesh(nodes, t, el, region, [nm for nm, _, _ in layers],
                  {k: np.flatnonzero(v) for k, v in sets.items()})


def _count(g: Mapping[str, Any], key: str, default: int) -> int:
    v = g.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise ModelError(f"geometry.{key}", f"must be a whole number at least 1, got {v!r}")
    return v


def twopad_from_spec(g: Mapping[str, Any], layers: Sequence[tuple[str, float, int]]) -> FEMesh:
    """The mesh of a ``[geometry] kind = "twopad"`` table.

    Keys (all optional): ``size = [Lx, Ly]`` (100 mm, 50 mm), ``pad_size`` (8 mm), ``gap``
    (32 mm), ``n_pad`` (2), ``n_gap`` (6), ``n_outer`` (3), ``n_side`` (3), ``grading``
    (1.6), ``pad_grading`` (1), ``layer_grading`` (1); see :func:`twopad_mesh`. ``layers``:
    ``(name, thickness [m], element layers)`` top down. An unknown key or a bad value raises
    :class:`ModelError` naming ``geometry.<key>``.
    """
    from skinkit.fem.values import quantity, vector

    extra = sorted(set(g) - _KEYS)
    if extra:
        raise ModelError(f"geometry.{extra[0]}",
                         f"unknown key for kind 'twopad'; allowed are {sorted(_KEYS)}")
    from skinkit.fem.values import grading as _grading

    size = vector(g.get("size", [0.100, 0.050]), "m", "geometry.size", 2)
    for key in ("grading", "pad_grading", "layer_grading"):
        v = g.get(key, 1.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ModelError(f"geometry.{key}", f"must be a number at least 1, got {v!r}")
    return twopad_mesh(size, quantity(g.get("pad_size", PAD_SIZE), "m", "geometry.pad_size"),
                       quantity(g.get("gap", GAP), "m", "geometry.gap"), layers,
                       _count(g, "n_pad", 2), _count(g, "n_gap", 6), _count(g, "n_outer", 3),
                       _count(g, "n_side", 3), _grading(g, "grading", 1.6), _grading(g, "pad_grading"),
                       _grading(g, "layer_grading"))
