"""27-node hexahedral meshes (scikit-fem ``MeshHex2``): blocks, phantoms, the in vivo disc.

A :class:`FEMesh` holds every node of the quadratic mesh (vertices, edge, face and centre
nodes, in scikit-fem's ``MeshHex2.doflocs`` order) so that moving any node (fitting to a
surface) keeps the isoparametric, possibly curved, geometry. Lengths are in metres.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from skfem import MeshHex, MeshHex2

from skinkit.fem.errors import ModelError


@dataclass
class FEMesh:
    """A quadratic hexahedral mesh with named regions and node sets.

    Attributes:
        nodes: ``(N, 3)`` node coordinates [m].
        t: ``(8, n_el)`` vertex connectivity of the underlying linear mesh (scikit-fem order).
        elements: ``(n_el, 27)`` node indices of each element (scikit-fem ``ElementHex2`` order).
        region: ``(n_el,)`` region index of each element (into ``regions``).
        regions: region names, e.g. ``["skin", "subdermal"]``.
        node_sets: name -> sorted node indices (``"top"``, ``"bottom"``, ``"outer"``, ...).
    """

    nodes: np.ndarray
    t: np.ndarray
    elements: np.ndarray
    region: np.ndarray
    regions: list[str]
    node_sets: dict[str, np.ndarray] = field(default_factory=dict)
    #: ``(N,)`` depth of each node below the top surface [m] in the unfitted mesh, kept when
    #: the mesh is fitted to a measured surface (fields by depth follow the layers); None: from z
    depth: np.ndarray | None = None

    @property
    def n_nodes(self) -> int:
        """Number of nodes."""
        return int(self.nodes.shape[0])

    @property
    def n_elements(self) -> int:
        """Number of elements."""
        return int(self.elements.shape[0])

    @property
    def n_dof(self) -> int:
        """Number of degrees of freedom (3 per node)."""
        return 3 * self.n_nodes

    def skfem_mesh(self) -> MeshHex2:
        """The scikit-fem ``MeshHex2`` with the current node positions."""
        return MeshHex2(doflocs=np.ascontiguousarray(self.nodes.T), t=self.t, validate=False)

    def with_nodes(self, nodes: np.ndarray) -> FEMesh:
        """A copy with node positions replaced (same topology)."""
        nodes = np.asarray(nodes, dtype=float)
        if nodes.shape != self.nodes.shape:
            raise ModelError("mesh.nodes", f"expected shape {self.nodes.shape}, got {nodes.shape}")
        depth = self.depth if self.depth is not None else self.nodes[:, 2].max() - self.nodes[:, 2]
        return FEMesh(nodes, self.t, self.elements, self.region, list(self.regions),
                      {k: v.copy() for k, v in self.node_sets.items()}, depth.copy())

    def region_elements(self, name: str) -> np.ndarray:
        """Indices of the elements of region ``name``."""
        if name not in self.regions:
            raise ModelError("region", f"no region {name!r}; regions are {self.regions}")
        return np.flatnonzero(self.region == self.regions.index(name))


def _from_linear(m: MeshHex) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    m2 = MeshHex2.from_mesh(m)
    from skfem import Basis, ElementHex2
    # a basis of intorder 1 is the cheapest way to get the element -> node table
    b = Basis(m2, ElementHex2(), intorder=1)
    return np.ascontiguousarray(m2.doflocs.T), m.t, np.ascontiguousarray(b.element_dofs.T)


def _region_by_z(nodes: np.ndarray, elements: np.ndarray, z_interfaces: Sequence[float]) -> np.ndarray:
    """Region index of each element from its centroid height: 0 is the top layer."""
    zc = nodes[elements, 2].mean(axis=1)
    # interfaces are listed top-down; an element below k interfaces is in layer k
    return np.sum(zc[:, None] < np.asarray(z_interfaces)[None, :], axis=1)


def _check_rings(n_inner: int, n_ring: int, grading: float, inner_grading: float) -> None:
    """The counts and gradings shared by the disc and the punch-fitted block."""
    for key, gv in (("grading", grading), ("inner_grading", inner_grading)):
        if not gv >= 1:
            raise ModelError(f"geometry.{key}", f"must be at least 1 (1 is uniform), got {gv}")
    for key, v in (("n_inner", n_inner), ("n_ring", n_ring)):
        if int(v) != v or v < 1:
            raise ModelError(f"geometry.{key}", f"must be a whole number at least 1, got {v}")


def _near(a: np.ndarray, b: float, scale: float) -> np.ndarray:
    return np.abs(a - b) <= 1e-9 * max(scale, 1e-12)


def _layer_coords(thicknesses: Sequence[float], n_layers: Sequence[int], grading: float = 1.0) -> np.ndarray:
    """z coordinates of element boundaries, top (z = 0) down, returned ascending.

    ``grading`` >= 1: within each layer the k-th of n boundaries lies ``t (k/n)^grading``
    below the layer's top, so elements are thinnest at the top of each layer (the surface,
    where a bonded probe's edge concentrates the stress); 1 is uniform."""
    if not grading >= 1:
        raise ModelError("geometry.layer_grading", f"must be at least 1 (1 is uniform), got {grading}")
    zs = [0.0]
    if not len(thicknesses):
        raise ModelError("layers", "needs at least one [[layers]] table")
    # entries are named as in a model file (layers[i].thickness), where these values come from
    for i, (t, n) in enumerate(zip(thicknesses, n_layers, strict=True)):
        if not t > 0:
            raise ModelError(f"layers[{i}].thickness", f"must be positive, got {t} m")
        if int(n) != n or n < 1:
            raise ModelError(f"layers[{i}].elements", f"must be a whole number at least 1, got {n}")
        zs.extend(list(zs[-1] - t * (np.arange(1, n + 1) / n) ** grading))
    return np.array(sorted(zs))


def block_mesh(size: Sequence[float] = (1.0, 1.0, 1.0), n: Sequence[int] = (2, 2, 2),
               layers: Sequence[tuple[str, float, int]] | None = None,
               layer_grading: float = 1.0) -> FEMesh:
    """A box ``[0, Lx] x [0, Ly] x [-Lz, 0]`` of 27-node hexahedra (top face at z = 0).

    ``n`` elements per direction; ``layers`` optionally splits it through the thickness as
    ``(name, thickness [m], element layers)`` from the top (thicknesses must sum to ``Lz``),
    each layer's elements graded towards its top by ``layer_grading`` (1: uniform).
    Node sets: ``top``, ``bottom``, ``xmin``, ``xmax``, ``ymin``, ``ymax``, ``sides``.
    """
    Lx, Ly, Lz = (float(v) for v in size)
    if min(Lx, Ly) <= 0:
        raise ModelError("geometry.size", f"must be positive, got {list(size[:2])} m")
    if Lz <= 0:
        raise ModelError("layers", f"the thicknesses must add up to a positive height, got {Lz} m")
    if min(n) < 1:
        raise ModelError("geometry.n", f"element counts must be at least 1, got {list(n)}")
    if layers:
        tot = sum(t for _, t, _ in layers)
        if abs(tot - Lz) > 1e-9 * Lz:
            raise ModelError("layers", f"layer thicknesses sum to {tot} m, not the block's height {Lz} m")
        z = _layer_coords([t for _, t, _ in layers], [k for _, _, k in layers], layer_grading)
        names = [nm for nm, _, _ in layers]
    else:
        z = np.linspace(-Lz, 0.0, n[2] + 1)
        names = ["body"]
    m = MeshHex.init_tensor(np.linspace(0, Lx, n[0] + 1), np.linspace(0, Ly, n[1] + 1), z)
    nodes, t, el = _from_linear(m)
    if layers:
        ifaces = list(np.cumsum([-th for _, th, _ in layers])[:-1])
        region = _region_by_z(nodes, el, ifaces)
    else:
        region = np.zeros(el.shape[0], dtype=int)
    x, y, zz = nodes.T
    L = max(Lx, Ly, Lz)
    sets = {"top": _near(zz, 0.0, L), "bottom": _near(zz, -Lz, L),
            "xmin": _near(x, 0.0, L), "xmax": _near(x, Lx, L),
            "ymin": _near(y, 0.0, L), "ymax": _near(y, Ly, L)}
    sets["sides"] = sets["xmin"] | sets["xmax"] | sets["ymin"] | sets["ymax"]
    return FEMesh(nodes, t, el, region, names, {k: np.flatnonzero(v) for k, v in sets.items()})


def _o_grid(n_inner: int, n_ring: int, z: np.ndarray) -> MeshHex:
    """The disc's logical mesh as an O-grid: the central ``n_inner`` x ``n_inner`` block of
    the square ``[-rho_c, rho_c]^2`` (``rho_c = n_inner / (n_inner + 2 n_ring)``, as in the
    full grid, so :func:`disc_mesh`'s mapping applies unchanged) and ``n_ring`` rings, each
    between concentric squares carrying the block boundary's ``4 n_inner`` nodes, scaled;
    extruded through the heights ``z`` (ascending). Elements are right-handed like
    ``MeshHex.init_tensor``'s."""
    rho_c = n_inner / (n_inner + 2 * n_ring)
    s = np.linspace(-rho_c, rho_c, n_inner + 1)
    U, V = np.meshgrid(s, s, indexing="ij")                 # node (i, j) is i * (n_inner+1) + j
    pts = [np.column_stack([U.ravel(), V.ravel()])]
    m1 = n_inner + 1
    quads = [(i * m1 + j, (i + 1) * m1 + j, (i + 1) * m1 + j + 1, i * m1 + j + 1)
             for i in range(n_inner) for j in range(n_inner)]
    # the block's boundary counter-clockwise from (-rho_c, -rho_c): 4 n_inner nodes
    ij = ([(i, 0) for i in range(n_inner)] + [(n_inner, j) for j in range(n_inner)]
          + [(i, n_inner) for i in range(n_inner, 0, -1)] + [(0, j) for j in range(n_inner, 0, -1)])
    loop = np.array([i * m1 + j for i, j in ij])
    unit = pts[0][loop] / rho_c                                # on the square of half-size 1
    inner, count, nl = loop, m1 * m1, len(loop)
    for k in range(1, n_ring + 1):
        rho = rho_c + (1.0 - rho_c) * k / n_ring
        pts.append(rho * unit)
        outer = count + np.arange(nl)
        count += nl
        # a outward, b counter-clockwise along the ring: right-handed with z up
        quads += [(inner[q], outer[q], outer[(q + 1) % nl], inner[(q + 1) % nl]) for q in range(nl)]
        inner = outer
    p2 = np.vstack(pts)
    q = np.array(quads).T                                      # (4, n_quad): P00, P10, P11, P01
    nz, n2 = len(z), p2.shape[0]
    p = np.column_stack([np.tile(p2, (nz, 1)), np.repeat(z, n2)])
    lo, hi = q[:, None, :] + n2 * np.arange(nz - 1)[:, None], q[:, None, :] + n2 * np.arange(1, nz)[:, None]
    lo, hi = lo.reshape(4, -1), hi.reshape(4, -1)
    # MeshHex vertex order: P000, P010, P100, P001, P110, P011, P101, P111 (a, b, c)
    t = np.vstack([lo[0], lo[3], lo[1], hi[0], lo[2], hi[3], hi[1], hi[2]])
    return MeshHex(np.ascontiguousarray(p.T), np.ascontiguousarray(t))


def fitted_block_mesh(size: Sequence[float], indenter_diameter: float,
                      layers: Sequence[tuple[str, float, int]], n_inner: int = 2, n_ring: int = 2,
                      grading: float = 1.0, inner_grading: float = 1.0,
                      layer_grading: float = 1.0) -> FEMesh:
    """A layered box ``[0, Lx] x [0, Ly] x [-H, 0]`` whose elements fit a circular indenter
    of diameter ``indenter_diameter`` at the top centre.

    The disc's layout (:func:`disc_mesh`): a square grid of ``n_inner + 2 n_ring`` elements
    across whose central ``n_inner`` x ``n_inner`` block fills the indenter's circle (its
    boundary lands on the circle, graded towards it by ``inner_grading``), and ``n_ring``
    rings from the circle to the box's sides, blending from the circle to the rectangle,
    spaced as ``s^grading`` (finer at the indenter for ``grading`` > 1). The indenter's
    footprint is then the same circle on every mesh (the top nodes within the radius of a
    plain grid form a staircase that changes with the mesh, so its force does not converge).
    Node sets as :func:`block_mesh`'s, plus ``indenter``.
    """
    Lx, Ly = (float(v) for v in size[:2])
    a = 0.5 * float(indenter_diameter)
    if min(Lx, Ly) <= 0:
        raise ModelError("geometry.size", f"must be positive, got {[Lx, Ly]} m")
    if not 0 < a < 0.5 * min(Lx, Ly):
        raise ModelError("geometry.indenter_diameter", f"must be in (0, {min(Lx, Ly)}) m (the block's "
                         f"smaller side) to fit the mesh to it, got {indenter_diameter} m")
    _check_rings(n_inner, n_ring, grading, inner_grading)
    z = _layer_coords([t for _, t, _ in layers], [k for _, _, k in layers], layer_grading)
    n = n_inner + 2 * n_ring
    s = np.linspace(-1.0, 1.0, n + 1)
    nodes, t, el = _from_linear(MeshHex.init_tensor(s, s, z))
    u, v = nodes[:, 0], nodes[:, 1]
    rho = np.maximum(np.abs(u), np.abs(v))
    rho_c = n_inner / n
    d = np.column_stack([u, v]) / np.where(rho > 0, rho, 1.0)[:, None]   # on the unit square
    c = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)  # on the unit circle
    inner = rho <= rho_c + 1e-12
    sc = np.clip(rho / rho_c, 0, 1)
    wgt = np.where(inner, sc, 1.0)
    r = a * (1.0 - (1.0 - sc) ** inner_grading)
    xy_in = r[:, None] * ((1 - wgt)[:, None] * d + wgt[:, None] * c)
    # outside: from the circle (w = 0) to the rectangle's boundary (w = 1)
    w = np.clip((rho - rho_c) / (1 - rho_c), 0, 1) ** grading
    xy_out = (1 - w)[:, None] * (a * c) + w[:, None] * (d * [0.5 * Lx, 0.5 * Ly])
    xy = np.where(inner[:, None], xy_in, xy_out)
    xy[rho == 0] = 0.0
    nodes = np.column_stack([xy + [0.5 * Lx, 0.5 * Ly], nodes[:, 2]])
    ifaces = list(np.cumsum([-th for _, th, _ in layers])[:-1])
    region = _region_by_z(nodes, el, ifaces)
    H = float(sum(th for _, th, _ in layers))
    x, y, zz = nodes.T
    L = max(Lx, Ly, H)
    rr = np.hypot(x - 0.5 * Lx, y - 0.5 * Ly)
    sets = {"top": _near(zz, 0.0, L), "bottom": _near(zz, -H, L),
            "xmin": _near(x, 0.0, L), "xmax": _near(x, Lx, L),
            "ymin": _near(y, 0.0, L), "ymax": _near(y, Ly, L)}
    sets["sides"] = sets["xmin"] | sets["xmax"] | sets["ymin"] | sets["ymax"]
    sets["indenter"] = sets["top"] & (rr <= a * (1 + 1e-9))
    return FEMesh(nodes, t, el, region, [nm for nm, _, _ in layers],
                  {k: np.flatnonzero(v) for k, v in sets.items()})


def disc_mesh(diameter: float = 0.040, indenter_diameter: float = 0.004,
              layers: Sequence[tuple[str, float, int]] = (("skin", 0.0015, 2), ("subdermal", 0.0035, 2)),
              n_inner: int = 3, n_ring: int = 3, grading: float = 1.6, inner_grading: float = 1.0,
              layer_grading: float = 1.0, o_grid: bool = False) -> FEMesh:
    """The in vivo geometry (:func:`_disc_mesh`), a fresh copy of a cached build: a prediction
    builds its model's mesh several times (validation, sensitivities' bookkeeping, each
    worker's solve) and a fit predicts often."""
    import copy

    layers = tuple((str(n), float(t), int(k)) for n, t, k in layers)
    return copy.deepcopy(_disc_mesh(float(diameter), float(indenter_diameter), layers, int(n_inner),
                                    int(n_ring), float(grading), float(inner_grading), float(layer_grading),
                                    bool(o_grid)))


@functools.lru_cache(maxsize=16)
def _disc_mesh(diameter: float = 0.040, indenter_diameter: float = 0.004,
               layers: Sequence[tuple[str, float, int]] = (("skin", 0.0015, 2), ("subdermal", 0.0035, 2)),
               n_inner: int = 3, n_ring: int = 3, grading: float = 1.6, inner_grading: float = 1.0,
               layer_grading: float = 1.0, o_grid: bool = False) -> FEMesh:
    """The in vivo geometry: a layered disc under the support plate's hole.

    One square grid of ``n_inner + 2 n_ring`` elements across is mapped onto the disc so
    that the square ring at the edge of the central ``n_inner`` x ``n_inner`` block lands
    exactly on the indenter's circle (the indenter footprint is resolved, not cut by
    elements), the central block fills the indenter disc, and the ``n_ring`` rings of
    elements outside it are circles graded towards the centre, ``r = a + (R - a) s^grading``.
    Inside, the central block's rings are graded towards the indenter's edge,
    ``r = a (1 - (1 - s)^inner_grading)`` (1: uniform), where a bonded indenter's edge makes
    the stress singular. Every node (edge, face and centre nodes too) is mapped, so element
    edges follow the circles. Layers are ``(name, thickness [m], element layers)`` from the
    top (z = 0) down, each graded towards its top by ``layer_grading`` (1: uniform).

    ``o_grid``: every ring keeps the central block's ``4 n_inner`` elements around (an O-grid)
    instead of 8 more than the ring inside it, so a ring costs ``4 n_inner`` elements per
    element layer rather than ``4 (n_inner + 2k - 1)``: radial resolution, where the
    indentation's field varies, without the circumferential elements the far rings do not
    need. Same mapping, same node sets.

    Node sets: ``top``, ``bottom``, ``outer`` (the rim, r = R), ``indenter`` (top nodes
    with r <= indenter radius).
    """
    R = 0.5 * float(diameter)
    a = 0.5 * float(indenter_diameter)
    if R <= 0:
        raise ModelError("geometry.diameter", f"must be positive, got {diameter} m")
    if not 0 < a < R:
        raise ModelError("geometry.indenter_diameter", f"must be in (0, {diameter}) m (the disc's "
                         f"diameter), got {indenter_diameter} m")
    _check_rings(n_inner, n_ring, grading, inner_grading)
    z = _layer_coords([t for _, t, _ in layers], [k for _, _, k in layers], layer_grading)
    n = n_inner + 2 * n_ring
    if o_grid:
        nodes, t, el = _from_linear(_o_grid(int(n_inner), int(n_ring), z))
    else:
        s = np.linspace(-1.0, 1.0, n + 1)
        nodes, t, el = _from_linear(MeshHex.init_tensor(s, s, z))
    u, v = nodes[:, 0], nodes[:, 1]
    rho = np.maximum(np.abs(u), np.abs(v))
    rho_c = n_inner / n
    safe = np.where(rho > 0, rho, 1.0)
    d = np.column_stack([u, v]) / safe[:, None]          # on the unit square's boundary
    c = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)  # on the unit circle
    inner = rho <= rho_c + 1e-12
    # inside: squares morph into the indenter's circle; outside: graded circles
    wgt = np.where(inner, rho / rho_c, 1.0)
    r = np.where(inner, a * (1.0 - (1.0 - np.clip(rho / rho_c, 0, 1)) ** inner_grading),
                 a + (R - a) * np.clip((rho - rho_c) / (1 - rho_c), 0, 1) ** grading)
    xy = r[:, None] * ((1 - wgt)[:, None] * d + wgt[:, None] * c)
    xy[rho == 0] = 0.0
    nodes = np.column_stack([xy, nodes[:, 2]])
    ifaces = list(np.cumsum([-th for _, th, _ in layers])[:-1])
    region = _region_by_z(nodes, el, ifaces)
    rr = np.hypot(nodes[:, 0], nodes[:, 1])
    H = float(sum(th for _, th, _ in layers))
    top = _near(nodes[:, 2], 0.0, H)
    sets = {"top": top, "bottom": _near(nodes[:, 2], -H, H),
            "outer": np.abs(rr - R) <= 1e-9 * R,
            "indenter": top & (rr <= a * (1 + 1e-9))}
    return FEMesh(nodes, t, el, region, [nm for nm, _, _ in layers],
                  {k: np.flatnonzero(v) for k, v in sets.items()})
