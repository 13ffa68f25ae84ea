"""Writing a solved model: HDF5 result, a VTU series ParaView opens, a JSON summary."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np

from skinkit import jsonio
from skinkit.fem.mesh import FEMesh
from skinkit.fem.solver import Solution

#: scikit-fem's hexahedron vertices in VTK's order (bottom quad then top quad, each
#: counter-clockwise seen from above, so that VTK's cell volumes are positive); checked
#: by ``tests/fem/test_fem_model.py::test_vtu_cells_have_positive_volume``
VTK_HEX_ORDER = np.array([6, 2, 0, 3, 7, 4, 1, 5])


def summary(model_name: str, mesh: FEMesh, sol: Solution, fixed_nodes: np.ndarray,
            wall_s: float) -> dict[str, Any]:
    """JSON-ready summary: per step tip displacement [m], tip force [N], reaction [N], iterations."""
    steps = []
    for st in sol.steps:
        reac = st.reaction.reshape(-1, 3)[fixed_nodes].sum(axis=0) if fixed_nodes.size else np.zeros(3)

        def lst(x):
            return None if x is None else [None if not np.isfinite(v) else float(v) for v in x]
        steps.append({"t": float(st.t), "tip_displacement_m": lst(st.tip_displacement),
                      "tip_force_N": lst(st.tip_force), "reaction_force_N": lst(reac),
                      "newton_iterations": int(st.iterations)})
    return {"model": model_name, "dof": mesh.n_dof, "elements": mesh.n_elements,
            "wall_s": wall_s, "newton_iterations": int(sol.timings.iterations),
            "factorisations": int(sol.timings.factorisations),
            "assembly_s": sol.timings.assembly, "solve_s": sol.timings.solve, "steps": steps}


def write_hdf5(path: Path, mesh: FEMesh, sol: Solution, info: dict[str, Any]) -> None:
    """``/mesh/nodes`` (N, 3) [m], ``/mesh/elements`` (E, 27), ``/times`` [s or 1],
    ``/displacement`` (steps, N, 3) [m], ``/tip_displacement``, ``/tip_force``, ``/iterations``."""
    with h5py.File(path, "w") as f:
        f.attrs["model"] = info["model"]
        f.attrs["summary"] = jsonio.dumps(info)
        f["mesh/nodes"] = mesh.nodes
        f["mesh/elements"] = mesh.elements
        f["mesh/region"] = mesh.region
        f["mesh"].attrs["regions"] = jsonio.dumps(mesh.regions)
        f["times"] = sol.times
        f["displacement"] = sol.u.reshape(len(sol.times), -1, 3)
        nan3 = np.full(3, np.nan)
        tip = [s.tip_displacement if s.tip_displacement is not None else nan3 for s in sol.steps]
        frc = [s.tip_force if s.tip_force is not None else nan3 for s in sol.steps]
        f["tip_displacement"] = np.array(tip)
        f["tip_force"] = np.array(frc)
        f["iterations"] = np.array([s.iterations for s in sol.steps])
        if "points" in sol.extra:
            f["points"] = sol.extra["points"]  # (steps, M, 3) embedded point positions [m]
        if "sensitivities" in sol.extra and sol.extra["sensitivities"]:
            sens = sol.extra["sensitivities"]
            f["sensitivity/displacement"] = np.array([sv.du for sv in sens])  # (steps, n_dof, n_par)
            f["sensitivity"].attrs["parameters"] = jsonio.dumps(sens[0].names)


def write_vtu_series(out: Path, mesh: FEMesh, sol: Solution, stem: str = "step") -> Path:
    """One ``.vtu`` per step (linear hexahedra on the vertices, displacement as point data)
    plus a ``.pvd`` collection; returns the ``.pvd`` path."""
    import meshio
    nv = int(mesh.t.max()) + 1
    cells = [("hexahedron", mesh.t.T[:, VTK_HEX_ORDER])]
    entries = []
    for k, t in enumerate(sol.times):
        u = sol.u[k].reshape(-1, 3)[:nv]
        name = f"{stem}_{k:04d}.vtu"
        meshio.write(out / name, meshio.Mesh(mesh.nodes[:nv], cells, point_data={"displacement": u},
                                             cell_data={"region": [mesh.region.astype(np.int32)]}))
        entries.append(f'    <DataSet timestep="{t:.9g}" part="0" file="{name}"/>')
    pvd = out / f"{stem}.pvd"
    pvd.write_text('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                   + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n")
    return pvd
