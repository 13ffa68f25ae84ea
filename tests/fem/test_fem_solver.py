"""Solver behaviour: force control, step cutting, clear failures, mesh geometry."""

from __future__ import annotations

import re

import numpy as np
import pytest

from skinkit import registry
from skinkit.fem.assembly import geometry
from skinkit.fem.bcs import BoundaryConditions, Rigid
from skinkit.fem.errors import InvertedElementError, ModelError, SolverError
from skinkit.fem.mesh import block_mesh, disc_mesh
from skinkit.fem.problem import Material, Problem
from skinkit.fem.solver import NewtonSolver, SolverOptions

pytestmark = pytest.mark.needs_plugins


def _nh():
    return registry.create("skinkit.laws", "neo-hookean-ni")


def test_disc_mesh_geometry():
    m = disc_mesh()
    g = geometry(m)
    # the isoparametric quadratic map represents the circle to O(h^3) per edge; with
    # 9 edges per quarter rim the area error is below 1e-4 relative
    vol = np.pi * 0.02 ** 2 * 0.005
    assert abs(g.w.sum() - vol) <= 1e-4 * vol
    r = np.hypot(*m.nodes[m.node_sets["indenter"], :2].T)
    assert r.max() <= 0.002 * (1 + 1e-9) and m.node_sets["indenter"].size > 9
    assert m.regions == ["skin", "subdermal"]
    skin = m.region_elements("skin")
    assert np.all(m.nodes[m.elements[skin], 2] >= -0.0015 - 1e-12)


def _indent_problem(mode, value):
    m = disc_mesh(0.02, 0.004, layers=(("skin", 0.0015, 1), ("subdermal", 0.0035, 1)),
                  n_inner=2, n_ring=2)
    law = _nh()
    p = {"mu": 1e4, "K": 2e5}
    prob = Problem(m, [Material("skin", law, p), Material("subdermal", law, dict(p, mu=3e3))])
    bc = BoundaryConditions(m.n_dof).fix(m.node_sets["bottom"]).fix(m.node_sets["outer"])
    bc.rigid = Rigid(m.node_sets["indenter"], mode, lambda t: t * np.asarray(value))
    return prob, bc


def test_force_control_reproduces_displacement_control():
    prob, bc = _indent_problem("displacement", [0.0, 0.0, -0.0003])
    sd = NewtonSolver(prob, bc, SolverOptions(rtol=1e-10)).run([0.5, 1.0])
    F = sd.steps[-1].tip_force
    prob2, bc2 = _indent_problem("force", F)
    sf = NewtonSolver(prob2, bc2, SolverOptions(rtol=1e-10)).run([0.5, 1.0])
    # the same equilibrium reached from either side: agreement to the Newton tolerance,
    # amplified by the tangent's condition (1e-10 -> 1e-7 relative is generous)
    np.testing.assert_allclose(sf.steps[-1].tip_displacement, [0, 0, -0.0003], atol=3e-11 + 1e-7 * 3e-4)
    np.testing.assert_allclose(sf.u[-1], sd.u[-1], atol=1e-7 * 3e-4)


def test_a_tolerance_below_round_off_converges_at_the_floor():
    """A tolerance no arithmetic can meet (zero): Newton stops once its residual stops falling
    below 1e-6 of the reference force (the round-off floor) instead of cutting steps until it
    gives up; the state equals a normally converged one to that floor's effect (1e-6 of the
    reference force through the tangent: far below 1e-6 of the displacement)."""
    prob, bc = _indent_problem("displacement", [0.0, 0.0, -0.0003])
    normal = NewtonSolver(prob, bc, SolverOptions(rtol=1e-10)).run([0.5, 1.0])
    prob2, bc2 = _indent_problem("displacement", [0.0, 0.0, -0.0003])
    floor = NewtonSolver(prob2, bc2, SolverOptions(rtol=0.0, atol=0.0)).run([0.5, 1.0])
    np.testing.assert_allclose(floor.u[-1], normal.u[-1], atol=1e-6 * 3e-4)


def test_inverting_load_is_cut_then_reported():
    prob, bc = _indent_problem("displacement", [0.0, 0.0, -0.02])  # 4x the thickness
    # 8 iterations per increment: with the default 20 the cut steps creep on to a quarter of the
    # load through hundreds of iterations before the same report (the reporting is what is tested)
    with pytest.raises(SolverError, match=r"gave up at load t = .* after 3 step cuts"):
        NewtonSolver(prob, bc, SolverOptions(max_cuts=3, max_iter=8)).run([1.0])


def test_a_failed_increment_says_where_the_body_is_out_of_balance():
    """The report names the node with the largest unbalance and its layer: for a punch pushed
    to 4x the skin's thickness it is at the punch's bonded edge (radius 2 mm), where the strain
    concentrates, within one element (1 mm) of it."""
    prob, bc = _indent_problem("displacement", [0.0, 0.0, -0.02])
    with pytest.raises(SolverError) as info:
        NewtonSolver(prob, bc, SolverOptions(max_cuts=3, max_iter=8)).run([1.0])
    m = re.search(r"largest unbalance \S+ N at \((\S+), (\S+), (\S+)\) mm \((skin|subdermal)",
                  str(info.value))
    assert m, str(info.value)
    x, y = float(m.group(1)), float(m.group(2))
    assert abs(np.hypot(x, y) - 2.0) <= 1.0


def test_a_newton_that_stops_making_progress_gives_up_early(monkeypatch):
    """Past what the mesh can carry (a punch pushed to 4x the skin's thickness), an increment whose
    residual stops halving is given up after STAGNANT_ITERS iterations instead of the whole
    max_iter: the solve fails at the same load as when every increment spends its 20 iterations,
    with fewer Newton iterations, and says that the residual stopped falling."""
    from skinkit.fem import solver as solver_mod

    def attempt():
        prob, bc = _indent_problem("displacement", [0.0, 0.0, -0.02])
        s = NewtonSolver(prob, bc, SolverOptions(max_cuts=3))
        with pytest.raises(SolverError) as info:
            s.run([1.0])
        return s.timings.iterations, str(info.value)

    its_rule, msg_rule = attempt()
    window = solver_mod.STAGNANT_ITERS
    monkeypatch.setattr(solver_mod, "STAGNANT_ITERS", 10**6)   # the rule off: max_iter alone
    its_all, msg_all = attempt()
    where = r"gave up at load t = (\S+) "
    assert re.search(where, msg_rule).group(1) == re.search(where, msg_all).group(1)
    assert its_rule < its_all
    assert f"did not halve in {window} Newton iterations" in msg_rule


def test_an_indefinite_tangent_is_named_as_the_reason():
    from skinkit.fem.solver import _why
    assert _why(0, 20) == "" and _why(4, 20) == ""
    assert "tangent was indefinite" in _why(5, 20) and "5 of 20" in _why(5, 20)


def test_step_cutting_recovers():
    """A load too large for one increment converges after cuts (the history shows it)."""
    m = block_mesh((0.01, 0.01, 0.01), (2, 2, 2))
    prob = Problem(m, [Material("body", _nh(), {"mu": 1e4, "K": 1e6})])
    s = m.node_sets
    bc = BoundaryConditions(m.n_dof).fix(s["bottom"]).prescribe(s["top"], 2, lambda t: -0.006 * t)
    sol = NewtonSolver(prob, bc, SolverOptions(max_iter=6)).run([1.0])
    assert sol.timings.iterations > 6
    assert np.isclose(sol.u[-1].reshape(-1, 3)[s["top"], 2], -0.006).all()


def test_an_extrapolated_start_that_inverts_an_element_falls_back_to_the_predictor():
    """An extrapolation that overshoots (here: a guess of random centimetres) costs
    the increment its start, not a cut: the tangent predictor takes over and Newton converges
    to the equilibrium it reaches without a guess."""
    prob, bc = _indent_problem("displacement", [0.0, 0.0, -0.0003])
    solver = NewtonSolver(prob, bc, SolverOptions(rtol=1e-10))
    u0 = np.zeros(prob.n_dof)
    plain, _, _ = solver.increment(u0, 1.0, None)
    # a centimetre of random motion per node on millimetre elements: many invert
    wild = 0.01 * np.random.default_rng(0).standard_normal(prob.n_dof)
    with pytest.raises(InvertedElementError):
        prob.evaluate(wild, False, None)
    u, its, _ = solver.increment(u0, 1.0, None, guess=wild)
    # the same equilibrium to the Newton tolerance, amplified by the tangent's condition
    np.testing.assert_allclose(u, plain, atol=1e-7 * 3e-4)
    assert its >= 1


def test_inverted_element_error_names_the_element():
    m = block_mesh((1, 1, 1), (1, 1, 1))
    prob = Problem(m, [Material("body", _nh(), {"mu": 1.0, "K": 10.0})])
    u = np.zeros(m.n_dof)
    u[2::3] = -2.0 * (m.nodes[:, 2] + 1)  # flips the element through its floor
    with pytest.raises(InvertedElementError, match="element 0 is inverted"):
        prob.evaluate(u)


def test_material_errors():
    m = block_mesh()
    with pytest.raises(ModelError, match="region 'body' needs exactly one material"):
        Problem(m, [])
    with pytest.raises(ModelError, match=r"materials\[body\]\.mu.*outside"):
        Problem(m, [Material("body", _nh(), {"mu": -1.0, "K": 1.0})])


@pytest.mark.parametrize("linear", ["splu", "auto"])
def test_linear_solvers_agree(linear):
    m = block_mesh((1, 1, 1), (2, 2, 2))
    prob = Problem(m, [Material("body", _nh(), {"mu": 1.0, "K": 20.0})])
    s = m.node_sets
    bc = BoundaryConditions(m.n_dof).fix(s["bottom"])
    bc.prescribe(s["top"], 0, lambda t: 0.1 * t).prescribe(s["top"], 2, lambda t: -0.1 * t)
    u_ref = NewtonSolver(prob, bc, SolverOptions(linear="splu", rtol=1e-12)).run([1.0]).u[-1]
    u = NewtonSolver(prob, bc, SolverOptions(linear=linear, rtol=1e-12)).run([1.0]).u[-1]
    # two direct solvers on the same converged Newton problem: rounding-level agreement
    np.testing.assert_allclose(u, u_ref, atol=1e-10)


def _block_tangent(n: int):
    """A PARDISO Newton solver on an n x n x n block held at top and bottom, and its tangent at
    rest (upper triangle)."""
    m = block_mesh((1, 1, 1), (n, n, n))
    prob = Problem(m, [Material("body", _nh(), {"mu": 1.0, "K": 20.0})])
    bc = BoundaryConditions(m.n_dof).fix(m.node_sets["bottom"]).fix(m.node_sets["top"])
    solver = NewtonSolver(prob, bc, SolverOptions(linear="pardiso"))
    _, Ke = prob.evaluate(np.zeros(m.n_dof))
    return solver, solver.pattern.matrix(Ke)


def test_pardiso_on_two_threads_solves_as_on_one():
    """A protocol solved alone may give PARDISO the idle cores: the same solution to rounding
    (the factorisation's sums in another order), and the count is fixed once analysed (PARDISO
    crashes when its phases run with different counts)."""
    from threadpoolctl import threadpool_limits

    from skinkit.fem import linsolve
    from skinkit.fem.errors import SolverError
    if "pardiso" not in linsolve.available():
        pytest.skip("pypardiso not installed")
    _, K = _block_tangent(6)
    b = np.random.default_rng(0).normal(size=(K.shape[0], 3))
    x = {}
    with threadpool_limits(limits=1):      # as inside a solve: the thread count is the solver's own
        for n in (1, 2):
            lin = linsolve.make("pardiso")
            lin.use_threads(n)
            lin.factor(K)
            x[n] = lin.solve(b)
            with pytest.raises(SolverError, match="fixed"):
                lin.use_threads(3 - n)
            lin.free()
    np.testing.assert_allclose(x[2], x[1], rtol=1e-10, atol=1e-12 * np.abs(x[1]).max())


def test_pardiso_survives_a_thread_limit_between_phases():
    """PARDISO crashed (segfault) when a factorisation ran under a BLAS thread limit after
    an analysis without one; the solver pins its thread count."""
    from skinkit.fem import linsolve
    from skinkit.fem.threads import single_threaded_blas
    if "pardiso" not in linsolve.available():
        pytest.skip("pypardiso not installed")
    solver, K = _block_tangent(5)
    b = np.random.default_rng(0).normal(size=K.shape[0])
    solver.linear.factor(K)
    x1 = solver.linear.solve(b)
    with single_threaded_blas():
        solver.linear.factor(K)
        x2 = solver.linear.solve(b)
    np.testing.assert_allclose(x2, x1, rtol=1e-10, atol=1e-12 * np.abs(x1).max())
