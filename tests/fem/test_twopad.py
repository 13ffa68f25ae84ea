"""The two-pad extension geometry: node sets, pad areas, element counts, a linear-limit solve."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit.fem.bcs import BoundaryConditions, Rigid
from skinkit.fem.errors import ModelError
from skinkit.fem.model import build_model, nodal_areas, read_model
from skinkit.fem.problem import Material, Problem
from skinkit.fem.solver import NewtonSolver, SolverOptions
from skinkit.fem.twopad import twopad_from_spec, twopad_mesh

# the laws, effects and optimisers these tests use are built-in plugins
pytestmark = pytest.mark.needs_plugins

LAYERS = (("skin", 0.0015, 1), ("subdermal", 0.0035, 1))


def test_default_mesh_size_and_sets():
    m = twopad_mesh()
    # 16 x 8 elements in plane (3 + 2 + 6 + 2 + 3 along x, 3 + 2 + 3 along y), 2 + 2 through
    assert m.n_elements == 16 * 8 * 4 and m.n_nodes == 33 * 17 * 9 <= 6000
    assert m.regions == ["skin", "subdermal"]
    x, y, z = m.nodes.T
    np.testing.assert_allclose([x.min(), x.max(), y.min(), y.max(), z.min(), z.max()],
                               [-0.05, 0.05, -0.025, 0.025, -0.005, 0.0], atol=1e-15)
    s = m.node_sets
    assert np.array_equal(s["indenter"], s["pad_moving"])
    for name, sign in (("pad_fixed", -1), ("pad_moving", 1)):
        p = m.nodes[s[name]]
        assert np.all(p[:, 2] == 0) and len(p) == 5 * 5          # 2 x 2 quadratic elements
        assert np.all(np.sign(p[:, 0]) == sign)
        np.testing.assert_allclose([np.abs(p[:, 0]).min(), np.abs(p[:, 0]).max()], [0.016, 0.024], atol=1e-15)
        np.testing.assert_allclose([p[:, 1].min(), p[:, 1].max()], [-0.004, 0.004], atol=1e-15)
    assert np.array_equal(np.sort(s["sides"]), np.unique(np.concatenate([s[k] for k in
                                                                         ("xmin", "xmax", "ymin", "ymax")])))
    # pad edges are element boundaries: every element is either wholly under a pad or not at all
    top = np.zeros(m.n_nodes, bool)
    top[s["pad_moving"]] = True
    el_top = m.elements[np.isclose(m.nodes[m.elements, 2].max(axis=1), 0.0)]
    n_in = top[el_top].sum(axis=1)
    # 0: away, 1: a shared corner, 3: a shared edge, 9: the whole top face under the pad
    assert set(np.unique(n_in)) == {0, 1, 3, 9} and np.sum(n_in == 9) == 4


def test_pad_area_and_grading():
    m = twopad_mesh(layers=LAYERS)
    for name in ("pad_fixed", "pad_moving"):
        # the facets under a pad: 64 mm^2 (exact for affine elements, to rounding)
        assert nodal_areas(m, m.node_sets[name]).sum() == pytest.approx(64e-6, rel=1e-12)
    xs = np.unique(m.nodes[m.elements[:, :8], 0])
    h = np.diff(xs)
    # finer next to the pads than at the far sides and mid-gap
    assert h[0] > 2 * h[2] and h[len(h) // 2] > h[5]


def test_spec_keys_and_errors():
    m = twopad_from_spec({"kind": "twopad", "size": ["80 mm", "40 mm"], "gap": "20 mm", "pad_size": "6 mm",
                          "n_gap": 4}, LAYERS)
    assert m.nodes[:, 0].max() == pytest.approx(0.04)
    assert nodal_areas(m, m.node_sets["pad_fixed"]).sum() == pytest.approx(36e-6, rel=1e-12)
    with pytest.raises(ModelError, match=r"geometry\.colour: unknown key"):
        twopad_from_spec({"kind": "twopad", "colour": 1}, LAYERS)
    with pytest.raises(ModelError, match=r"geometry\.gap.*inconsistent units"):
        twopad_from_spec({"gap": "3 kPa"}, LAYERS)
    with pytest.raises(ModelError, match=r"geometry\.n_gap"):
        twopad_from_spec({"n_gap": 0}, LAYERS)
    with pytest.raises(ModelError, match=r"geometry\.size"):
        twopad_from_spec({"size": ["40 mm", "50 mm"]}, LAYERS)


def _force(m, d):
    from skinkit import registry

    law = registry.create("skinkit.laws", "neo-hookean-enu")
    prob = Problem(m, [Material("skin", law, {"E": 2e4, "nu": 0.45}),
                       Material("subdermal", law, {"E": 2e3, "nu": 0.45})])
    s = m.node_sets
    bc = BoundaryConditions(m.n_dof).fix(s["pad_fixed"]).fix(s["bottom"])
    bc.rigid = Rigid(s["indenter"], "displacement", lambda t: np.array([d * t, 0.0, 0.0]))
    sol = NewtonSolver(prob, bc, SolverOptions(rtol=1e-10)).run([1.0])
    return sol.steps[-1].tip_force, sol.u[-1].reshape(-1, 3)


def test_linear_limit_and_symmetry():
    m = twopad_mesh(layers=LAYERS, n_gap=4, n_outer=2, n_side=2)
    d = 1e-6                                   # 1 um: strains ~1e-4, the linear limit
    f1, u1 = _force(m, d)
    f2, _ = _force(m, 2 * d)
    # pulling the pad along +x: the pad pulls the skin along +x
    assert f1[0] > 0
    # linear: doubling the displacement doubles the force up to the O(strain) nonlinearity
    assert f2[0] / f1[0] == pytest.approx(2.0, rel=1e-3)
    # the problem is symmetric under y -> -y: no y force, mirrored displacement field
    assert abs(f1[1]) < 1e-9 * f1[0]
    x = m.nodes
    key = {tuple(np.round(p * 1e9).astype(np.int64)): i for i, p in enumerate(x)}
    mirror = np.array([key[tuple(np.round(p * 1e9).astype(np.int64))] for p in x * [1, -1, 1]])
    scale = np.abs(u1).max()
    np.testing.assert_allclose(u1[mirror] * [1, -1, 1], u1, atol=1e-9 * scale)


def test_model_file_builds():
    from pathlib import Path

    spec = read_model(Path(__file__).resolve().parents[2] / "docs" / "models" / "extension_dic_twopad.toml")
    model = build_model(spec)
    # the example's graded mesh (its convergence study: tests/fem/test_examples_converged.py)
    # stays a model solved in seconds: under 50,000 unknowns
    assert model.mesh.n_dof <= 50_000 and model.bc.rigid.mode == "displacement"
    assert set(model.fixed_sets) == {"pad_fixed", "bottom", "sides"}
    assert nodal_areas(model.mesh, model.mesh.node_sets["indenter"]).sum() == pytest.approx(64e-6, rel=1e-12)
