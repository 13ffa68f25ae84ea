"""``skinkit predict --vtu``: a PVD series per protocol on the full 27-node mesh, read back with
meshio and pyvista: the arrays and shapes, VTK's node order (each cell's volume as VTK computes
it equals the engine's), and the displacement exactly the solver's."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli as main
from tests.core._cli import extension_record

pytestmark = pytest.mark.needs_plugins

#: a small layered disc (50 elements, 1,815 unknowns): GOH fibres in a QLV skin over a
#: neo-Hookean layer, indented for one 10 s period (about 5 s per solve)
DISC = """
[model]
name = "vtu-disc"

[session]
protocols = ["normal_indentation"]
[session.parameters.normal_indentation]
periods = 1

[geometry]
kind = "disc"
diameter = "20 mm"
indenter_diameter = "4 mm"
n_inner = 1
n_ring = 2

[[layers]]
name = "skin"
thickness = "1.5 mm"
elements = 1
law = "qlv"
options = { elastic = "goh", terms = 1, elastic_options = { switch = "macaulay" } }
[layers.parameters]
c = "20 kPa"
k1 = "50 kPa"
k2 = 5.0
kappa = 0.1
gamma = "30 deg"
k = "500 kPa"
g1 = 0.3
tau1 = "2 s"

[[layers]]
name = "subdermal"
thickness = "3.5 mm"
elements = 1
law = "neo-hookean-enu"
[layers.parameters]
E = "8 kPa"
nu = 0.45

[indenter]
mode = "displacement"

[surface]
fit = "auto"
outside = "nearest"

[drive]
max_step = "1 s"
"""
ARRAYS = {"displacement": 3, "green_lagrange_strain": 9, "cauchy_stress": 9, "fibre_directions": 3,
          "fibre_directions_2": 3}


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    """The session, then ``predict --vtu`` in this process with the solver's solution and
    problem kept (the solver's own ``run`` wrapped)."""
    from skinkit.fem.solver import NewtonSolver

    d = tmp_path_factory.mktemp("vtu")
    (d / "m.toml").write_text(DISC)
    r = CliRunner().invoke(main, ["lab", "session", str(d / "m.toml"), "--out", str(d / "s.h5"),
                                  "--truth-out", str(d / "t.json"), "--seed", "1", "--shared-mesh"])
    assert r.exit_code == 0, r.output
    kept = {}
    run = NewtonSolver.run

    def keep(self, *a, **kw):
        kept["solution"] = sol = run(self, *a, **kw)
        kept["problem"] = self.problem
        return sol
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(NewtonSolver, "run", keep)
        r = CliRunner().invoke(main, ["predict", str(d / "m.toml"), str(d / "s.h5"), "--vtu", str(d / "v"),
                                      "--workers", "1", "--json"])
    assert r.exit_code == 0, r.output
    return d, json.loads(r.stdout), kept


def test_series_read_back_with_meshio(series):
    import meshio

    d, summary, kept = series
    pvd = d / "v" / "normal_indentation.pvd"
    assert summary["vtu"] == {"normal_indentation": str(pvd)}
    sol, problem = kept["solution"], kept["problem"]
    files = sorted((d / "v").glob("normal_indentation_*.vtu"))
    assert len(files) == len(sol.times) + 1      # the unloaded state, then every solved step
    n = problem.mesh.n_nodes
    for k, f in enumerate(files):
        m = meshio.read(f)
        assert [c.type for c in m.cells] == ["hexahedron27"] and m.cells[0].data.shape == (50, 27)
        assert {a: v.shape for a, v in m.point_data.items()} == {a: (n, c) for a, c in ARRAYS.items()}
        np.testing.assert_array_equal(m.points, problem.mesh.nodes)
        u = np.zeros((n, 3)) if k == 0 else sol.u[k - 1].reshape(-1, 3)
        np.testing.assert_array_equal(m.point_data["displacement"], u)     # the solver's, exactly
        sigma = m.point_data["cauchy_stress"].reshape(-1, 3, 3)
        assert np.allclose(sigma, np.swapaxes(sigma, 1, 2), rtol=0, atol=1e-9 * max(np.abs(sigma).max(), 1))
        if k == 0:   # the unloaded state: no strain, no stress
            assert np.abs(m.point_data["green_lagrange_strain"]).max() < 1e-12
            assert np.abs(sigma).max() < 1e-6
    last = meshio.read(files[-1]).point_data
    assert np.abs(last["cauchy_stress"]).max() > 100.0            # indented: stressed (Pa)
    fib = np.linalg.norm(last["fibre_directions"], axis=1)
    skin = problem.mesh.elements[problem.mesh.region == problem.mesh.regions.index("skin")]
    np.testing.assert_allclose(fib[np.unique(skin)], 1.0, rtol=1e-12)   # unit directions in the skin
    below = np.setdiff1d(np.arange(n), skin)
    assert below.size and np.all(fib[below] == 0)                 # none in the neo-Hookean layer


def test_stress_carries_the_viscous_history(series):
    """The skin's QLV stress at the last step is its total stress from the solver's committed
    history, not the elastic response at the same strain (at a sinusoid's end they differ)."""
    import meshio

    from skinkit.fem.vtu import point_data, total_stress

    d, _, kept = series
    sol, problem = kept["solution"], kept["problem"]
    u = sol.u[-1]
    skin = problem.mesh.region == problem.mesh.regions.index("skin")
    viscous, elastic = total_stress(problem, u, True), problem.stress_at(u)
    assert np.abs(viscous[skin] - elastic[skin]).max() > 0.01 * np.abs(viscous[skin]).max()
    np.testing.assert_array_equal(viscous[~skin], elastic[~skin])
    last = sorted((d / "v").glob("normal_indentation_*.vtu"))[-1]
    written = meshio.read(last).point_data["cauchy_stress"]
    np.testing.assert_allclose(written, point_data(problem, u, True)["cauchy_stress"], rtol=0,
                               atol=1e-9 * np.abs(written).max())


def _vtk_volumes(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, float]:
    """Each cell's volume [m³] and the smallest Jacobian determinant, from VTK's own triquadratic
    shape functions (``vtkTriQuadraticHexahedron.InterpolationDerivs``, in VTK's node order) at
    3 x 3 x 3 Gauss points: exact for these cells' polynomial Jacobians."""
    import vtk

    X = points[cells]                                # (n, 27, 3)
    cell = vtk.vtkTriQuadraticHexahedron()
    x, w = np.polynomial.legendre.leggauss(3)
    x, w = (x + 1) / 2, w / 2                        # VTK's parametric cube is [0, 1]³
    vol, det_min = np.zeros(len(X)), np.inf
    for i, j, k in np.ndindex(3, 3, 3):
        d = [0.0] * 81
        cell.InterpolationDerivs([x[i], x[j], x[k]], d)
        det = np.linalg.det(np.einsum("ra,eac->erc", np.reshape(d, (3, 27)), X))
        vol += w[i] * w[j] * w[k] * det
        det_min = min(det_min, float(det.min()))
    return vol, det_min


def test_series_read_back_with_pyvista_in_vtk_order(series):
    """Every cell's Jacobian, from VTK's shape functions in VTK's node order, is positive and its
    volume equals the engine's element volume (Σ quadrature weight x det J): a node out of VTK's
    order would change both. (VTK's cell-size filter splits a curved cell into linear pieces,
    so its volumes are not the comparison.)"""
    import pyvista as pv

    from skinkit.fem.vtu import VTK_TRIQUADRATIC_HEXAHEDRON

    d, _, kept = series
    sol, problem = kept["solution"], kept["problem"]
    reader = pv.PVDReader(str(d / "v" / "normal_indentation.pvd"))
    np.testing.assert_allclose(reader.time_values, np.concatenate([[0.0], sol.times]), rtol=1e-8)
    reader.set_active_time_point(len(reader.time_values) - 1)
    grid = reader.read()[0]
    assert set(grid.celltypes) == {VTK_TRIQUADRATIC_HEXAHEDRON}
    for a, c in ARRAYS.items():
        assert grid.point_data[a].shape == (problem.mesh.n_nodes, c)
    np.testing.assert_array_equal(grid.point_data["displacement"], sol.u[-1].reshape(-1, 3))
    vol, det_min = _vtk_volumes(np.asarray(grid.points), grid.cell_connectivity.reshape(-1, 27))
    engine = np.empty(problem.mesh.n_elements)
    engine[problem.order] = problem.geom.w.sum(axis=1)
    assert det_min > 0
    np.testing.assert_allclose(vol, engine, rtol=1e-10)


def test_vtu_refused_for_a_lumped_model(tmp_path):
    model = Path(__file__).resolve().parents[2] / "docs" / "models" / "extension_relaxation_lumped.toml"
    csv = extension_record(tmp_path / "r.csv", np.linspace(0.0, 5.0, 300))
    r = CliRunner().invoke(main, ["predict", str(model), str(csv), "--vtu", str(tmp_path / "v")])
    assert r.exit_code == 2 and "--vtu" in r.output and "lumped" in r.output
    assert not (tmp_path / "v").exists()
