"""Sensitivities without a tangent assembly at the converged states.

The sensitivity pass solves ``K du/dp = -∂r/∂p`` with the converged tangent ``K`` by conjugate
gradients preconditioned with the Newton loop's last factorisation and matrix-free products
``K v``. These tests check that the products are the assembled tangent's (to rounding), that
the sensitivities equal those of the direct solve (assemble and factorise ``K``) to far below
what a finite-difference check can see, and count operations: no tangent is assembled or
factorised for the sensitivities, so the forward solve follows exactly the path of a plain one.
"""

from __future__ import annotations

import numpy as np
import pytest

from skinkit import registry
from skinkit.fem import lawkit
from skinkit.fem.assembly import element_tangent_apply, first_elasticity
from skinkit.fem.bcs import BoundaryConditions, Rigid
from skinkit.fem.errors import ModelError
from skinkit.fem.mesh import block_mesh
from skinkit.fem.problem import Material, Problem
from skinkit.fem.sensitivity import HistorySensitivity, sensitivities
from skinkit.fem.solver import NewtonSolver, SolverOptions

# the laws, effects and optimisers these tests use are built-in plugins
pytestmark = pytest.mark.needs_plugins

L = 0.01
TIMES = [0.1, 0.2, 0.4, 0.7, 1.0]


def _case(mode: str):
    """Two layers: QLV (GOH, two Prony terms) skin with an in-plane pre-stretch over
    neo-Hookean tissue, a bonded indenter in ``mode`` with a drive parameter ``bias``."""
    mesh = block_mesh((L, L, 0.5 * L), (2, 2, 2), layers=[("skin", 0.2 * L, 1), ("sub", 0.3 * L, 1)])
    qlv = registry.create("skinkit.laws", "qlv", elastic="goh", terms=2)
    p = lawkit.default_parameters(qlv)
    p.update({"g1": 0.25, "g2": 0.15, "tau1": 0.3, "tau2": 3.0})
    sub = registry.create("skinkit.laws", "neo-hookean-enu")
    prob = Problem(mesh, [Material("skin", qlv, p, prestress=(1.05, 1.02, 0.3)),
                          Material("sub", sub, lawkit.default_parameters(sub))])
    s, x = mesh.node_sets, mesh.nodes
    top = s["top"]
    ind = top[np.hypot(x[top, 0] - L / 2, x[top, 1] - L / 2) <= 0.3 * L]
    bc = BoundaryConditions(mesh.n_dof).fix(s["bottom"]).fix(s["sides"])
    if mode == "force":
        prog, unit = (lambda t: np.array([0.1, 0.05, -1.0]) * 0.05 * min(t / 0.2, 1.0)), 1e-3
    else:
        prog, unit = (lambda t: np.array([1e-5, 0.0, -4e-4]) * min(t / 0.2, 1.0)), 1e-6
    bc.rigid = Rigid(ind, mode, prog, derivatives={"bias": lambda t: np.array([0.0, 0.0, unit * t])})
    return prob, bc


def _magnitude(prob: Problem, name: str) -> float:
    """A parameter's size, to normalise its derivatives (1 for stretches and the bias)."""
    region, _, local = name.partition(".")
    mats = {m.region: m for m in prob.materials}
    if region not in mats or local.startswith("prestretch"):
        return 1.0
    return abs(float(np.max(mats[region].params[local])))


def _run(mode: str, sens, method: str = "iterative"):
    prob, bc = _case(mode)
    solver = NewtonSolver(prob, bc, SolverOptions(rtol=1e-10, atol=1e-16))
    return solver, solver.run(TIMES, viscous_time=True, sensitivities=sens, sensitivity_method=method)


def test_matrix_free_products_are_the_assembled_tangent():
    """``element_tangent_apply`` with ``first_elasticity`` equals ``Kₑ uₑ`` of the element
    matrices, through pre-stretch and a viscous history (rounding only)."""
    solver, sol = _run("force", False)
    prob, g = solver.problem, solver.problem.geom
    u, dt = sol.u[-2], 0.3   # a trial step from the committed history: algorithmic tangent
    _, Ke = prob.evaluate(u, True, dt)
    lin = prob.linearise(u, dt)
    ue = np.random.default_rng(1).standard_normal((prob.n_dof, 3))[g.edofs]
    ref = np.einsum("eij,ejm->eim", Ke, ue)
    for k, (F, S, CC) in enumerate(lin):
        sl = prob.slices[k]
        got = element_tangent_apply(g.dNT[sl], first_elasticity(F, S, CC, g.w[sl]), ue[sl])
        assert np.abs(got - ref[sl]).max() <= 1e-12 * np.abs(ref[sl]).max()


@pytest.mark.parametrize("mode", ["force", "displacement"])
def test_iterative_sensitivities_equal_direct_ones_and_assemble_no_tangent(mode):
    names = ["skin.c", "skin.k1", "skin.g1", "skin.tau2", "skin.prestretch.l1", "sub.E", "bias"]
    s_plain, sol_plain = _run(mode, False)
    s_it, sol_it = _run(mode, names, "iterative")
    s_dir, sol_dir = _run(mode, names, "direct")
    n = s_plain.steps_taken   # increments (a step cut adds some to the output times)
    assert s_it.steps_taken == s_dir.steps_taken == n
    # the direct pass assembles and factorises the converged tangent at every increment; the
    # iterative one neither, so its Newton loop is exactly that of a plain solve
    assert sol_dir.extra["sensitivity_solves"]["factorisations"] == n
    st = sol_it.extra["sensitivity_solves"]
    assert st["factorisations"] == 0 and st["iterative"] == n
    assert st["iterations"] <= 6 * n
    assert s_it.timings.tangent_assemblies == s_plain.timings.tangent_assemblies
    assert s_it.timings.iterations == s_plain.timings.iterations
    assert np.array_equal(sol_it.u, sol_plain.u)   # the very same states, bit for bit
    assert np.abs(sol_it.u - sol_dir.u).max() <= 1e-9 * np.abs(sol_dir.u).max()
    # the same derivatives, normalised as the verification suite's checks (per relative change
    # of the parameter, over the largest response): the states differ by the Newton tolerance
    # (the direct run's predictor used its converged tangents) and the CG stops at an estimated
    # relative error of 1e-8 per column; 1e-8 is a thousandth of what those finite-difference
    # checks accept (SENS_TOL 1e-5)
    pscale = np.array([_magnitude(s_dir.problem, n) for n in names])
    tip_u = np.array([np.nan_to_num(st.tip_displacement) for st in sol_dir.steps])
    tip_f = np.array([st.tip_force for st in sol_dir.steps])
    for a, b in zip(sol_it.extra["sensitivities"], sol_dir.extra["sensitivities"], strict=True):
        assert a.names == b.names == names
        pairs = ((a.du, b.du, sol_dir.u), (a.tip_force, b.tip_force, tip_f),
                 (np.nan_to_num(a.tip_displacement), np.nan_to_num(b.tip_displacement), tip_u))
        for got, ref, response in pairs:
            err = np.abs(got - ref).max(axis=0) * pscale / np.abs(response).max()
            assert err.max() <= 1e-8, (names, err)


def test_reactions_on_request_and_the_tip_force_from_the_indenter_elements():
    solver, sol = _run("force", False)
    prob = solver.problem
    full = sensitivities(solver, sol.u[-1], TIMES[-1])   # static, every reaction
    lean = HistorySensitivity(solver).step(sol.u[-1], TIMES[-1], None)
    assert full.reaction is not None and full.reaction.shape == (prob.n_dof, len(full.names))
    assert lean.reaction is None
    from_full = full.reaction.reshape(-1, 3, len(full.names))[solver.dofmap.bc.rigid.nodes].sum(axis=0)
    scale = np.abs(from_full).max()
    assert np.abs(lean.tip_force - from_full).max() <= 1e-9 * scale
    assert np.abs(full.tip_force - from_full).max() <= 1e-12 * scale


def test_iterative_at_one_state_and_the_fallback_to_the_direct_solve():
    """At one state, preconditioned by the Newton loop's last factorisation (of a viscous
    step's tangent, so that the static tangent here takes a few iterations), the iterative
    solve gives the direct solve's derivatives within its error estimate, 1e-8. With no
    iteration allowed, the pass assembles and factorises the converged tangent and gets the
    direct answer; that factorisation is then held for the next increment."""
    solver, sol = _run("force", False)
    u, t = sol.u[-1], TIMES[-1]
    it = HistorySensitivity(solver)
    got_it = it.step(u, t, None)
    assert it.stats["iterative"] == 1 and it.stats["factorisations"] == 0
    tr = HistorySensitivity(solver, max_iter=0)
    got = tr.step(u, t, None)
    assert tr.stats["factorisations"] == 1 and tr.stats["iterative"] == 0
    ref = HistorySensitivity(solver, method="direct").step(u, t, None)
    scale = np.abs(ref.du).max(axis=0)
    assert np.all(np.abs(got_it.du - ref.du).max(axis=0) <= 1e-8 * scale)
    assert np.all(np.abs(got.du - ref.du).max(axis=0) <= 1e-12 * scale)
    assert solver.factored


def test_unknown_method_is_refused():
    solver, _ = _run("force", False)
    with pytest.raises(ModelError, match="method 'lu'"):
        HistorySensitivity(solver, method="lu")
