"""Solve a :class:`~skinkit.fem.model.Model` and write its outputs."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.fem.model import Model
from skinkit.fem.output import summary, write_hdf5, write_vtu_series
from skinkit.fem.solver import NewtonSolver, Solution


def solve_model(model: Model, progress: Callable[[float], None] | None = None
                ) -> tuple[Solution, dict[str, Any]]:
    """Run the model's load programme; returns the solution and its JSON summary."""
    t0 = time.perf_counter()
    solver = NewtonSolver(model.problem, model.bc, model.options)
    emb = None
    if model.points is not None:
        from skinkit.fem.embed import embed_points
        emb = embed_points(model.mesh, model.points, model.point_depth)
    sol = solver.run(model.load.times, viscous_time=model.load.viscous_time, progress=progress,
                     sensitivities=model.sensitivities)
    wall = time.perf_counter() - t0
    fixed = np.unique(np.concatenate([model.mesh.node_sets[s] for s in model.fixed_sets])) \
        if model.fixed_sets else np.zeros(0, int)
    info = summary(model.name, model.mesh, sol, fixed, wall)
    info["load"] = model.load.description
    info["linear_solver"] = solver.linear.name
    if emb is not None:
        X = model.mesh.nodes
        pos = np.array([emb.positions(X, u) for u in sol.u])
        sol.extra["points"] = pos
        for st, p in zip(info["steps"], pos, strict=True):
            st["points_m"] = p.tolist()
    if model.sensitivities:
        sens = sol.extra["sensitivities"]
        info["parameters"] = sens[0].names if sens else []
        for st, sv in zip(info["steps"], sens, strict=True):
            st["d_tip_force_N"] = None if sv.tip_force is None else np.nan_to_num(sv.tip_force).tolist()
            st["d_tip_displacement_m"] = None if sv.tip_displacement is None else \
                np.nan_to_num(sv.tip_displacement).tolist()
            if emb is not None:
                J = emb.position_jacobian(model.mesh.n_dof)
                st["d_points_m"] = (J @ sv.du).reshape(-1, 3, sv.du.shape[1]).tolist()
    return sol, info


def write_outputs(model: Model, sol: Solution, info: dict[str, Any], out: Path,
                  vtu: bool = True) -> dict[str, str]:
    """Write ``result.h5``, ``summary.json`` and (``vtu``) ``step.pvd`` + ``step_*.vtu`` in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    files = {"hdf5": str(out / "result.h5"), "summary": str(out / "summary.json")}
    write_hdf5(out / "result.h5", model.mesh, sol, info)
    if vtu:
        files["vtu"] = str(write_vtu_series(out, model.mesh, sol))
    (out / "summary.json").write_text(json.dumps(info, indent=2))
    return files
