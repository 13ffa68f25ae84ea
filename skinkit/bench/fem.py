"""``skinkit bench fem``: skinkit's Newton iteration against its peers' on the same problem.

The same block of 27-node hexahedra (n x n x n elements; 7 -> 10,125 dofs), the same nearly
incompressible neo-Hookean law W = μ/2 (Ī1 - 3) + K/2 (J - 1)² (sfepy's ``dw_tl_he_neohook`` +
``dw_tl_bulk_penalty``), the same boundary conditions (floor fixed, top face moved by a shear
and a compression), the same quadrature degree, one load step, total Lagrangian. The peers:

* ``sfepy`` (Python/NumPy assembly, SciPy's direct solver; ``approx_order=2`` on the linear mesh);
* ``ngsolve`` (C++ assembly of the energy's second derivative, order-2 ``VectorH1`` on the same
  hexahedra, its own sparse LDLᵀ; :mod:`skinkit.bench.fem_ngsolve`).

Both are in the ``bench`` extra. Every code runs in this process, skinkit first at every size
and then the peers, so that no peer's libraries are loaded while skinkit is timed. sfepy's
failure on a larger block (an inverted element: "warp violation") is a Python ``ValueError``
raised by its C terms, not a process abort, so it is caught and reported beside skinkit's
figures like any other peer failure.

Seconds per step = solve wall time / converged load steps (one here, for every code): the
figure to compare, since skinkit finishes Newton with back-substitutions on its last
factorisation (frozen-tangent steps) where the peers factorise at every iteration. Seconds per
Newton iteration = solve wall time / number of tangent factorisations (the tangent predictor's
and each factorised Newton iteration's; skinkit's back-substitutions ride on them);
``assembly_s`` is all of skinkit's assembly per factorisation (the tangent and the residuals
of the line search and of the frozen-tangent steps), ``tangent_assembly_s`` one tangent
assembly (skinkit's element pass yields the residual with it; sfepy's ``matrix`` and
NGSolve's ``AssembleLinearization`` are the tangent alone), ``solve_s`` one factorisation +
its solves.
"""

from __future__ import annotations

import contextlib
import io
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
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
    n_fact = tm.factorisations  # the tangent predictor's and each factorised Newton iteration's
    steps = max(solver.steps_taken, 1)   # converged increments (more than one if a step was cut)
    return {"n": n, "mesh": mesh, "u": sol.u[-1].reshape(-1, 3), "wall": wall, "setup": setup,
            "factorisations": n_fact, "assembly_s": tm.assembly / n_fact, "solve_s": tm.solve / n_fact,
            "tangent_assembly_s": tm.tangent / max(tm.tangent_assemblies, 1),
            "s_per_newton": wall / n_fact, "dof": mesh.n_dof, "linear": solver.linear.name,
            "steps": steps, "s_per_step": wall / steps, "factorisations_per_step": n_fact / steps,
            "iterations": tm.iterations, "back_substitutions": tm.back_substitutions}


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
    ts = {k: float(v) for k, v in dict(stats).items()}
    # each Newton iteration assembles the tangent ("matrix") and factorises it (ScipyDirect)
    return {"u": uv[:nv], "wall": wall, "iterations": n_it, "s_per_newton": wall / n_it,
            "time_stats": ts, "factorisations": n_it,
            "tangent_assembly_s": ts["matrix"] / n_it if "matrix" in ts else None,
            "solve_s": ts["solve"] / n_it if "solve" in ts else None}


def run_ngsolve(mesh) -> dict:
    """Solve the same problem with NGSolve (:func:`skinkit.bench.fem_ngsolve.run_ngsolve`)."""
    from skinkit.bench.fem_ngsolve import run_ngsolve as solve

    return solve(mesh, MU, BULK, TOP_U)


#: the extra that installs the peers
PEER_EXTRA = "bench"


@dataclass(frozen=True)
class Peer:
    """A code compared with skinkit: ``modules`` whose absence means it is not installed,
    ``extra`` the skinkit extra that installs it, ``runner`` the name of this module's function
    that solves a mesh (looked up when the peer runs)."""

    name: str
    modules: tuple[str, ...]
    extra: str
    runner: str


PEERS = {"sfepy": Peer("sfepy", ("sfepy",), PEER_EXTRA, "run_sfepy"),
         "ngsolve": Peer("ngsolve", ("ngsolve", "netgen"), PEER_EXTRA, "run_ngsolve")}
#: the figures a peer's entry carries (None where it gave none)
PEER_KEYS = ("s_per_newton", "tangent_assembly_s", "solve_s", "factorisations", "wall_s",
             "max_rel_disp_diff", "ratio_s_per_newton", "ratio_tangent_assembly", "s_per_step",
             "ratio_s_per_step")
#: keys of a row that are sfepy's in the first form of the JSON (kept for the tools reading it)
_SFEPY_LEGACY = ("sfepy_s_per_newton", "speedup", "max_rel_disp_diff", "sfepy_iterations",
                 "sfepy_wall_s", "sfepy_time_stats")


def peer_failure(exc: BaseException, name: str = "sfepy") -> str:
    """Why the peer ``name`` gave no figures, in one line: not installed (naming the extra that
    installs it) or failed (its own error, e.g. sfepy's "warp violation" of an inverted element)."""
    peer = PEERS.get(name, Peer(name, (name,), PEER_EXTRA, ""))
    if isinstance(exc, ImportError) and (exc.name or "").split(".")[0] in peer.modules:
        return f"{name} is not installed (pip install 'skinkit[{peer.extra}]')"
    return f"{name} failed: {type(exc).__name__}: {' '.join(str(exc).split())}"


def _ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or not b else a / b


def _peer_entry(name: str, sk: dict, runner: Callable[[Any], dict],
                repeat: int = 1) -> tuple[dict, dict | None]:
    """Run one peer on skinkit's mesh (``repeat`` times, the fastest kept): its entry of
    ``peers`` and its raw output (None when it gave no figures). A peer solves the one load
    step, so its seconds per step are its wall time [s]."""
    entry: dict[str, Any] = {"status": "ok", "error": None, "extra": PEERS[name].extra if name in PEERS
                             else PEER_EXTRA, **dict.fromkeys(PEER_KEYS)}
    try:
        out = min((runner(sk["mesh"]) for _ in range(repeat)), key=lambda o: o["wall"])
    except Exception as exc:   # the peer's own failure is a figure of the comparison, not skinkit's
        missing = isinstance(exc, ImportError) and "not installed" in peer_failure(exc, name)
        entry.update(status="not installed" if missing else "failed", error=peer_failure(exc, name))
        return entry, None
    nv = out["u"].shape[0]
    # vertices are the first nodes of a MeshHex2 and the first vertices of the peers' meshes
    du = np.abs(sk["u"][:nv] - out["u"])
    entry.update({"s_per_newton": out["s_per_newton"], "tangent_assembly_s": out.get("tangent_assembly_s"),
                  "solve_s": out.get("solve_s"), "factorisations": out.get("factorisations"),
                  "wall_s": out["wall"], "max_rel_disp_diff": float(du.max() / np.abs(out["u"]).max()),
                  "ratio_s_per_newton": _ratio(out["s_per_newton"], sk["s_per_newton"]),
                  "ratio_tangent_assembly": _ratio(out.get("tangent_assembly_s"), sk["tangent_assembly_s"]),
                  "s_per_step": out["wall"], "ratio_s_per_step": _ratio(out["wall"], sk["s_per_step"])})
    entry.update({k: out[k] for k in ("setup_s", "residuals", "inverse", "assembly", "version") if k in out})
    return entry, out


def compare(sk: dict, peers: Sequence[str] = tuple(PEERS),
            runners: Mapping[str, Callable[[Any], dict]] | None = None, repeat: int = 1) -> dict:
    """One size's row: skinkit's figures (``sk`` from :func:`run_skinkit`) and each of ``peers``
    run on the same mesh. ``runners`` replaces a peer's solver (default: this module's
    ``run_sfepy`` / ``run_ngsolve``); each peer runs ``repeat`` times, its fastest run kept.
    ``peers`` maps each name to its entry (``status``: ok, not installed, failed; ``error``;
    the figures of :data:`PEER_KEYS`, ratios peer / skinkit); the sfepy keys of the first form
    of this JSON stay, ``peer_error`` saying why sfepy has none."""
    res = {"n": sk["n"], "dof": sk["dof"], "elements": sk["mesh"].n_elements, "linear_solver": sk["linear"],
           "skinkit_s_per_newton": sk["s_per_newton"], "assembly_s": sk["assembly_s"],
           "solve_s": sk["solve_s"], "tangent_assembly_s": sk["tangent_assembly_s"],
           "skinkit_factorisations": sk["factorisations"], "skinkit_wall_s": sk["wall"],
           "skinkit_s_per_step": sk["s_per_step"], "skinkit_steps": sk["steps"],
           "skinkit_factorisations_per_step": sk["factorisations_per_step"],
           "skinkit_iterations": sk["iterations"], "skinkit_back_substitutions": sk["back_substitutions"],
           "peer_error": "sfepy was not run (not among the peers asked for)",
           **dict.fromkeys(_SFEPY_LEGACY), "peers": {}}
    for name in peers:
        runner = (runners or {}).get(name) or globals()[PEERS[name].runner]
        entry, out = _peer_entry(name, sk, runner, repeat)
        res["peers"][name] = entry
        if name == "sfepy":
            res["peer_error"] = entry["error"]
            if out is not None:
                res.update({"sfepy_s_per_newton": entry["s_per_newton"],
                            "speedup": entry["ratio_s_per_newton"],
                            "max_rel_disp_diff": entry["max_rel_disp_diff"],
                            "sfepy_iterations": out.get("iterations"), "sfepy_wall_s": out["wall"],
                            "sfepy_time_stats": out.get("time_stats")})
    return res


def run(n: int = 7, linear: str = "auto", peers: Sequence[str] = tuple(PEERS),
        runners: Mapping[str, Callable[[Any], dict]] | None = None) -> dict:
    """skinkit and ``peers`` on the n x n x n block; the JSON-ready row of :func:`compare`."""
    return compare(run_skinkit(n, linear), peers, runners)


def run_sizes(sizes: Sequence[int], linear: str = "auto", peers: Sequence[str] = tuple(PEERS),
              runners: Mapping[str, Callable[[Any], dict]] | None = None, repeat: int = 1) -> dict:
    """Every size in ``sizes``: skinkit at all of them first, then the peers, each code
    ``repeat`` times with its fastest run kept (a shared machine's load only
    slows a run down). Returns the first size's row (the keys of a one-size run) with ``sizes``,
    every size's row in order, ``repeat``, and ``threads``, the thread-count variables of the
    environment it ran in."""
    runs = [min((run_skinkit(n, linear) for _ in range(repeat)), key=lambda r: r["wall"])
            for n in sizes]
    rows = [compare(sk, peers, runners, repeat) for sk in runs]
    env = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
    return {**rows[0], "sizes": rows, "repeat": repeat, "threads": {k: os.environ.get(k) for k in env}}


def _fmt(x: float | None, spec: str = ".3f") -> str:
    return "-" if x is None else format(x, spec)


def summary_lines(res: dict) -> list[str]:
    """The figures of :func:`run` or :func:`run_sizes` as lines of text, a block per size."""
    out: list[str] = []
    for row in res.get("sizes", [res]):
        out += [f"n = {row.get('n', '?')}: {row['dof']} dofs, {row['elements']} 27-node hexahedra, "
                f"linear solver {row['linear_solver']}",
                f"skinkit {_fmt(row.get('skinkit_s_per_step'))} s/step, "
                f"{_fmt(row.get('skinkit_factorisations_per_step'), 'g')} factorisations + "
                f"{_fmt(row.get('skinkit_back_substitutions'), 'g')} back-substitutions; "
                f"{row['skinkit_s_per_newton']:.3f} s/iteration "
                f"(per factorisation: assembly {row['assembly_s']:.3f} s of which tangent "
                f"{row['tangent_assembly_s']:.3f} s, "
                f"solve {row['solve_s']:.3f} s)"]
        for name, p in row.get("peers", {}).items():
            if p["status"] != "ok":
                out.append(f"{name:<7} no figures: {p['error']}")
                continue
            out.append(f"{name:<7} {_fmt(p.get('s_per_step'))} s/step "
                       f"({_fmt(p.get('ratio_s_per_step'), '.2f')}x skinkit's); "
                       f"{p['s_per_newton']:.3f} s/iteration "
                       f"({_fmt(p['ratio_s_per_newton'], '.2f')}x skinkit's; tangent "
                       f"{_fmt(p['tangent_assembly_s'])} s, {_fmt(p['ratio_tangent_assembly'], '.2f')}x "
                       f"skinkit's; solve {_fmt(p['solve_s'])} s), {p['factorisations']} factorisations; "
                       f"max relative displacement difference {p['max_rel_disp_diff']:.1e}")
    if res.get("threads"):
        out.append("threads: " + ", ".join(f"{k}={v or 'unset'}" for k, v in res["threads"].items())
                   + " (NGSolve: one thread, its task manager off)")
    return out


#: the columns of :func:`table_rows`
COLUMNS = ("n", "dofs", "code", "s/step", "x skinkit (step)", "s/iteration", "x skinkit", "tangent s",
           "x skinkit (tangent)", "solve s", "factorisations", "back-substitutions",
           "max rel. disp. diff.", "note")


def table_rows(res: dict) -> list[list[str]]:
    """The figures as table cells (:data:`COLUMNS`), a row per size and code."""
    rows = []
    for row in res.get("sizes", [res]):
        head = [str(row.get("n", "?")), str(row["dof"])]
        rows.append([*head, "skinkit", _fmt(row.get("skinkit_s_per_step")), "1",
                     _fmt(row["skinkit_s_per_newton"]), "1",
                     _fmt(row["tangent_assembly_s"]), "1", _fmt(row["solve_s"]),
                     str(row["skinkit_factorisations"]), _fmt(row.get("skinkit_back_substitutions"), "g"),
                     "-", f"linear solver {row['linear_solver']}"])
        for name, p in row.get("peers", {}).items():
            rows.append([*head, name, _fmt(p.get("s_per_step")), _fmt(p.get("ratio_s_per_step"), ".2f"),
                         _fmt(p["s_per_newton"]), _fmt(p["ratio_s_per_newton"], ".2f"),
                         _fmt(p["tangent_assembly_s"]), _fmt(p["ratio_tangent_assembly"], ".2f"),
                         _fmt(p["solve_s"]), "-" if p["factorisations"] is None else str(p["factorisations"]),
                         "-", _fmt(p["max_rel_disp_diff"], ".1e"), p["error"] or p.get("assembly", "")])
    return rows
