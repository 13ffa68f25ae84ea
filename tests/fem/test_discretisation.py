"""Discretisation error: Richardson extrapolation, refined model descriptions,
the estimate in ``skinkit convergence`` / ``skinkit solve``, ``[solver] discretisation_tolerance``,
the grading keys, and the example meshes meeting 5 % on the tip force at their documented loads."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.fem.discretisation import refined_spec, richardson
from skinkit.fem.errors import ModelError
from skinkit.fem.model import build_mesh, estimate_size, layer_table, read_model

# the laws, effects and optimisers these tests use are built-in plugins
pytestmark = pytest.mark.needs_plugins

MODELS = Path(__file__).resolve().parents[2] / "docs" / "models"

#: a small disc (7 x 7 elements, 2 layers of 1 element: ~1,200 unknowns) indented 0.3 mm in
#: one static step, with two tracked surface points: cheap enough to refine 3x in a test
TINY = """
[model]
name = "tiny"
[geometry]
kind = "disc"
n_inner = 1
n_ring = 2
grading = 2.5
inner_grading = 1.5
layer_grading = 1.5
[[layers]]
name = "skin"
thickness = "1.5 mm"
elements = 1
law = "neo-hookean-ni"
[layers.parameters]
mu = "15 kPa"
K = "500 kPa"
[[layers]]
name = "subdermal"
thickness = "3.5 mm"
elements = 1
law = "neo-hookean-enu"
[layers.parameters]
E = "10 kPa"
nu = 0.45
[indenter]
mode = "displacement"
[load]
kind = "ramp"
value = ["0 mm", "0 mm", "-0.3 mm"]
steps = 1
[output]
points = [["4 mm", "0 mm", "0 mm"], ["0 mm", "6 mm", "0 mm"]]
"""


def _tiny(tmp_path: Path, solver: str = "") -> Path:
    p = tmp_path / "tiny.toml"
    p.write_text(TINY + (f"[solver]\n{solver}\n" if solver else ""))
    return p


# --- Richardson -------------------------------------------------------------------------------

@pytest.mark.parametrize("factors", [[1, 2, 4], [1, 2, 3], [2, 3, 5]])
@pytest.mark.parametrize("p", [1.3, 2.0, 3.0])
def test_richardson_recovers_order_and_limit_exactly(factors, p):
    # v(h) = v* + C h^p is what Richardson assumes: the order and the limit come back to
    # rounding (a constant ratio in closed form, any other by bisection on p)
    vstar, C = 0.0561, 0.04
    vals = [vstar + C * (1.0 / f) ** p for f in factors]
    r = richardson(vals, factors)
    assert r["observed_order"] == pytest.approx(p, rel=1e-8)
    assert r["extrapolated"] == pytest.approx(vstar, rel=1e-9)
    for v, e in zip(vals, r["errors"], strict=True):
        assert e == pytest.approx(abs(v - vstar), rel=1e-7, abs=1e-15)
    assert r["monotone"]


def test_richardson_vectorised_one_order_from_norms():
    # a (steps, M, 3) history converging at order 2 with an array-valued constant (some
    # components not changing at all): one order, the exact limit componentwise
    rng = np.random.default_rng(0)
    vstar = rng.normal(size=(4, 2, 3))
    C = rng.normal(size=(4, 2, 3))
    C[:, :, 0] = 0.0
    vals = [vstar + C * (1.0 / f) ** 2 for f in (1, 2, 3)]
    r = richardson(vals, [1, 2, 3])
    assert r["observed_order"] == pytest.approx(2.0, rel=1e-8)
    np.testing.assert_allclose(r["extrapolated"], vstar, atol=1e-12)
    np.testing.assert_allclose(r["errors"][0], np.abs(C), atol=1e-12)


def test_richardson_two_levels_needs_the_order():
    with pytest.raises(ValueError, match="order must be given"):
        richardson([1.0, 0.5], [1, 2])
    # with the order given, the limit of an exact order-1 sequence
    r = richardson([1.0 + 0.3, 1.0 + 0.15], [1, 2], order=1.0)
    assert r["extrapolated"] == pytest.approx(1.0) and np.isnan(r["observed_order"])
    with pytest.raises(ValueError, match="increasing"):
        richardson([1.0, 2.0, 3.0], [1, 3, 2])


def test_richardson_not_monotone_is_conservative():
    # an oscillating sequence has no order: the finest value, and errors that bound the spread
    r = richardson([1.0, 0.8, 0.9], [1, 2, 3])
    assert np.isnan(r["observed_order"]) and not r["monotone"]
    assert r["extrapolated"] == 0.9 and r["errors"][-1] == pytest.approx(0.1)


# --- refined descriptions ------------------------------------------------------------------------

def _spec(kind: str) -> dict:
    from skinkit.fem.discretisation import pin_mesh
    s = read_model(MODELS / {"disc": "invivo_goh_qlv.toml", "block": "phantom_membrane_gel.toml",
                             "twopad": "extension_dic_twopad.toml"}[kind])
    if kind == "disc":  # the example's geometry on a small full-grid mesh: refining it stays cheap
        s = pin_mesh(s, [2, 2], n_inner=3, n_ring=3, grading=1.6)
    return s


@pytest.mark.parametrize("kind", ["disc", "block", "twopad"])
def test_refined_spec_multiplies_every_count(kind):
    s = _spec(kind)
    before = copy.deepcopy(s)
    g = s["geometry"]
    r = refined_spec(s, 2)
    assert s == before  # a copy: the description given is untouched
    if kind == "disc":
        keys = ["n_inner", "n_ring"]
    elif kind == "twopad":
        keys = ["n_pad", "n_gap", "n_outer", "n_side"]
    else:
        keys = []
        assert r["geometry"]["n"] == [2 * k for k in g["n"]]
    for k in keys:
        assert r["geometry"][k] == 2 * g[k]
    assert [L["elements"] for L in r["layers"]] == [2 * L["elements"] for L in s["layers"]]
    # gradings and lengths are kept: the same mapped geometry, h halved
    assert {k: v for k, v in r["geometry"].items() if not k.startswith("n")} == \
        {k: v for k, v in g.items() if not k.startswith("n")}
    # unknowns: (2 nx + 1)(2 ny + 1)(2 nz + 1) x 3 nodes of 27-node hexahedra, nx, ny, nz doubled
    e1, e2 = estimate_size(s, layer_table(s)), estimate_size(r, layer_table(r))
    assert e2["elements"] == 8 * e1["elements"]
    assert build_mesh(r).n_dof == e2["unknowns"] and build_mesh(s).n_dof == e1["unknowns"]


@pytest.mark.parametrize("kind,absent,default", [("disc", "n_ring", 3), ("twopad", "n_gap", 6),
                                                  ("block", "n", [4, 4])])
def test_refined_spec_uses_the_builders_defaults(kind, absent, default):
    s = _spec(kind)
    s["geometry"].pop(absent)
    del s["layers"][0]["elements"]
    r = refined_spec(s, 3)
    assert r["geometry"][absent] == ([3 * k for k in default] if isinstance(default, list) else 3 * default)
    assert r["layers"][0]["elements"] == 6
    # and the refined mesh is what the builder makes of those counts
    assert build_mesh(r).n_elements == estimate_size(r, layer_table(r))["elements"]


def test_refined_spec_refuses_bad_counts():
    s = _spec("disc")
    s["geometry"]["n_inner"] = "two"
    with pytest.raises(ModelError, match=r"geometry.n_inner: must be a whole number"):
        refined_spec(s, 2)
    with pytest.raises(ModelError, match="refinement factor"):
        refined_spec(_spec("disc"), 0)


# --- grading keys -----------------------------------------------------------------------------

def test_grading_keys_refine_towards_the_probe_edge():
    s = _spec("disc")
    s["geometry"].update(n_inner=4, inner_grading=2.0, layer_grading=2.0)
    m = build_mesh(s)
    a = 0.002
    r = np.unique(np.round(np.hypot(*m.nodes[m.node_sets["top"]][:, :2].T), 12))
    inner = r[r <= a * (1 + 1e-9)]
    # along the x axis the central block's vertices lie at a (1 - (1 - k/2)^2), k = 0, 1, 2:
    # the ring next to the edge (0.5 a wide uniform) is 0.25 a wide
    x, y, z = m.nodes.T
    on_axis = np.sort(x[(np.abs(y) < 1e-12) & (z == 0) & (x >= 0)])
    assert on_axis[0] == 0 and np.isclose(inner.max(), a)
    verts = on_axis[on_axis <= a + 1e-12][::2]  # quadratic elements: every other node is a vertex
    np.testing.assert_allclose(verts, a * (1 - (1 - np.arange(3) / 2) ** 2), atol=1e-12)
    zs = np.unique(np.round(z, 12))[::-1]
    zv = zs[::2]  # vertices, top down: skin 1.5 mm in 2 elements graded (k/2)^2
    np.testing.assert_allclose(zv[:3], [0.0, -0.0015 / 4, -0.0015], atol=1e-12)
    # defaults (absent keys) are today's uniform meshes
    assert np.array_equal(build_mesh(_spec("disc")).nodes, build_mesh(_spec("disc")).nodes)


@pytest.mark.parametrize("entry,value,needle", [
    ("geometry.inner_grading", 0.5, "geometry.inner_grading: must be in [1, 10]"),
    ("geometry.layer_grading", "x", "geometry.layer_grading: expected '<number> <unit>'"),
    ("geometry.layer_grading", True, "geometry.layer_grading: expected a quantity"),
    ("solver.discretisation_tolerance", -0.05, "solver.discretisation_tolerance: must be in (0, 0.5]"),
    ("solver.discretisation_tolerance", "5 mm", "solver.discretisation_tolerance: inconsistent units"),
    ("solver.point_tolerance", "2 s", "solver.point_tolerance: inconsistent units"),
    ("solver.point_tolerance", 0.5, "solver.point_tolerance: must be in (0, 0.01] m"),
])
def test_bad_values_refused_in_one_line(tmp_path, entry, value, needle):
    from tests.core._cli import one_error
    table, key = entry.split(".")
    p = _tiny(tmp_path)
    text = p.read_text()
    val = json.dumps(value) if not isinstance(value, bool) else str(value).lower()
    if table == "geometry":
        text = text.replace("[geometry]\n", f"[geometry]\n{key} = {val}\n", 1)
        text = text.replace(f"{key} = 1.5\n", "", 1)
    else:
        text += f"[solver]\n{key} = {val}\n"
    p.write_text(text)
    r = CliRunner().invoke(cli, ["solve", str(p), "--no-vtu", "--out", str(tmp_path / "out")])
    one_error(r, needle)


def test_twopad_pad_grading():
    s = _spec("twopad")
    s["geometry"].update(n_pad=4, pad_grading=2.0)
    m = build_mesh(s)
    p = m.nodes[m.node_sets["pad_moving"]]
    xs = np.unique(np.round(p[:, 0], 12))[::2]  # vertices across the pad, 4 elements
    h = np.diff(xs)
    assert h[0] < h[1] and h[-1] < h[-2] and np.isclose(h[0], h[-1])  # finer at both edges
    with pytest.raises(ModelError, match="geometry.pad_grading: must be in"):
        s["geometry"]["pad_grading"] = 0.9
        build_mesh(s)


# --- the estimate in the commands ----------------------------------------------------------------

def test_convergence_json_carries_the_estimate(tmp_path):
    r = CliRunner().invoke(cli, ["convergence", str(_tiny(tmp_path)), "--levels", "3",
                                 "--out", str(tmp_path / "conv"), "--json"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.stdout)
    rows = res["levels"]
    F = [np.array(x["tip_force_N"]) for x in rows]
    # the estimate is Richardson's over the three levels (checked against the function), the
    # order is that of a graded mesh (above the ~1.3 of uniform refinement at a punch edge)
    ref = richardson(F, [1, 2, 3])
    assert res["observed_order"] == pytest.approx(ref["observed_order"]) and res["observed_order"] > 1.3
    assert not res["order_assumed"]
    np.testing.assert_allclose(res["extrapolated"], ref["extrapolated"])
    rel = [x["relative_error"] for x in rows]
    assert rel[0] > rel[1] > rel[2] > 0
    for x, e in zip(rows, ref["errors"], strict=True):
        np.testing.assert_allclose(x["estimated_error"], e)
        assert x["relative_error"] == pytest.approx(np.linalg.norm(e) / np.linalg.norm(ref["extrapolated"]))
    # the existing keys are kept
    assert {"change_vs_finest", "dof", "tip_force_N", "tip_displacement_m"} <= set(rows[0])
    saved = json.loads((tmp_path / "conv" / "convergence.json").read_text())
    assert saved["observed_order"] == res["observed_order"]


def test_solve_error_estimate_beside_the_result(tmp_path):
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, ["solve", str(_tiny(tmp_path)), "--no-vtu", "--out", str(out),
                                 "--error-estimate"])
    assert r.exit_code == 0, r.output
    assert "estimated discretisation error on the 1x mesh" in r.output and "order 1 assumed" in r.output
    info = json.loads((out / "summary.json").read_text())
    d = info["discretisation"]
    assert d["factors"] == [1, 2] and d["factor"] == 1 and d["dof"][0] == info["dof"] < d["dof"][1]
    st = info["steps"][-1]
    F, eF = np.array(st["tip_force_N"]), np.array(st["tip_force_error_N"])
    # order 1 assumed with two meshes: the 1x error is twice the change from 1x to 2x
    # (v* = v2 + (v2 - v1)), and the prescribed tip motion has none
    F2 = np.array(d["extrapolated"]["tip_force_N"])  # v* of the final step
    np.testing.assert_allclose(eF, np.abs(F - F2), rtol=1e-9, atol=1e-15)
    assert d["tip_force_relative_error"] == pytest.approx(np.linalg.norm(eF) / np.linalg.norm(F2))
    assert st["tip_displacement_error_m"] == [0.0, 0.0, 0.0] and d["tip_displacement_relative_error"] == 0
    assert len(st["points_error_m"]) == 2
    assert d["points_max_error_m"] == pytest.approx(max(st["points_error_m"]))


def test_discretisation_tolerance_refines_until_met(tmp_path):
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, ["solve", str(_tiny(tmp_path, "discretisation_tolerance = 0.1")), "--no-vtu",
                                 "--out", str(out)])
    assert r.exit_code == 0, r.output
    info = json.loads((out / "summary.json").read_text())
    d = info["discretisation"]
    assert d["met"] and d["tip_force_relative_error"] <= 0.1
    # the result written is the finest mesh's, which met it; the file's 1x mesh did not
    assert d["factor"] == d["factors"][-1] >= 2 and info["dof"] == d["dof"][-1]
    assert d["unknowns_solved"] > info["dof"]
    assert "tolerance 10 % on the tip met" in r.output


def test_discretisation_tolerance_refused_at_the_size_limit(tmp_path):
    from tests.core._cli import one_error
    # the 2x mesh (11,907 unknowns) fits, the 3x one (37,479) does not: refused, with the
    # estimate reached and nothing written
    p = _tiny(tmp_path, "discretisation_tolerance = 0.01\nmax_unknowns = 20000")
    r = CliRunner().invoke(cli, ["solve", str(p), "--no-vtu", "--out", str(tmp_path / "out")])
    line = one_error(r, "solver.discretisation_tolerance: not met before the size limit",
                     "at 11,907 unknowns (refined 2x)", "refining 3x")
    assert "estimated force error" in line
    assert not (tmp_path / "out").exists()


def test_convergence_on_an_example_reports_the_estimate(tmp_path):
    # the membrane phantom at its documented 0.5 mm, one static step, 1x and 2x: the estimate
    # (order 1 assumed with two levels) is the change from 1x to 2x, twice for the 1x mesh
    s = (MODELS / "phantom_membrane_gel.toml").read_text().replace("steps = 2", "steps = 1")
    p = tmp_path / "phantom.toml"
    p.write_text(s.replace("sensitivities = true", "sensitivities = false"))
    r = CliRunner().invoke(cli, ["convergence", str(p), "--levels", "2", "--out", str(tmp_path / "c"),
                                 "--json"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.stdout)
    assert res["order"] == 1.0 and res["order_assumed"] and res["observed_order"] is None
    F1, F2 = (np.array(x["tip_force_N"]) for x in res["levels"])
    np.testing.assert_allclose(res["extrapolated"], 2 * F2 - F1, rtol=1e-12, atol=1e-15)
    e1, e2 = (x["relative_error"] for x in res["levels"])
    assert e1 == pytest.approx(2 * e2)
    # this example meets 5 % on the tip force at its documented load (docs/reference/model-files.md)
    assert e1 < 0.05


# --- mesh layouts: the disc's O-grid, the block fitted to its indenter -------------------------

def _volume(mesh) -> float:
    from skfem import Basis, ElementHex2, Functional
    b = Basis(mesh.skfem_mesh(), ElementHex2(), intorder=3)
    assert b.dx.min() > 0  # no inverted element
    return float(Functional(lambda w: 1.0 + 0 * w.x[0]).assemble(b))


def test_o_grid_keeps_the_block_elements_around_every_ring():
    from skinkit.fem.mesh import disc_mesh
    layers = [("skin", 0.0015, 1), ("subdermal", 0.0035, 1)]
    m = disc_mesh(0.04, 0.004, layers, n_inner=2, n_ring=5, o_grid=True)
    # per element layer: the 2 x 2 block and 5 rings of 4 x 2 = 8 elements
    assert m.n_elements == 2 * (4 + 5 * 8)
    top = m.nodes[m.node_sets["top"]]
    r = np.hypot(top[:, 0], top[:, 1])
    # the rim carries 2 x 8 = 16 nodes (vertices and mid-edge nodes), all on the circle
    assert np.sum(np.isclose(r, 0.02)) == 16 and len(m.node_sets["outer"]) == 16 * 5
    # the footprint is the indenter's circle, resolved as in the full grid
    full = disc_mesh(0.04, 0.004, layers, n_inner=2, n_ring=5)
    np.testing.assert_allclose(np.sort(m.nodes[m.node_sets["indenter"]], axis=0),
                               np.sort(full.nodes[full.node_sets["indenter"]], axis=0), atol=1e-15)
    # volume: the cylinder up to its rim's 8 quadratic arcs of 45° (each short of the circle
    # by a sliver: 4e-3 of the area for this interpolation)
    assert _volume(m) == pytest.approx(np.pi * 0.02 ** 2 * 0.005, rel=5e-3)
    assert _volume(disc_mesh(0.04, 0.004, layers, n_inner=4, n_ring=5, o_grid=True)) == \
        pytest.approx(np.pi * 0.02 ** 2 * 0.005, rel=5e-4)  # 16 arcs: 16x closer (h^4)
    # the size estimate before building knows the layout
    s = _spec("disc")
    s["geometry"].update(o_grid=True, n_inner=2, n_ring=5)
    assert estimate_size(s, layer_table(s))["unknowns"] == build_mesh(s).n_dof
    assert refined_spec(s, 2)["geometry"]["o_grid"] is True


def test_fitted_block_puts_the_indenter_circle_on_element_boundaries():
    s = read_model(MODELS / "phantom_membrane_gel.toml")
    g = {k: v for k, v in s["geometry"].items() if k != "n"}
    s["geometry"] = dict(g, fit_indenter=True, n_inner=2, n_ring=3, grading=1.5)
    m = build_mesh(s)
    c = np.array([0.01, 0.01])
    foot = m.nodes[m.node_sets["indenter"]]
    r = np.hypot(*(foot[:, :2] - c).T)
    # the footprint's outermost nodes lie on the 2.5 mm circle, on every refinement
    for f in (1, 2):
        mf = build_mesh(refined_spec(s, f))
        ff = mf.nodes[mf.node_sets["indenter"]]
        rf = np.hypot(*(ff[:, :2] - c).T)
        assert np.isclose(rf.max(), 0.0025) and np.sum(np.isclose(rf, 0.0025)) == 8 * 2 * f
    assert r.max() == pytest.approx(0.0025)
    assert _volume(m) == pytest.approx(0.02 * 0.02 * 0.010, rel=1e-12)  # the box exactly
    assert estimate_size(s, layer_table(s))["unknowns"] == m.n_dof
    assert set(m.node_sets) >= {"top", "bottom", "sides", "xmin", "indenter"}
    s["geometry"]["n"] = [4, 4]
    with pytest.raises(ModelError, match="geometry.n: unknown key"):
        build_mesh(s)


def test_refined_spec_coarsens_by_a_fraction():
    s = _spec("disc")
    s["geometry"].update(n_inner=4, n_ring=6)
    s["layers"][0]["elements"], s["layers"][1]["elements"] = 2, 4
    c = refined_spec(s, "1/2")
    assert (c["geometry"]["n_inner"], c["geometry"]["n_ring"]) == (2, 3)
    assert [L["elements"] for L in c["layers"]] == [1, 2]
    with pytest.raises(ModelError, match=r"geometry.n_ring: 6 elements cannot be scaled by 1/4"):
        refined_spec(s, "1/4")
    with pytest.raises(ModelError, match="refinement factor: expected a number"):
        refined_spec(s, "half")


def test_pin_mesh_sets_every_mesh_key():
    from skinkit.fem.discretisation import MESH_KEYS, pin_mesh
    s = _spec("disc")
    s["geometry"].update(o_grid=True, inner_grading=2.0, n_ring=12)
    p = pin_mesh(s, [1, 1], n_inner=1, n_ring=2)
    g = p["geometry"]
    assert {k: g[k] for k in MESH_KEYS["disc"]} == {"n_inner": 1, "n_ring": 2, "grading": 1.6,
                                                    "inner_grading": 1.0, "layer_grading": 1.0,
                                                    "o_grid": False}
    assert [L["elements"] for L in p["layers"]] == [1, 1] and s["geometry"]["n_ring"] == 12
    with pytest.raises(ModelError, match="geometry.n_pad: not a mesh key of kind 'disc'"):
        pin_mesh(s, [1, 1], n_pad=2)


def test_convergence_at_the_peak_of_a_sinusoid_and_by_coarsened_factors(tmp_path):
    # a sinusoid returns to zero depth at its end: the final step's force says nothing about
    # the mesh, its peak does (step 1 of 2: half a period, the full 0.3 mm)
    text = TINY.replace('kind = "ramp"\nvalue = ["0 mm", "0 mm", "-0.3 mm"]\nsteps = 1',
                        'kind = "sinusoid"\npeak_to_peak = "0.3 mm"\nfrequency = "1 Hz"\nperiods = 1\n'
                        'steps_per_period = 2\ndirection = [0, 0, -1]')
    text = text.replace("n_inner = 1", "n_inner = 2\no_grid = true")
    text = text.replace("elements = 1", "elements = 2")
    p = tmp_path / "sine.toml"
    p.write_text(text)
    runs = {}
    for at in ("final", "peak"):
        r = CliRunner().invoke(cli, ["convergence", str(p), "--factors", "1/2,1", "--at", at,
                                     "--out", str(tmp_path / at), "--json"])
        assert r.exit_code == 0, r.output
        runs[at] = json.loads(r.stdout)
    peak = runs["peak"]["levels"]
    assert [x["step"] for x in peak] == [0, 0] and [x["factor"] for x in peak] == ["1/2", "1"]
    assert peak[1]["dof"] > peak[0]["dof"]
    assert all(abs(x["tip_force_N"][2]) > 1e3 * abs(y["tip_force_N"][2])
               for x, y in zip(peak, runs["final"]["levels"], strict=True))
    # two levels, order 1 assumed: the finer level's estimated error is its change from the coarser
    f1, f2 = (np.array(x["tip_force_N"]) for x in peak)
    assert peak[1]["relative_error"] == pytest.approx(np.linalg.norm(f2 - f1) / np.linalg.norm(2 * f2 - f1))
    r = CliRunner().invoke(cli, ["convergence", str(p), "--factors", "1/4,1", "--out", str(tmp_path / "x")])
    assert r.exit_code != 0 and "cannot be scaled by 1/4" in r.output
