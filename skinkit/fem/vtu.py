"""Fields of a solved finite-element model for ParaView: a PVD series of VTU files on the full
quadratic mesh.

Each step is one ``.vtu`` of 27-node hexahedra (``VTK_TRIQUADRATIC_HEXAHEDRON``, cell type 29,
nodes in VTK's order: :data:`VTK_HEX27_ORDER`) on the mesh's reference configuration, with
point data

* ``displacement`` ``(N, 3)`` [m]: the solution at the nodes (exact);
* ``green_lagrange_strain`` ``(N, 9)`` [1]: E = (FᵀF − I)/2 relative to the mesh's reference
  configuration (a pre-stretch of the natural state is not in it), row-major 3 x 3;
* ``cauchy_stress`` ``(N, 9)`` [Pa]: σ = F S Fᵀ / det F, the law's total stress (its viscous
  history included, pre-stress and fields applied), row-major 3 x 3;
* ``fibre_directions`` ``(N, 3)`` [1] (and ``fibre_directions_2`` for a second family) where a
  layer's law has fibres (a ``fibres(...)`` method, e.g. ``goh``, also inside ``qlv``): the unit
  fibre direction in the deformed configuration, F F0 a / |F F0 a|; zero at nodes no fibred
  element touches;

and cell data ``region`` (the layer's index). Strain, stress and fibres live at the quadrature
points; their nodal values are obtained by **averaging**: in each element the quadrature values
are extrapolated to its 27 nodes by the least-squares fit of a triquadratic field (trilinear
with fewer than 27 quadrature points), exact for fields of that order, and the element values
at a node are averaged (unweighted) over the elements sharing it — the usual "nodal averaging"
of FE post-processors, not a global L2 projection. Across a layer interface the stress jumps;
the average there is a smoothed value.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.fem.mesh import FEMesh
from skinkit.fem.output import VTK_HEX_ORDER
from skinkit.fem.tensors import push_with

#: VTK's cell type of the 27-node hexahedron
VTK_TRIQUADRATIC_HEXAHEDRON = 29

#: VTK_TRIQUADRATIC_HEXAHEDRON's nodes in its reference cube [0, 1]³: 8 vertices, 12 edge
#: midpoints (bottom, top, vertical), 6 face centres (x = 0, x = 1, y = 0, y = 1, z = 0, z = 1),
#: the centre (VTK's vtkTriQuadraticHexahedron documentation)
_VTK_XI = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
                    [.5, 0, 0], [1, .5, 0], [.5, 1, 0], [0, .5, 0],
                    [.5, 0, 1], [1, .5, 1], [.5, 1, 1], [0, .5, 1],
                    [0, 0, .5], [1, 0, .5], [1, 1, .5], [0, 1, .5],
                    [0, .5, .5], [1, .5, .5], [.5, 0, .5], [.5, 1, .5], [.5, .5, 0], [.5, .5, 1],
                    [.5, .5, .5]])


def _hex27_order() -> np.ndarray:
    """The scikit-fem ``ElementHex2`` node of each VTK node: the vertices as :data:`VTK_HEX_ORDER`
    (checked for positive volume), the other nodes found through the affine map of VTK's
    reference cube onto scikit-fem's that this vertex order fixes."""
    from skfem import ElementHex2

    ref = ElementHex2().doflocs                      # (27, 3) scikit-fem's reference positions
    r = ref[VTK_HEX_ORDER]
    A = np.column_stack([r[1] - r[0], r[3] - r[0], r[4] - r[0]])
    target = _VTK_XI @ A.T + r[0]
    order = np.array([int(np.argmin(np.abs(ref - x).sum(axis=1))) for x in target])
    assert np.allclose(ref[order], target) and len(set(order.tolist())) == 27
    return order


#: scikit-fem ``ElementHex2`` node index of each VTK_TRIQUADRATIC_HEXAHEDRON node
VTK_HEX27_ORDER = _hex27_order()


def extrapolation(N: np.ndarray) -> np.ndarray:
    """``(27, n_q)``: element nodal values (scikit-fem order) from quadrature values, by the
    least-squares fit of a triquadratic field (trilinear when ``n_q < 27``). ``N`` ``(n_q, 27)``:
    the shape functions at the quadrature points."""
    from skfem import ElementHex2

    nodes = ElementHex2().doflocs                    # (27, 3)
    xq = N @ nodes                                   # the quadrature points' reference positions
    if N.shape[0] >= 27:
        return np.linalg.pinv(N)

    def trilinear(x: np.ndarray) -> np.ndarray:
        a, b, c = x.T
        return np.column_stack([np.ones_like(a), a, b, c, a * b, b * c, a * c, a * b * c])
    return trilinear(nodes) @ np.linalg.pinv(trilinear(xq))


def nodal_average(mesh: FEMesh, P: np.ndarray, q: np.ndarray,
                  elements: np.ndarray | None = None) -> np.ndarray:
    """``(N, ...)`` nodal averages of quadrature values ``q`` ``(n_el, n_q, ...)`` (module
    docstring); ``P``: :func:`extrapolation`; ``elements``: only these elements' values (nodes
    none of them touches get 0)."""
    el = np.arange(mesh.n_elements) if elements is None else np.asarray(elements)
    flat = q[el].reshape(len(el), q.shape[1], -1)
    per_node = np.einsum("aq,eqk->eak", P, flat)     # (n, 27, k)
    total = np.zeros((mesh.n_nodes, flat.shape[2]))
    count = np.zeros(mesh.n_nodes)
    idx = mesh.elements[el]
    np.add.at(total, idx.ravel(), per_node.reshape(-1, flat.shape[2]))
    np.add.at(count, idx.ravel(), 1.0)
    out = total / np.maximum(count, 1.0)[:, None]
    return out.reshape((mesh.n_nodes,) + q.shape[2:])


def _fibres(law: Any, params: Mapping[str, Any]) -> list[np.ndarray]:
    """The law's unit fibre directions in its natural configuration (each ``(3,)``), or []:
    from a ``fibres`` method (its arguments taken from the parameters by name), also of a
    viscoelastic wrapper's ``elastic`` law."""
    for obj in (law, getattr(law, "elastic", None)):
        f = getattr(obj, "fibres", None)
        if callable(f):
            args = [params[n] for n in inspect.signature(f).parameters]
            return [np.asarray(a, dtype=float).reshape(3) for a in f(*args)]
    return []


def total_stress(problem: Any, u: np.ndarray, viscous: bool) -> np.ndarray:
    """``(n_el, n_q, 3, 3)`` PK2 stress [Pa] with respect to the mesh configuration at ``u``;
    ``viscous``: a committed viscous state at ``u`` (the solver's, at a converged step in time)
    gives the total stress (1 − Σg) Sₑ + Σ gᵢ hᵢ; otherwise the elastic response."""
    out = problem.stress_at(u)
    if not viscous:
        return out
    for k, st in problem.state.items():
        m = problem.materials[k]
        g, _ = m.prony()
        S = (1 - np.sum(g)) * st.Se + np.einsum("i,i...->...", np.asarray(g, float), st.h)
        if m.F0 is not None:
            S = push_with(m.F0, S)[0]
        out[m.elements] = S
    return out


def point_data(problem: Any, u: np.ndarray, viscous: bool = False) -> dict[str, np.ndarray]:
    """The point data of one state ``u`` ``(n_dof,)`` [m] of ``problem`` (module docstring)."""
    mesh = problem.mesh
    P = extrapolation(problem.geom.N)
    F = problem.deformation_gradients(u)
    S = total_stress(problem, u, viscous)
    I = np.eye(3)
    E = 0.5 * (np.swapaxes(F, -1, -2) @ F - I)
    sigma = F @ S @ np.swapaxes(F, -1, -2) / np.linalg.det(F)[..., None, None]
    out = {"displacement": u.reshape(-1, 3).copy(),
           "green_lagrange_strain": nodal_average(mesh, P, E).reshape(-1, 9),
           "cauchy_stress": nodal_average(mesh, P, sigma).reshape(-1, 9)}
    dirs: list[np.ndarray] = []     # per family: quadrature directions (n_el, n_q, 3)
    fibred = np.zeros(mesh.n_elements, bool)
    for m in problem.materials:
        for j, a in enumerate(_fibres(m.law, m.params)):
            FF0 = F[m.elements] if m.F0 is None else F[m.elements] @ m.F0
            d = FF0 @ a
            while len(dirs) <= j:
                dirs.append(np.zeros(F.shape[:2] + (3,)))
            dirs[j][m.elements] = d / np.linalg.norm(d, axis=-1, keepdims=True)
            fibred[m.elements] = True
    for j, d in enumerate(dirs):
        avg = nodal_average(mesh, P, d, np.flatnonzero(fibred))
        n = np.linalg.norm(avg, axis=1, keepdims=True)
        # a node no fibred element touches keeps a zero vector, not a direction
        unit = np.where(n > 0, avg / np.where(n > 0, n, 1.0), 0.0)
        out["fibre_directions" if j == 0 else f"fibre_directions_{j + 1}"] = unit
    return out


class Series:
    """A PVD series being written: ``out_dir/<stem>.pvd`` and ``out_dir/<stem>_NNNN.vtu``, one
    per :meth:`write` (its time [s]); :meth:`close` writes the collection and returns its path."""

    def __init__(self, out_dir: str | Path, stem: str, mesh: FEMesh) -> None:
        import meshio

        self.out = Path(out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        self.stem = stem
        self._mesh = meshio.Mesh(mesh.nodes, [("hexahedron27", mesh.elements[:, VTK_HEX27_ORDER])],
                                 cell_data={"region": [mesh.region.astype(np.int32)]})
        self.entries: list[tuple[float, str]] = []

    def write(self, t: float, data: Mapping[str, np.ndarray]) -> Path:
        """One step at time ``t`` [s] with point ``data`` (name -> ``(N, k)``)."""
        import meshio

        name = f"{self.stem}_{len(self.entries):04d}.vtu"
        self._mesh.point_data = {k: np.ascontiguousarray(v) for k, v in data.items()}
        meshio.write(self.out / name, self._mesh, file_format="vtu")
        self.entries.append((float(t), name))
        return self.out / name

    def close(self) -> Path:
        """Write ``<stem>.pvd`` (ParaView opens the series from it); returns its path."""
        rows = "\n".join(f'    <DataSet timestep="{t:.9g}" part="0" file="{n}"/>' for t, n in self.entries)
        pvd = self.out / f"{self.stem}.pvd"
        pvd.write_text('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                       + rows + "\n  </Collection>\n</VTKFile>\n")
        return pvd


__all__ = ["VTK_HEX27_ORDER", "VTK_TRIQUADRATIC_HEXAHEDRON", "Series", "extrapolation", "nodal_average",
           "point_data", "total_stress"]
