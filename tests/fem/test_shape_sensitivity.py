"""Shape sensitivities (a layer's thickness moving the mesh's reference nodes) against
differences: the internal force at fixed displacement against its own central differences in
the node positions, and the solved state's derivatives against central differences of whole
solves, elastic and viscoelastic (QLV with pre-stretch and fields by position and depth)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from skinkit.fem.assembly import full_vector
from skinkit.fem.model import build_mesh, build_model
from skinkit.fem.shape import DesignVelocity, internal_force_derivative
from skinkit.fem.solver import NewtonSolver

pytestmark = pytest.mark.needs_plugins

#: a small layered disc (one quadratic element per layer, 2,535 dofs): pre-stretched skin,
#: an inclusion in it and a band by depth below, so every term of the derivative is exercised
SPEC = {
    "model": {"name": "shape"},
    "geometry": {"kind": "disc", "diameter": "20 mm", "indenter_diameter": "4 mm", "n_inner": 2, "n_ring": 2},
    "layers": [
        {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "neo-hookean-ni",
         "parameters": {"mu": "15 kPa", "K": "500 kPa"},
         "prestress": {"stretch": [1.05, 1.02], "angle": "20 deg"}},
        {"name": "subdermal", "thickness": "3.5 mm", "elements": 1, "law": "neo-hookean-enu",
         "parameters": {"E": "10 kPa", "nu": 0.45}},
    ],
    "fields": [
        {"name": "inc", "kind": "inclusion", "layers": ["skin"], "x": "2 mm", "y": "1 mm", "radius": "2 mm",
         "ratio": 2.0},
        {"name": "band", "kind": "band", "layers": ["subdermal"], "depth": "2 mm", "half_width": "0.5 mm",
         "ratio": 0.5},
    ],
    "indenter": {"mode": "displacement"},
    "solver": {"rtol": 1e-12},
}
QLV = {"law": "qlv", "options": {"elastic": "neo-hookean-ni", "terms": 1},
       "parameters": {"mu": "15 kPa", "K": "500 kPa", "g1": 0.3, "tau1": "2 s"}}


def thicker(spec: dict, delta: float) -> dict:
    """The skin ``delta`` [m] thicker, the layer below as much thinner (the thickness effect)."""
    out = copy.deepcopy(spec)
    out["layers"][0]["thickness"] = 1.5e-3 + delta
    out["layers"][1]["thickness"] = 3.5e-3 - delta
    return out


def _depth(mesh) -> np.ndarray:
    return mesh.depth if mesh.depth is not None else mesh.nodes[:, 2].max() - mesh.nodes[:, 2]


def velocity(spec: dict) -> DesignVelocity:
    """dX/dδ from the meshes at δ = ±h: node positions are linear in the layer thicknesses, so the
    difference is exact to rounding (1e-16 m / 1e-7 m ~ 1e-9 relative)."""
    h = 1e-7
    up, dn = build_mesh(thicker(spec, h)), build_mesh(thicker(spec, -h))
    return DesignVelocity((up.nodes - dn.nodes) / (2 * h), (_depth(up) - _depth(dn)) / (2 * h))


def test_internal_force_derivative_is_the_difference_of_residuals_in_the_node_positions():
    """∂f_int/∂δ at a fixed (random, moderate) displacement against central differences of the
    internal force on meshes moved by ±h V (depth moved likewise), h = 1e-7 m: the truncation
    error ~(h/t)² ~ 1e-8, rounding ~1e-16 |f| / h ~ 1e-9; measured 5e-9 of the largest entry."""
    V = velocity(SPEC)
    model = build_model(SPEC, require_load=False)
    u = 2e-5 * np.random.default_rng(0).standard_normal(model.problem.n_dof)

    def force(t: float) -> np.ndarray:
        mesh = model.mesh.with_nodes(model.mesh.nodes + t * V.nodes)
        mesh.depth = _depth(model.mesh) + t * V.depth
        prob = build_model(SPEC, require_load=False, mesh=mesh).problem
        return full_vector(prob.geom.edofs, prob.evaluate(u, False)[0], prob.n_dof)

    h = 1e-7
    fd = (force(h) - force(-h)) / (2 * h)
    an = internal_force_derivative(model.problem, u, V)
    assert np.abs(an - fd).max() <= 1e-7 * np.abs(fd).max()


def _solve(spec: dict, viscous: bool, shapes: dict | None):
    model = build_model(spec, require_load=False)
    # an oblique push to its peak at t = 2 s and half-way back: loading, then unloading through
    # the viscous history
    model.bc.rigid.programme = lambda t: np.array([1.5e-4, 0.0, -5e-4]) * (t / 2 if t <= 2 else 1.5 - t / 4)
    solver = NewtonSolver(model.problem, model.bc, model.options)
    return solver.run([1.0, 2.0, 3.0], viscous_time=viscous, sensitivities=list(shapes or []) or False,
                      shapes=shapes)


@pytest.mark.parametrize("law", ["elastic", "qlv"])
def test_thickness_derivatives_match_central_differences_of_whole_solves(law):
    """du/dδ and the indenter's reaction force's derivative against central differences of whole
    solves at δ = ±H, H = 1e-6 m: truncation ~(H/t)² = 4e-7 relative (t = 1.5 mm), solver error
    ~rtol |f| / H ~ 1e-6 relative at most; tolerance 5e-6 of each quantity's largest entry
    (measured 4e-7 to 6e-7)."""
    spec = copy.deepcopy(SPEC)
    viscous = law == "qlv"
    if viscous:
        spec["layers"][0].update(copy.deepcopy(QLV))
    sol = _solve(spec, viscous, {"thickness": velocity(spec)})
    H = 1e-6
    up, dn = _solve(thicker(spec, H), viscous, None), _solve(thicker(spec, -H), viscous, None)
    for i, sv in enumerate(sol.extra["sensitivities"]):
        assert sv.names == ["thickness"]
        fd_u = (up.u[i] - dn.u[i]) / (2 * H)
        fd_f = (up.steps[i].tip_force - dn.steps[i].tip_force) / (2 * H)
        assert np.abs(sv.du[:, 0] - fd_u).max() <= 5e-6 * np.abs(fd_u).max(), i
        assert np.abs(sv.tip_force[:, 0] - fd_f).max() <= 5e-6 * np.abs(fd_f).max(), i
