"""TOML model files, their validation errors, and the solve/verify/convergence commands."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.fem.errors import ModelError, SolverError
from skinkit.fem.model import build_model, read_model
from skinkit.fem.run import solve_model

pytestmark = pytest.mark.needs_plugins

MODELS = Path(__file__).resolve().parents[2] / "docs" / "models"


@pytest.mark.parametrize("path", sorted(MODELS.glob("*.toml")), ids=lambda p: p.stem)
def test_example_models_build(path):
    spec = read_model(path)
    if dict(spec.get("model", {})).get("kind") == "lumped":
        from skinkit.forward import load
        assert len(load(spec).parameters()) >= 2
        return
    m = build_model(spec, require_load="load" in spec)
    assert m.mesh.n_dof == 3 * _quadratic_hex_nodes(m.mesh)
    assert len(m.load.times) > 0


def test_block_mesh_dof_count_closed_form():
    """A block of nx x ny x nz quadratic hexahedra has (2nx+1)(2ny+1)(2nz+1) nodes, 3 DOFs each."""
    from skinkit.fem.mesh import block_mesh

    for n in [(1, 1, 1), (2, 3, 1), (3, 2, 4)]:
        mesh = block_mesh((1e-2, 2e-2, 3e-3), n)
        nodes = (2 * n[0] + 1) * (2 * n[1] + 1) * (2 * n[2] + 1)
        assert mesh.n_nodes == nodes == _quadratic_hex_nodes(mesh)
        assert mesh.n_dof == 3 * nodes


def _quadratic_hex_nodes(mesh) -> int:
    """Nodes of a conforming 27-node hexahedral mesh, counted from its corner topology: one per
    vertex, one per edge and one per face (each shared by the elements around it), and one
    inside each element. Checks on the way that every node belongs to an element and that an
    element's first 8 nodes are its corners."""
    from skfem import MeshHex

    t = mesh.t
    assert np.array_equal(mesh.elements[:, :8].T, t)
    assert np.array_equal(np.unique(mesh.elements), np.arange(mesh.n_nodes))  # no orphan node
    lin = MeshHex(mesh.nodes.T, t, validate=False)   # edges and faces of the corner mesh
    vertices, edges, faces, cells = np.unique(t).size, lin.edges.shape[1], lin.facets.shape[1], t.shape[1]
    assert cells == mesh.n_elements and mesh.elements.shape[1] == 27
    return vertices + edges + faces + cells


def test_invivo_model_has_its_documented_size():
    # the file's header: about 51,500 unknowns (the mesh that meets 5 % on the tip force)
    m = build_model(read_model(MODELS / "invivo_goh_qlv.toml"))
    assert 50_000 <= m.mesh.n_dof <= 53_000
    assert m.load.viscous_time and np.isclose(m.load.times[-1], 30.0)


def test_invivo_goh_qlv_coarse_protocol_runs():
    """The acceptance model on a coarse mesh and few steps: the viscous pipeline end to end."""
    from skinkit.fem.discretisation import pin_mesh
    spec = pin_mesh(read_model(MODELS / "invivo_goh_qlv.toml"), [1, 1], n_inner=1, n_ring=2, grading=1.6)
    spec["load"].update(periods=1, steps_per_period=6)
    model = build_model(spec)
    sol, info = solve_model(model)
    f = np.array([s["tip_force_N"][2] for s in info["steps"]])
    d = np.array([s["tip_displacement_m"][2] for s in info["steps"]])
    np.testing.assert_allclose(d[-1], 0.0, atol=1e-12)   # back to the start of the sinusoid
    # tip force = the force the indenter applies to the tissue: downwards while indenting
    assert f[2] < 0
    # viscoelastic hysteresis: at equal depth, less force on the way up (t = 6.67 s vs 3.33 s)
    assert np.isclose(d[1], d[3]) and abs(f[3]) < abs(f[1])


def _bad(mutate):
    spec = read_model(MODELS / "phantom_membrane_gel.toml")
    spec = copy.deepcopy(spec)
    mutate(spec)
    return spec


@pytest.mark.parametrize(("mutate", "message"), [
    (lambda s: s["layers"][0].update(law="no-such-law"), r"layers\[0\]\.law: no plugin 'no-such-law'"),
    (lambda s: s["layers"][0]["parameters"].pop("c2"), r"layers\[0\]\.parameters: missing parameter.*c2"),
    (lambda s: s["layers"][0]["parameters"].update(c1="40 mm"),
     r"layers\[0\]\.parameters\.c1: inconsistent units"),
    (lambda s: s["layers"][1]["parameters"].update(mu="-5 kPa"),
     r"layers\[1\]\.parameters\.mu.*outside its admissible range"),
    (lambda s: s["geometry"].update(kind="sphere"), r"geometry\.kind"),
    (lambda s: s["boundary"].update(fixed=["nowhere"]), r"boundary\.fixed: no node set 'nowhere'"),
    (lambda s: s.update(extra={}), r"unknown key"),
])
def test_invalid_models_name_the_entry(mutate, message):
    with pytest.raises(ModelError, match=message):
        build_model(_bad(mutate))


def test_goh_kappa_out_of_range():
    spec = read_model(MODELS / "invivo_goh_qlv.toml")
    spec["layers"][0]["parameters"]["kappa"] = 0.4
    with pytest.raises(ModelError, match=r"layers\[0\]\.parameters\.kappa.*\[0, 0\.333333\]"):
        build_model(spec)


def test_inverting_load_gives_up_with_load_and_reason():
    spec = _bad(lambda s: s["load"].update(value=["0 mm", "0 mm", "-12 mm"], steps=1))
    spec["solver"] = {"max_cuts": 2, "max_iter": 8}   # the report, not a long creep before it
    with pytest.raises(SolverError, match=r"gave up at load t = [0-9.]+ .*after 2 step cuts: .*"):
        solve_model(build_model(spec))


def test_cli_solve_writes_outputs(tmp_path):
    out = tmp_path / "res"
    r = CliRunner().invoke(cli, ["solve", str(MODELS / "phantom_membrane_gel.toml"), "--out", str(out),
                                 "--json"])
    assert r.exit_code == 0, r.output
    info = json.loads(r.stdout)
    assert info["dof"] > 0 and len(info["steps"]) == 2
    st = info["steps"][-1]
    assert st["tip_force_N"][2] < 0 and st["newton_iterations"] >= 1
    assert np.isclose(st["tip_displacement_m"][2], -0.0005)
    # embedded points and sensitivities requested by the example's [output] table
    assert len(st["points_m"]) == 3 and len(info["parameters"]) == 5
    assert np.array(st["d_points_m"]).shape == (3, 3, 5)
    # the point 0.1 mm under the indenter's centre stays on the axis (symmetry) and moves
    # down with the bonded indenter (0.5 mm), less the little the stiff membrane compresses
    np.testing.assert_allclose(st["points_m"][0][:2], [0.01, 0.01], atol=1e-12)
    assert -0.0001 - 0.00055 < st["points_m"][0][2] < -0.0001 - 0.00045
    # a stiffer gel needs more force for the same depth: d(force)/d(mu_gel) points down
    assert st["d_tip_force_N"][2][info["parameters"].index("gel.mu")] < 0
    with h5py.File(out / "result.h5") as f:
        assert f["displacement"].shape[0] == 2
        assert f["points"].shape == (2, 3, 3)
        assert f["sensitivity/displacement"].shape[2] == 5
    assert (out / "step.pvd").is_file() and (out / "step_0001.vtu").is_file()
    assert json.loads((out / "summary.json").read_text())["dof"] == info["dof"]


def test_cli_solve_bad_model_exits_2(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((MODELS / "phantom_membrane_gel.toml").read_text().replace('c1 = "40 kPa"', 'c1 = "40 s"'))
    r = CliRunner().invoke(cli, ["solve", str(bad)])
    assert r.exit_code == 2
    assert "error: layers[0].parameters.c1: inconsistent units" in r.output


def test_cli_verify_json():
    r = CliRunner().invoke(cli, ["verify", "--json", "--case", "patch-test", "--case", "qlv-relaxation"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.stdout)
    assert [c["name"] for c in res["cases"]] == ["patch-test", "qlv-relaxation"]
    assert all(c["passed"] and c["tolerance"] > 0 and "error" in c for c in res["cases"])


def test_cli_convergence(tmp_path):
    r = CliRunner().invoke(cli, ["convergence", str(MODELS / "phantom_membrane_gel.toml"), "--levels", "2",
                                 "--out", str(tmp_path), "--json"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.stdout)
    assert [x["level"] for x in res["levels"]] == [1, 2]
    assert res["levels"][1]["dof"] > res["levels"][0]["dof"]
    assert (tmp_path / "convergence.png").is_file()


@pytest.mark.parametrize("kind", ["block", "disc"])
def test_vtu_cells_have_positive_volume(kind):
    import pyvista as pv

    from skinkit.fem.mesh import block_mesh, disc_mesh
    from skinkit.fem.output import VTK_HEX_ORDER
    m = block_mesh((1, 1, 1), (2, 2, 2)) if kind == "block" else disc_mesh()
    nv = int(m.t.max()) + 1
    cells = np.hstack([np.full((m.t.shape[1], 1), 8), m.t.T[:, VTK_HEX_ORDER]]).ravel()
    grid = pv.UnstructuredGrid(cells, np.full(m.t.shape[1], pv.CellType.HEXAHEDRON), m.nodes[:nv])
    assert grid.compute_cell_sizes()["Volume"].min() > 0
