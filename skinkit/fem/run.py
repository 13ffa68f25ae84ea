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
    sol = solver.run(model.load.times, viscous_time=model.load.viscous_time, progress=progress)
    wall = time.perf_counter() - t0
    fixed = np.unique(np.concatenate([model.mesh.node_sets[s] for s in model.fixed_sets])) \
        if model.fixed_sets else np.zeros(0, int)
    info = summary(model.name, model.mesh, sol, fixed, wall)
    info["load"] = model.load.description
    info["linear_solver"] = solver.linear.name
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
