"""Newton finishes an increment on its last factorisation (frozen-tangent steps).

Below ``FROZEN_RTOL`` of the reference force the solver steps with the tangent it last
factorised while each step cuts the residual ``FROZEN_GAIN``-fold. These tests count, from
the solver's timings, that a converged step then factorises fewer tangents than it takes
Newton steps; that the answer is full Newton's to the convergence tolerance; and that the
sensitivities (whose conjugate gradients are preconditioned by that older factorisation) are
unchanged. Full Newton is the same solver with ``FROZEN_RTOL = 0``: no residual is below it.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from skinkit import registry
from skinkit.fem import solver as solver_mod
from skinkit.fem.bcs import BoundaryConditions
from skinkit.fem.mesh import block_mesh
from skinkit.fem.problem import Material, Problem
from skinkit.fem.solver import NewtonSolver, SolverOptions
from tests.fem.test_sensitivity_speed import TIMES, _case, _magnitude

pytestmark = pytest.mark.needs_plugins

RTOL = 1e-10


def _block(monkeypatch, frozen: bool):
    """The block of ``skinkit bench fem`` (3^3 elements): sheared and compressed in one step."""
    if not frozen:
        monkeypatch.setattr(solver_mod, "FROZEN_RTOL", 0.0)
    mesh = block_mesh((1.0, 1.0, 1.0), (3, 3, 3))
    law = registry.create("skinkit.laws", "neo-hookean-ni")
    prob = Problem(mesh, [Material("body", law, {"mu": 1e4, "K": 1e5})])
    bc = BoundaryConditions(mesh.n_dof).fix(mesh.node_sets["bottom"])
    for c, v in enumerate((0.02, 0.0, -0.04)):
        bc.prescribe(mesh.node_sets["top"], c, lambda t, v=v: v * t)
    solver = NewtonSolver(prob, bc, SolverOptions(rtol=RTOL, linear="splu"))
    sol = solver.run([1.0])
    monkeypatch.undo()
    return solver, sol


def _newton_correction(solver: NewtonSolver, u: np.ndarray) -> float:
    """|K⁻¹ r(u)| [m] with the tangent at ``u``: to first order, how far ``u`` is from the solution."""
    r, K, _ = solver._residual(u, 1.0, None, True)
    return float(np.linalg.norm(spla.spsolve(K.tocsc(), r)))


def test_a_step_finishes_on_its_last_factorisation_with_full_newtons_answer(monkeypatch):
    fr_solver, fr = _block(monkeypatch, True)
    nw_solver, nw = _block(monkeypatch, False)
    ft, nt = fr_solver.timings, nw_solver.timings
    assert fr_solver.steps_taken == nw_solver.steps_taken == 1
    # full Newton factorises at every step; the frozen-tangent steps reuse the last one
    assert nt.back_substitutions == 0 and nt.factorisations == nt.iterations
    assert ft.back_substitutions >= 1
    assert ft.factorisations < ft.iterations and ft.factorisations < nt.factorisations
    # both met the same test, |r| <= rtol x reference force; each iterate is then within its
    # Newton correction K⁻¹ r of the exact solution (to second order), so the two differ by
    # at most the sum of their corrections: the convergence tolerance measured in metres
    bound = _newton_correction(fr_solver, fr.u[-1]) + _newton_correction(nw_solver, nw.u[-1])
    assert np.abs(fr.u[-1] - nw.u[-1]).max() <= 2 * bound
    assert bound <= 1e-8 * np.abs(nw.u[-1]).max()


@pytest.mark.parametrize("method", ["iterative", "direct"])
def test_sensitivities_are_unchanged_by_frozen_tangent_steps(monkeypatch, method):
    """Through a viscous history under displacement control, where frozen-tangent steps are
    taken: the derivatives equal full Newton's to the iterative solve's error estimate (1e-8
    per column, normalised as the verification suite's checks), and the direct pass, which
    factorises the converged tangent, to the states' difference (the Newton tolerance)."""
    names = ["skin.c", "skin.k1", "skin.g1", "skin.tau2", "skin.prestretch.l1", "sub.E", "bias"]
    runs = []
    for frozen in (True, False):
        if not frozen:
            monkeypatch.setattr(solver_mod, "FROZEN_RTOL", 0.0)
        prob, bc = _case("displacement")
        solver = NewtonSolver(prob, bc, SolverOptions(rtol=RTOL, atol=1e-16))
        runs.append((solver, solver.run(TIMES, viscous_time=True, sensitivities=names,
                                        sensitivity_method=method)))
        monkeypatch.undo()
    (fs, fsol), (ns, nsol) = runs
    assert fs.timings.back_substitutions > 0 and ns.timings.back_substitutions == 0
    assert fs.timings.factorisations < ns.timings.factorisations
    if method == "iterative":   # no tangent factorised for the sensitivities either way
        assert fsol.extra["sensitivity_solves"]["factorisations"] == 0
    assert np.abs(fsol.u - nsol.u).max() <= 1e-9 * np.abs(nsol.u).max()
    pscale = np.array([_magnitude(ns.problem, n) for n in names])
    tip_f = np.array([st.tip_force for st in nsol.steps])
    for a, b in zip(fsol.extra["sensitivities"], nsol.extra["sensitivities"], strict=True):
        for got, ref, response in ((a.du, b.du, nsol.u), (a.tip_force, b.tip_force, tip_f)):
            err = np.abs(got - ref).max(axis=0) * pscale / np.abs(response).max()
            assert err.max() <= 1e-8, (names, err)
