"""``skinkit bench fem``: skinkit's Newton iteration against sfepy's on the same problem.

The same ~10,000-dof block of 27-node hexahedra (7 x 7 x 7 elements), the same
nearly incompressible neo-Hookean law split as sfepy does it (``dw_tl_he_neohook`` +
``dw_tl_bulk_penalty``: W = μ/2 (Ī1 - 3) + K/2 (J - 1)²), the same boundary conditions
(floor fixed, top face moved by a shear and a compression) and the same quadrature degree,
solved in one load step by both in one process, total Lagrangian, ``approx_order=2``.
Seconds per Newton iteration = solve wall time / number of tangent factorisations;
``assembly_s`` is all assembly per iteration (the tangent and the line search's residuals),
``tangent_assembly_s`` one tangent assembly, ``solve_s`` one factorisation + solve.
"""

from __future__ import annotations

import contextlib
import io
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from skinkit.fem.assembly import DEFAULT_INTORDER
from skinkit.fem.bcs import BoundaryConditions
from skinkit.fem.mesh import block_mesh
from skinkit.fem.output import VTK_HEX_ORDER
from skinkit.fem.problem import Material, Problem
from skinkit.fem.solver import NewtonSolver, SolverOptions

MU = 1.0e4       # Pa
BULK = 1.0e5     # Pa (ν ≈ 0.45)
TOP_U = (0.02, 0.0, -0.04)  # m, on a 1 m cube (sfepy, without load steps, fails at larger loads)


def _law():
    from skinkit import registry
    return registry.create("skinkit.laws", "neo-hookean-ni")


def run_skinkit(n: int = 7, linear: str = "auto") -> dict:
    """Solve with skinkit; returns displacement at vertices and timings."""
    mesh = block_mesh((1.0, 1.0, 1.0), (n, n, n))
    t0 = time.perf_counter()
    prob = Problem(mesh, [Material("body", _law(), {"mu": MU, "K": BULK})], intorder=DEFAULT_INTORDER)
    bc = BoundaryConditions(mesh.n_dof).fix(mesh.node_sets["bottom"])
    for c, v in enumerate(TOP_U):
        bc.prescribe(mesh.node_sets["top"], c, lambda t, v=v: v * t)
    solver = NewtonSolver(prob, bc, SolverOptions(linear=linear, rtol=1e-10))
    setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    sol = solver.run([1.0])
    wall = time.perf_counter() - t0
    tm = sol.timings
    n_fact = tm.iterations  # factorisations: the tangent predictor's and each Newton iteration's
    return {"mesh": mesh, "u": sol.u[-1].reshape(-1, 3), "wall": wall, "setup": setup,
            "factorisations": n_fact, "assembly_s": tm.assembly / n_fact, "solve_s": tm.solve / n_fact,
            "tangent_assembly_s": tm.tangent / max(tm.tangent_assemblies, 1),
            "s_per_newton": wall / n_fact, "dof": mesh.n_dof, "linear": solver.linear.name}


def run_sfepy(mesh) -> dict:
    """Solve the same problem with sfepy (linear hex mesh, approx_order=2)."""
    # sfepy prints notices on stdout at import and while solving: keep stdout for our JSON
    with contextlib.redirect_stdout(io.StringIO()):
        return _run_sfepy(mesh)


def _run_sfepy(mesh) -> dict:
    from sfepy.base.base import IndexedStruct, output
    from sfepy.discrete import Equation, Equations, FieldVariable, Integral
    from sfepy.discrete import Material as SfMaterial
    from sfepy.discrete import Problem as SfProblem
    from sfepy.discrete.conditions import Conditions, EssentialBC
    from sfepy.discrete.fem import FEDomain, Field, Mesh
    from sfepy.solvers.ls import ScipyDirect
    from sfepy.solvers.nls import Newton
    from sfepy.terms import Term
    output.set_output(quiet=True)

    nv = int(mesh.t.max()) + 1
    coors = mesh.nodes[:nv]
    # sfepy's 3_8 cells use the VTK hexahedron order
    conn = mesh.t.T[:, VTK_HEX_ORDER].astype(np.int32)
    sm = Mesh.from_data("block", coors, None, [conn], [np.zeros(len(conn), dtype=np.int32)], ["3_8"])
    domain = FEDomain("domain", sm)
    omega = domain.create_region("Omega", "all")
    zmin, zmax = coors[:, 2].min(), coors[:, 2].max()
    eps = 1e-8
    bottom = domain.create_region("Bottom", f"vertices in (z < {zmin + eps})", "facet")
    top = domain.create_region("Top", f"vertices in (z > {zmax - eps})", "facet")
    field = Field.from_args("displacement", np.float64, "vector", omega, approx_order=2)
    u = FieldVariable("u", "unknown", field)
    v = FieldVariable("v", "test", field, primary_var_name="u")
    m = SfMaterial("m", mu=MU, bulk=BULK)
    integral = Integral("i", order=DEFAULT_INTORDER)
    t1 = Term.new("dw_tl_he_neohook(m.mu, v, u)", integral, omega, m=m, v=v, u=u)
    t2 = Term.new("dw_tl_bulk_penalty(m.bulk, v, u)", integral, omega, m=m, v=v, u=u)
    eqs = Equations([Equation("balance", t1 + t2)])
    ebcs = Conditions([EssentialBC("fix", bottom, {"u.all": 0.0}),
                       EssentialBC("move", top, {"u.0": TOP_U[0], "u.1": TOP_U[1], "u.2": TOP_U[2]})])
    pb = SfProblem("bench", equations=eqs)
    pb.set_bcs(ebcs=ebcs)
    status = IndexedStruct()
    nls = Newton({"i_max": 30, "eps_a": 1e-10 * MU, "eps_r": 1e-10}, lin_solver=ScipyDirect({}),
                 status=status)
    pb.set_solver(nls)
    t0 = time.perf_counter()
    state = pb.solve(save_results=False)
    wall = time.perf_counter() - t0
    uv = state.get_state_parts()["u"].reshape(-1, 3) if hasattr(state, "get_state_parts") \
        else pb.get_variables()["u"]().reshape(-1, 3)
    n_it = max(int(status.nls_status.n_iter if hasattr(status, "nls_status") else status.n_iter), 1)
    stats = getattr(status.nls_status if hasattr(status, "nls_status") else status, "time_stats", {})
    return {"u": uv[:nv], "wall": wall, "iterations": n_it, "s_per_newton": wall / n_it,
            "time_stats": {k: float(v) for k, v in dict(stats).items()}}


#: the extra that installs the peer
PEER_EXTRA = "bench"


def peer_failure(exc: BaseException) -> str:
    """Why the peer gave no figures, in one line: not installed (naming the extra that installs
    it) or failed (its own error, e.g. sfepy's "warp violation" of an inverted element)."""
    if isinstance(exc, ImportError) and (exc.name or "").split(".")[0] == "sfepy":
        return f"sfepy is not installed (pip install 'skinkit[{PEER_EXTRA}]')"
    return f"sfepy failed: {type(exc).__name__}: {' '.join(str(exc).split())}"


def run(n: int = 7, linear: str = "auto", peer: Callable[[Any], dict] | None = None) -> dict:
    """Both solvers; the JSON-ready summary. ``peer`` solves the mesh (default: :func:`run_sfepy`).
    A peer that is not installed or fails leaves skinkit's figures, its own set to None and
    ``peer_error`` saying why."""
    sk = run_skinkit(n, linear)
    res = {"dof": sk["dof"], "elements": sk["mesh"].n_elements, "linear_solver": sk["linear"],
           "skinkit_s_per_newton": sk["s_per_newton"], "assembly_s": sk["assembly_s"],
           "solve_s": sk["solve_s"], "tangent_assembly_s": sk["tangent_assembly_s"],
           "skinkit_factorisations": sk["factorisations"], "skinkit_wall_s": sk["wall"],
           "peer_error": None, "sfepy_s_per_newton": None, "speedup": None, "max_rel_disp_diff": None,
           "sfepy_iterations": None, "sfepy_wall_s": None, "sfepy_time_stats": None}
    try:
        sf = (peer or run_sfepy)(sk["mesh"])
    except Exception as exc:   # the peer's own failure is a figure of the comparison, not skinkit's
        res["peer_error"] = peer_failure(exc)
        return res
    nv = sf["u"].shape[0]
    # vertices are the first nodes of a MeshHex2 in both numberings
    du = np.abs(sk["u"][:nv] - sf["u"])
    scale = float(np.abs(sf["u"]).max())
    res.update({"sfepy_s_per_newton": sf["s_per_newton"], "speedup": sf["s_per_newton"] / sk["s_per_newton"],
                "max_rel_disp_diff": float(du.max() / scale), "sfepy_iterations": sf["iterations"],
                "sfepy_wall_s": sf["wall"], "sfepy_time_stats": sf["time_stats"]})
    return res


def summary_lines(res: dict) -> list[str]:
    """The figures of :func:`run` as lines of text."""
    out = [f"{res['dof']} dofs, {res['elements']} 27-node hexahedra, "
           f"linear solver {res['linear_solver']}",
           f"skinkit {res['skinkit_s_per_newton']:.3f} s/iteration "
           f"(assembly {res['assembly_s']:.3f} s of which tangent {res['tangent_assembly_s']:.3f} s, "
           f"solve {res['solve_s']:.3f} s)"]
    if res.get("peer_error"):
        return [*out, f"sfepy   no figures: {res['peer_error']}"]
    return [*out, f"sfepy   {res['sfepy_s_per_newton']:.3f} s/iteration",
            f"speedup {res['speedup']:.2f}x; max relative displacement difference "
            f"{res['max_rel_disp_diff']:.2e}"]
