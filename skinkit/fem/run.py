"""Solve a :class:`~skinkit.fem.model.Model` and write its outputs."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from skinkit import jsonio
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
    (out / "summary.json").write_text(jsonio.dumps(info, indent=2))
    return files


def _quantity(model: Model) -> str | None:
    """The computed (not prescribed) tip quantity: the force under displacement control, the
    motion under force control; None without an indenter."""
    rigid = model.bc.rigid
    if rigid is None:
        return None
    return "tip_displacement_m" if rigid.mode == "force" else "tip_force_N"


def _attach(info: dict[str, Any], est: dict[str, Any], level: int, model: Model,
            extra: dict[str, Any]) -> None:
    """Write the estimate of level ``level`` beside the result: per step ``tip_force_error_N``,
    ``tip_displacement_error_m`` (3,), ``points_error_m`` (M,), and a ``discretisation`` block."""
    names = {"tip_force_N": "tip_force_error_N", "tip_displacement_m": "tip_displacement_error_m",
             "points_m": "points_error_m"}
    for key, name in names.items():
        if key in est:
            for st, e in zip(info["steps"], est[key]["estimated_error"][level], strict=True):
                st[name] = e
    q = _quantity(model)
    block: dict[str, Any] = {
        "method": est["method"], "factors": est["factors"], "dof": est["dof"],
        "factor": est["factors"][level], "quantity": q,
        "tip_force_relative_error": est.get("tip_force_N", {}).get("relative_error", [None])[level],
        "tip_displacement_relative_error": est.get("tip_displacement_m", {}).get("relative_error",
                                                                                 [None])[level],
        "points_max_error_m": est["points_m"]["max_error_m"][level] if "points_m" in est else None}
    main = est.get(q or "tip_force_N") or est.get("points_m") or {}
    block.update({"order": main.get("order"), "observed_order": main.get("observed_order"),
                  "order_assumed": main.get("order_assumed")})
    block["extrapolated"] = {k: est[k]["extrapolated"][-1] for k in names if k in est}
    block.update(extra)
    info["discretisation"] = block


def solve_with_estimate(spec: dict[str, Any], levels: int = 2, *, order: float | None = None,
                        progress: Callable[[float], None] | None = None,
                        log: Callable[[str], None] | None = None
                        ) -> tuple[Model, Solution, dict[str, Any]]:
    """Solve a model description and estimate the discretisation error of its result.

    Without ``[solver] discretisation_tolerance`` / ``point_tolerance``: solves on the
    file's mesh and on meshes refined ``2x`` (and ``3x`` when ``levels`` is 3, to measure
    the order; otherwise :data:`skinkit.fem.discretisation.ASSUMED_ORDER` is assumed), and
    returns the file's mesh's result with its estimate. With a tolerance: solves on meshes
    refined 1x, 2x, 3x, ... (every count multiplied, so the graded mesh refines most near
    the probe) until the finest one's estimate meets it, and returns that one; a refinement
    over the size limit (:func:`skinkit.fem.model.max_unknowns`) is refused with a
    :class:`ModelError` giving the estimate reached.

    Returns ``(model, solution, summary)``; the summary carries per-step
    ``tip_force_error_N``, ``tip_displacement_error_m`` [N, m] (3,) and ``points_error_m``
    (M,) [m], and a ``discretisation`` block (factors, unknowns, order, relative errors, the
    extrapolated final values, and with a tolerance ``met`` and ``unknowns_solved``).
    """
    from skinkit.fem.discretisation import estimate, meets, refined_spec
    from skinkit.fem.errors import ModelError
    from skinkit.fem.model import build_model, check_size, layer_table

    say = log or (lambda _m: None)
    first = build_model(spec)
    tol, ptol = first.discretisation_tolerance, first.point_tolerance
    q = _quantity(first)
    if tol is not None and q is None:
        raise ModelError("solver.discretisation_tolerance", "the model has no [indenter] whose force or "
                         "motion it could control; use point_tolerance for tracked points")
    if ptol is not None and first.points is None:
        raise ModelError("solver.point_tolerance", "the model tracks no points ([output] points)")
    controlled = tol is not None or ptol is not None
    if not controlled and levels not in (2, 3):
        raise ValueError(f"levels must be 2 or 3, got {levels}")
    results: list[tuple[Model, Solution, dict[str, Any]]] = []
    factor = 1
    while True:
        if factor == 1:
            model = first
        else:
            fine = refined_spec(spec, factor)
            try:
                check_size(fine, layer_table(fine))
            except ModelError as exc:
                if not controlled:
                    raise
                last = results[-3:]
                reached = "no estimate yet (one mesh solved)" if len(last) < 2 else _met_text(
                    estimate([r[2] for r in last], list(range(factor - len(last), factor)), order), -1, q)
                entry = "solver.discretisation_tolerance" if tol is not None else "solver.point_tolerance"
                raise ModelError(entry, f"not met before the size limit: {reached} at "
                                 f"{results[-1][2]['dof']:,} unknowns (refined {factor - 1}x); refining "
                                 f"{factor}x: {exc.problem}") from None
            model = build_model(fine)
            say(f"refined {factor}x: {model.mesh.n_dof:,} unknowns")
        sol, info = solve_model(model, progress=progress if factor == 1 else None)
        results.append((model, sol, info))
        n = len(results)
        if not controlled:
            if n < levels:
                factor += 1
                continue
            est = estimate([r[2] for r in results], list(range(1, n + 1)), order)
            m0, s0, i0 = results[0]
            _attach(i0, est, 0, m0, {})
            return m0, s0, i0
        if n >= 2:
            facs = list(range(factor - min(n, 3) + 1, factor + 1))
            est = estimate([r[2] for r in results[-3:]], facs, order)
            if meets(est, -1, tol, ptol, q or "tip_force_N"):
                m, s, i = results[-1]
                _attach(i, est, len(facs) - 1, m, {
                    "tolerance": tol, "point_tolerance": ptol, "met": True,
                    "unknowns_solved": int(sum(r[2]["dof"] for r in results))})
                return m, s, i
            say(f"refined {factor}x: {_met_text(est, -1, q)}")
        factor += 1


def _met_text(est: dict[str, Any], level: int, q: str | None) -> str:
    """One line: the estimated error of level ``level``."""
    parts = []
    if q in est:
        parts.append(f"estimated {q.split('_')[1]} error {100 * est[q]['relative_error'][level]:.2g} %")
    if "points_m" in est:
        parts.append(f"points within {1e6 * est['points_m']['max_error_m'][level]:.3g} µm")
    return ", ".join(parts) or "no estimate"
