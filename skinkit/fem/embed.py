"""Fitting a mesh to a measured surface, and embedding tracked material points.

* :func:`fit_surface` (thesis 7.4.4): top-surface nodes move along z only to the measured
  surface; nodes on the rim and under the indenter stay; the nodes of the skin layer move
  with the top node above them so that the skin keeps its thickness, and the deeper nodes
  follow by an offset fading linearly to zero at the floor.
* :func:`embed_points`: each tracked surface point (optionally offset below the surface,
  as the thesis embeds its microspheres) is located in its element with local coordinates,
  so its position can be read in any deformed state (:meth:`Embedding.positions`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator
from skfem import ElementHex2

from skinkit.fem.errors import ModelError
from skinkit.fem.mesh import FEMesh

_ELEMENT = ElementHex2()


def _columns(mesh: FEMesh, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Column id of every node (nodes sharing x, y) and the top node of each column."""
    key = np.round(mesh.nodes[:, :2] / (1e-9 * scale)).astype(np.int64)
    _, col = np.unique(key, axis=0, return_inverse=True)
    col = col.ravel()
    top_of = np.full(col.max() + 1, -1)
    top = mesh.node_sets["top"]
    top_of[col[top]] = top
    return col, top_of


@dataclass
class SurfaceFit:
    """A fitted mesh and the RMS distance [m] of the measured points to its top surface."""

    mesh: FEMesh
    rms: float
    max_abs: float


def fit_surface(mesh: FEMesh, points: np.ndarray, skin_thickness: float,
                keep: tuple[str, ...] = ("outer", "indenter")) -> SurfaceFit:
    """Move the mesh onto the measured surface ``points`` ``(M, 3)`` [m] (see module doc)."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3:
        raise ModelError("surface", f"expected (M >= 3, 3) points, got shape {pts.shape}")
    X = mesh.nodes
    scale = float(np.ptp(X, axis=0).max())
    col, top_of = _columns(mesh, scale)
    lin = LinearNDInterpolator(pts[:, :2], pts[:, 2])
    near = NearestNDInterpolator(pts[:, :2], pts[:, 2])
    top = mesh.node_sets["top"]
    z_new = lin(X[top, :2])
    miss = ~np.isfinite(z_new)
    z_new[miss] = near(X[top[miss], :2])
    dz_top = z_new - X[top, 2]
    fixed = np.zeros(mesh.n_nodes, bool)
    for k in keep:
        if k in mesh.node_sets:
            fixed[mesh.node_sets[k]] = True
    dz_top[fixed[top]] = 0.0
    dz_col = np.zeros(top_of.size)
    dz_col[col[top]] = dz_top
    z_floor = X[:, 2].min()
    z_skin = X[top, 2].max() - skin_thickness
    z = X[:, 2]
    # skin nodes move rigidly with their column's top node; deeper nodes fade to the floor
    w = np.where(z >= z_skin - 1e-12 * scale, 1.0, (z - z_floor) / max(z_skin - z_floor, 1e-300))
    new = X.copy()
    new[:, 2] += w * dz_col[col]
    fitted = mesh.with_nodes(new)
    # residual: the measured points against the fitted top surface (interpolated linearly
    # between top nodes, the surface the elements' faces follow to second order)
    surf = LinearNDInterpolator(new[top, :2], new[top, 2])
    zs = surf(pts[:, :2])
    ok = np.isfinite(zs)
    r = pts[ok, 2] - zs[ok]
    return SurfaceFit(fitted, float(np.sqrt(np.mean(r ** 2))) if r.size else float("nan"),
                      float(np.max(np.abs(r))) if r.size else float("nan"))


@dataclass
class Embedding:
    """Tracked points located in a mesh: element ``(M,)``, local coordinates ``(M, 3)`` in
    [0, 1]³, the node indices of each element ``(M, 27)`` and shape values ``(M, 27)``."""

    element: np.ndarray
    local: np.ndarray
    nodes: np.ndarray
    N: np.ndarray

    def positions(self, X: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """``(M, 3)`` positions [m] with node coordinates ``X`` ``(N, 3)`` and displacement
        ``u`` (``(n_dof,)`` or ``(N, 3)``; None: the reference positions)."""
        P = X[self.nodes]
        if u is not None:
            P = P + np.asarray(u).reshape(-1, 3)[self.nodes]
        return _interpolate(self.N.T, P)

    def position_jacobian(self, n_dof: int):
        """Sparse ``(3 M, n_dof)`` matrix mapping a displacement (or a sensitivity ``du/dp``)
        to the points' displacements: ``d(positions)/dp = J @ du/dp``."""
        import scipy.sparse as sp
        M = self.element.size
        rows = (3 * np.arange(M)[:, None, None] + np.arange(3)[None, None, :]).repeat(27, axis=1)
        cols = 3 * self.nodes[:, :, None] + np.arange(3)[None, None, :]
        vals = np.repeat(self.N[:, :, None], 3, axis=2)
        return sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * M, n_dof))


    def moved(self, X: np.ndarray, u: np.ndarray, V: np.ndarray, dX: np.ndarray) -> np.ndarray:
        """``(M, 3)`` [m per unit of p] the positions' change at fixed nodal displacements ``u``
        (``(n_dof,)`` or ``(N, 3)``) when the mesh's nodes ``X`` ``(N, 3)`` move with ``V`` ``(N, 3)``
        and the points' reference positions with ``dX`` ``(M, 3)`` (a geometry parameter p).

        A point stays where it was located, so its local coordinates move by
        ``dξ = J⁻¹ (dX − V(ξ))`` and it reads the displacement field elsewhere: the change is
        ``dX + ∇_X u (dX − V(ξ))``; with ``J @ du/dp`` (:meth:`position_jacobian`) it is the
        whole derivative."""
        _, dN = _shape(self.local.T)
        Jx = _jacobian(dN, X[self.nodes])
        Ju = _jacobian(dN, np.asarray(u).reshape(-1, 3)[self.nodes])
        grad = Ju @ np.linalg.inv(Jx)                       # ∇_X u at the points
        rel = dX - _interpolate(self.N.T, V[self.nodes])
        return dX + np.matmul(grad, rel[..., None])[..., 0]


def located(mesh: FEMesh, element: np.ndarray, local: np.ndarray) -> np.ndarray:
    """``(M, 3)`` [m] reference positions of points at local coordinates ``local`` ``(M, 3)`` in
    the elements ``element`` ``(M,)`` of ``mesh``."""
    N, _ = _shape(np.asarray(local, dtype=float).T)
    return _interpolate(N, mesh.nodes[mesh.elements[np.asarray(element)]])


#: each node's position on the 1D quadratic nodes (0, ½, 1) along each axis, ``(27, 3)``: the
#: element's shape functions are products of 1D quadratic Lagrange polynomials
_AXIS_NODE = np.rint(2 * np.asarray(_ELEMENT.doflocs)).astype(int)


def _lagrange(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 1D quadratic Lagrange polynomials on the nodes 0, ½, 1 and their derivatives, each
    ``(3, M)``, at ``x`` ``(M,)``."""
    L = np.stack([2 * (x - 0.5) * (x - 1), -4 * x * (x - 1), 2 * x * (x - 0.5)])
    dL = np.stack([4 * x - 3, 4 - 8 * x, 4 * x - 1])
    return L, dL


def _shape(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shape values ``(27, M)`` and reference gradients ``(27, 3, M)`` at ``xi`` ``(3, M)``
    (as scikit-fem's ``ElementHex2``, by tensor products: its basis one function at a time
    was most of locating a session's tracked points)."""
    (Lx, dLx), (Ly, dLy), (Lz, dLz) = (_lagrange(xi[k]) for k in range(3))
    ix, iy, iz = _AXIS_NODE.T
    X, Y, Z = Lx[ix], Ly[iy], Lz[iz]
    N = X * Y * Z
    dN = np.stack([dLx[ix] * Y * Z, X * dLy[iy] * Z, X * Y * dLz[iz]], axis=1)
    return N, dN


def _interpolate(N: np.ndarray, Xe: np.ndarray) -> np.ndarray:
    """``(M, 3)`` sum over nodes of shape values ``N`` ``(27, M)`` times ``Xe`` ``(M, 27, 3)``
    (a batched product: einsum's generic loop was most of locating points)."""
    return np.matmul(N.T[:, None, :], Xe)[:, 0, :]


def _jacobian(dN: np.ndarray, Xe: np.ndarray) -> np.ndarray:
    """``(M, 3, 3)`` dX_i/dξ_j from reference gradients ``dN`` ``(27, 3, M)`` and ``Xe``."""
    return np.matmul(dN.transpose(2, 1, 0), Xe).transpose(0, 2, 1)


def embed_points(mesh: FEMesh, points: np.ndarray, depth: float = 0.0, tol: float = 1e-10) -> Embedding:
    """Locate ``points`` ``(M, 3)`` [m] (moved ``depth`` [m] down first) in ``mesh``.

    Newton inversion of the isoparametric map in every element whose node bounding box
    holds the point, nearest centre first; a point in none raises :class:`ModelError`.
    """
    pts = np.asarray(points, dtype=float).copy()
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ModelError("points", f"expected (M, 3) points, got shape {pts.shape}")
    pts[:, 2] -= depth
    Xe = mesh.nodes[mesh.elements]                  # (E, 27, 3)
    lo, hi = Xe.min(axis=1), Xe.max(axis=1)
    # a quadratic element bulges beyond its nodes' box: along an edge whose node values span a
    # range d, by up to d/8 (e.g. a top face fitted to a profile beside flat nodes under the
    # indenter: micrometres above its highest node). Pad each axis by that bound; the Newton
    # inversion and the inside test below decide which element holds a point.
    pad = 0.125 * (hi - lo) + 1e-3 * (hi - lo).max(axis=1, keepdims=True)
    inbox = np.all((pts[:, None, :] >= lo[None] - pad[None]) & (pts[:, None, :] <= hi[None] + pad[None]),
                   axis=2)                           # (M, E)
    dist = np.linalg.norm(pts[:, None, :] - Xe.mean(axis=1)[None], axis=2)
    dist[~inbox] = np.inf
    order = np.argsort(dist, axis=1)
    n_c = int(inbox.sum(axis=1).max()) if len(pts) else 0
    cand = order[:, :max(n_c, 1)]
    M = len(pts)
    found = np.full(M, -1)
    local = np.zeros((M, 3))
    for j in range(cand.shape[1]):
        todo = np.flatnonzero((found < 0) & np.isfinite(dist[np.arange(M), cand[:, j]]))
        if todo.size == 0:
            break
        e = cand[todo, j]
        xi = np.full((3, todo.size), 0.5)
        for _ in range(30):
            N, dN = _shape(xi)
            x = _interpolate(N, Xe[e])
            Jm = _jacobian(dN, Xe[e])
            r = pts[todo] - x
            try:
                dxi = np.linalg.solve(Jm, r[..., None])[..., 0]
            except np.linalg.LinAlgError:
                break
            xi = np.clip(xi + dxi.T, -0.5, 1.5)
            if np.max(np.abs(dxi)) < tol:
                break
        inside = np.all((xi > -1e-8) & (xi < 1 + 1e-8), axis=0) & (np.linalg.norm(r, axis=1) < 1e-8 * (
            np.ptp(mesh.nodes, axis=0).max()) + 1e-15)
        found[todo[inside]] = e[inside]
        local[todo[inside]] = np.clip(xi.T[inside], 0.0, 1.0)
    if np.any(found < 0):
        bad = int(np.flatnonzero(found < 0)[0])
        raise ModelError(f"points[{bad}]", f"{pts[bad].tolist()} m lies outside the mesh")
    N, _ = _shape(local.T)
    return Embedding(found, local, mesh.elements[found], N.T.copy())


def _vertical_axis(Xe: np.ndarray) -> tuple[int, float]:
    """The local axis of the element that runs up the thickness, and which end is the top."""
    xi = np.full((3, 1), 0.5)
    _, dN = _shape(xi)
    Jm = np.einsum("aj,ai->ij", dN[:, :, 0], Xe)    # dX_i/dξ_j
    a = int(np.argmax(np.abs(Jm[2])))
    return a, (1.0 if Jm[2, a] > 0 else 0.0)


def _face_newton(Xe: np.ndarray, xy: np.ndarray, free: list[int], axis: int, end: float, tol: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Face coordinates ``(n, 2)`` of the points ``xy`` ``(n, 2)`` [m] on the top faces of
    elements ``Xe`` ``(n, 27, 3)`` (Newton on the in-plane map, clipped to [-0.5, 1.5]) and the
    in-plane miss ``(n,)`` [m] of the face point found."""
    n = len(xy)
    s = np.full((2, n), 0.5)
    xi = np.zeros((3, n))
    xi[axis] = end
    for _ in range(30):
        xi[free] = s
        N, dN = _shape(xi)
        x = _interpolate(N, Xe)
        Jm = _jacobian(dN, Xe)[:, :2][:, :, free]
        r = xy - x[:, :2]
        det = Jm[:, 0, 0] * Jm[:, 1, 1] - Jm[:, 0, 1] * Jm[:, 1, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            ds = np.stack([(Jm[:, 1, 1] * r[:, 0] - Jm[:, 0, 1] * r[:, 1]) / det,
                           (Jm[:, 0, 0] * r[:, 1] - Jm[:, 1, 0] * r[:, 0]) / det])
        ds = np.where(np.isfinite(ds), ds, 0.0)   # a degenerate face: left where it is, then refused
        s = np.clip(s + ds, -0.5, 1.5)
        if np.max(np.abs(ds)) < tol:
            break
    xi[free] = s
    x = _interpolate(_shape(xi)[0], Xe)
    return s.T, np.linalg.norm(xy - x[:, :2], axis=1)


def surface_points(mesh: FEMesh, points: np.ndarray, depth: float = 0.0, tol: float = 1e-12
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Measured surface points ``(M, 3)`` [m] moved onto the mesh's top surface and then
    ``depth`` [m] inwards along the surface's true normal.

    Each point is projected along the surface normal: its in-plane position is moved until
    the surface point below it has the point on its normal (a few fixed-point steps, exact
    for a flat surface). Returns ``(positions (M, 3), unit outward normals (M, 3))``.
    Raises :class:`ModelError` naming the first point that lies outside the top surface.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ModelError("points", f"expected (M, 3) points, got shape {pts.shape}")
    if not len(pts):
        return np.zeros((0, 3)), np.zeros((0, 3))
    top = np.zeros(mesh.n_nodes, bool)
    top[mesh.node_sets["top"]] = True
    top_el = np.flatnonzero(top[mesh.elements].sum(axis=1) >= 9)
    Xe_all = mesh.nodes[mesh.elements[top_el]]
    axis, end = _vertical_axis(Xe_all[0])
    lo, hi = Xe_all[..., :2].min(axis=1), Xe_all[..., :2].max(axis=1)
    M = len(pts)
    out = np.zeros((M, 3))
    nrm = np.zeros((M, 3))
    xy = pts[:, :2].copy()
    free = [i for i in range(3) if i != axis]
    ctr = Xe_all[..., :2].mean(axis=1)
    scale = np.ptp(Xe_all.reshape(len(Xe_all), -1), axis=1)
    pad = 1e-9 * float(np.ptp(mesh.nodes, axis=0).max())
    for _ in range(4):
        found = np.full(M, -1)
        loc = np.zeros((M, 2))
        inbox = np.all((xy[:, None] >= lo[None] - pad) & (xy[:, None] <= hi[None] + pad), axis=2)
        dist = np.linalg.norm(xy[:, None] - ctr[None], axis=2)
        dist[~inbox] = np.inf
        order = np.argsort(dist, axis=1)[:, :max(int(inbox.sum(axis=1).max()), 1)]
        # every point's candidate faces, nearest centre first, all points at once per rank
        for j in range(order.shape[1]):
            todo = np.flatnonzero((found < 0) & np.isfinite(dist[np.arange(M), order[:, j]]))
            if todo.size == 0:
                break
            e = order[todo, j]
            sj, miss = _face_newton(Xe_all[e], xy[todo], free, axis, end, tol)
            # inside the face, and really there: a clipped Newton can stop at a wrong point
            ok = np.all((sj > -1e-8) & (sj < 1 + 1e-8), axis=1) & (miss < 1e-9 * np.maximum(1.0, scale[e]))
            found[todo[ok]] = e[ok]
            loc[todo[ok]] = np.clip(sj[ok], 0, 1)
        if np.any(found < 0):
            bad = int(np.flatnonzero(found < 0)[0])
            raise ModelError(f"points[{bad}]", f"{pts[bad].tolist()} m lies outside the model's top surface")
        xi = np.zeros((3, M))
        xi[free] = loc.T
        xi[axis] = end
        N, dN = _shape(xi)
        Xe = Xe_all[found]
        out = _interpolate(N, Xe)
        Jm = _jacobian(dN, Xe)
        n = np.cross(Jm[:, :, free[0]], Jm[:, :, free[1]])
        n = n / np.linalg.norm(n, axis=1, keepdims=True)
        nrm = np.where(n[:, 2:3] > 0, n, -n)
        # the measured point should lie on the normal through the surface point
        off = pts - out
        along = np.einsum("mi,mi->m", off, nrm)
        new_xy = (pts - along[:, None] * nrm)[:, :2]
        if np.max(np.abs(new_xy - xy)) < 1e-12 * max(1.0, float(np.abs(pts).max())):
            break
        xy = new_xy
    return out - depth * nrm, nrm
