"""FEBio export: the .feb file read back with a parser written here (plain xml.etree, none of
the writer's code) and every value compared with the skinkit model it came from -- node
coordinates in mm, hex27 connectivity in FEBio's node order with a positive Jacobian, material
parameters after the documented conversions, fixed sets, the rigid indenter, load curves
against the programme or the session record -- and the features FEBio has no counterpart of
refused with one line naming them. No FEBio binary is run (the file is checked structurally)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.examples import example_model
from skinkit.fem.model import build_model, load_model, read_model
from skinkit.schemas import Protocol, RobotRecord
from skinkit.store import create_experiment

pytestmark = pytest.mark.needs_plugins

#: FEBio's FEHex27 lookup table (shape-function index per node and axis: 0 is the -1 end,
#: 1 the +1 end, 2 the middle), as in FEBio's source
_LUT = ["000", "100", "110", "010", "001", "101", "111", "011", "200", "120", "210", "020",
        "201", "121", "211", "021", "002", "102", "112", "012", "202", "122", "212", "022",
        "220", "221", "222"]
_XI = {"0": -1.0, "1": 1.0, "2": 0.0}


def _run(*args: str) -> object:
    return CliRunner().invoke(cli, ["export", "febio", *args])


def _export(tmp_path: Path, model_file: str | Path, *extra: str) -> ET.Element:
    out = tmp_path / "model.feb"
    r = _run(str(model_file), "--out", str(out), *extra)
    assert r.exit_code == 0, r.output
    text = out.read_text(encoding="utf-8")
    assert text.startswith('<?xml version="1.0"')
    root = ET.fromstring(text.encode("utf-8"))
    assert root.tag == "febio_spec" and root.get("version") == "4.0"
    return root


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",")]


def _nodes(root: ET.Element) -> dict[int, np.ndarray]:
    return {int(n.get("id")): np.array(_floats(n.text)) for n in root.iter("node")}


def _shape_derivs(r: float, s: float, t: float) -> np.ndarray:
    """``(27, 3)`` derivatives of FEBio's hex27 shape functions at (r, s, t)."""
    def one(x: float) -> tuple[list[float], list[float]]:
        return [0.5 * x * (x - 1), 0.5 * x * (x + 1), 1 - x * x], [x - 0.5, x + 0.5, -2 * x]
    (R, dR), (S, dS), (T, dT) = one(r), one(s), one(t)
    out = np.zeros((27, 3))
    for k, code in enumerate(_LUT):
        i, j, m = (int(c) for c in code)
        out[k] = (dR[i] * S[j] * T[m], R[i] * dS[j] * T[m], R[i] * S[j] * dT[m])
    return out


def _check_mesh(root: ET.Element, model, straight: bool = True) -> None:
    """Nodes [mm] and hex27 connectivity; ``straight``: the mesh's elements are straight-sided
    (blocks), so every edge and face node lies where the corners' trilinear map puts it."""
    from skfem import Basis, ElementHex2

    mesh = model.mesh
    nodes = _nodes(root)
    X = np.array([nodes[i + 1] for i in range(mesh.n_nodes)])
    np.testing.assert_allclose(X, mesh.nodes * 1e3, rtol=0, atol=1e-12)
    blocks = {e.get("name"): e for e in root.iter("Elements") if e.get("type") == "hex27"}
    assert sorted(blocks) == sorted(mesh.regions)
    g = math.sqrt(3.0 / 5.0)
    w1 = {-g: 5 / 9, 0: 8 / 9, g: 5 / 9}
    gauss = [(a, b, c) for a in (-g, 0, g) for b in (-g, 0, g) for c in (-g, 0, g)]
    weights = np.array([w1[a] * w1[b] * w1[c] for a, b, c in gauss])
    dN = [_shape_derivs(*p) for p in gauss]
    corners = np.array([[_XI[c] for c in code] for code in _LUT])
    # the reference: scikit-fem's own map of skinkit's elements (mm^3), whatever their orientation
    basis = Basis(mesh.skfem_mesh(), ElementHex2(), intorder=4)
    dj = basis.mapping.detDF(basis.X) * 1e9
    vol_ref = np.abs(dj @ basis.W)     # the signed integral of det J: the element's volume
    folded_ref = (dj.min(axis=1) < 0) & (dj.max(axis=1) > 0)
    for region, block in blocks.items():
        conn = np.array([[int(v) - 1 for v in e.text.split(",")] for e in block.iter("elem")])
        idx = mesh.region_elements(region)
        els = mesh.elements[idx]
        assert conn.shape == els.shape
        assert all(set(a) == set(b) for a, b in zip(conn, els, strict=True))
        xe = mesh.nodes[conn] * 1e3                              # (E, 27, 3) [mm]
        dets = np.array([np.linalg.det(np.einsum("eai,ak->eik", xe, d)) for d in dN]).T   # (E, 27)
        centre = np.linalg.det(np.einsum("eai,ak->eik", xe, _shape_derivs(0, 0, 0)))
        assert centre.min() > 0, f"{region}: an element oriented left-handed"
        vol = dets @ weights
        assert vol.min() > 0
        np.testing.assert_allclose(vol, vol_ref[idx], rtol=1e-10)
        # an element folded at a Gauss point is folded in skinkit's own map too (the mesh's shape)
        np.testing.assert_array_equal(dets.min(axis=1) <= 0, folded_ref[idx])
        if straight:
            N8 = np.prod((1 + corners[:, None, :] * corners[None, :8, :]) / 2, axis=-1)
            np.testing.assert_allclose(np.einsum("na,eai->eni", N8, xe[:, :8]), xe, atol=1e-9)


def _params(el: ET.Element) -> dict[str, str]:
    return {c.tag: (c.text or "").strip() for c in el if len(c) == 0}


def _expected(law, p: dict[str, float]) -> tuple[str, dict[str, float], str | None]:
    """FEBio material type, parameters (MPa, degrees) and pressure model of a skinkit law,
    from the conversions of docs/reference/febio-export.md."""
    pm = {"log": "default", "quadratic": "Abaqus"}.get(getattr(law, "volumetric", ""), None)
    if law.name == "neo-hookean":
        mu, lam = p["mu"], p["lam"]
        return "neo-Hookean", {"E": mu * (3 * lam + 2 * mu) / (lam + mu) / 1e6,
                               "v": lam / (2 * (lam + mu))}, None
    if law.name == "neo-hookean-ni":
        return "Mooney-Rivlin", {"c1": p["mu"] / 2e6, "c2": 0.0, "k": p["K"] / 1e6}, pm
    if law.name == "neo-hookean-enu":
        E, nu = p["E"], p["nu"]
        return "Mooney-Rivlin", {"c1": E / (4 * (1 + nu)) / 1e6, "c2": 0.0,
                                 "k": E / (3 * (1 - 2 * nu)) / 1e6}, pm
    if law.name == "mooney-rivlin":
        return "Mooney-Rivlin", {"c1": p["c1"] / 1e6, "c2": p["c2"] / 1e6, "k": p["K"] / 1e6}, pm
    if law.name == "goh":
        return "Holzapfel-Gasser-Ogden", {"c": p["c"] / 1e6, "k1": p["k1"] / 1e6, "k2": p["k2"],
                                          "kappa": p["kappa"], "gamma": abs(p["gamma"]) * 180 / math.pi,
                                          "k": p["k"] / 1e6}, pm
    if law.name == "ogden":
        out = {"k": p["K"] / 1e6}
        for i in range(1, law.terms + 1):
            out[f"c{i}"], out[f"m{i}"] = 2 * p[f"mu{i}"] / 1e6, p[f"alpha{i}"]
        return "Ogden", out, pm
    raise AssertionError(law.name)


def _check_material(el: ET.Element, m) -> None:
    law, p = m.law, dict(m.params)
    if law.name == "qlv":
        assert el.get("type") == "viscoelastic"
        got = _params(el)
        g = [p[f"g{i}"] for i in range(1, law.terms + 1)]
        assert float(got["g0"]) == pytest.approx(1 - sum(g), rel=1e-15)
        for i in range(1, law.terms + 1):
            assert float(got[f"g{i}"]) == pytest.approx(p[f"g{i}"], rel=1e-15)
            assert float(got[f"t{i}"]) == pytest.approx(p[f"tau{i}"], rel=1e-15)
        el = el.find("elastic")
        law = law.elastic
        p = {q.name: p[q.name] for q in law.parameters()}
    if m.F0 is not None:
        assert el.get("type") == "prestrain elastic"
        pre = el.find("prestrain")
        assert pre.get("type") == "prestrain gradient" and float(pre.find("ramp").text) == 1.0
        np.testing.assert_allclose(np.array(_floats(pre.find("F0").text)).reshape(3, 3), m.F0,
                                   rtol=1e-15, atol=1e-15)
        el = el.find("elastic")
    ftype, want, pm = _expected(law, p)
    assert el.get("type") == ftype
    got = _params(el)
    for k, v in want.items():
        assert float(got[k]) == pytest.approx(v, rel=1e-13, abs=1e-300), (ftype, k)
    assert got.get("pressure_model") == pm
    if ftype == "Holzapfel-Gasser-Ogden":
        th = law.frame_angle
        ax = el.find("mat_axis")
        np.testing.assert_allclose(_floats(ax.find("a").text), [math.cos(th), math.sin(th), 0], atol=1e-15)
        np.testing.assert_allclose(_floats(ax.find("d").text), [-math.sin(th), math.cos(th), 0], atol=1e-15)


def _curves(root: ET.Element) -> dict[str, tuple[int, np.ndarray]]:
    out = {}
    for lc in root.iter("load_controller"):
        pts = np.array([_floats(p.text) for p in lc.find("points")])
        out[lc.get("name")] = (int(lc.get("id")), pts)
    return out


def _check_boundary(root: ET.Element, model) -> None:
    sets = {s.get("name"): np.array([int(v) - 1 for v in s.text.split(",")]) for s in root.iter("NodeSet")}
    for name, ids in model.mesh.node_sets.items():
        np.testing.assert_array_equal(sets[name], ids)
    fixed = [bc for bc in root.iter("bc") if bc.get("type") == "zero displacement"]
    assert sorted(bc.get("node_set") for bc in fixed) == sorted(model.fixed_sets)
    assert all(_params(bc) == {"x_dof": "1", "y_dof": "1", "z_dof": "1"} for bc in fixed)
    rig = model.bc.rigid
    np.testing.assert_array_equal(sets["indenter_tied"], rig.nodes)
    tie = [bc for bc in root.iter("bc") if bc.get("type") == "rigid"]
    assert len(tie) == 1 and tie[0].get("node_set") == "indenter_tied"
    rb = tie[0].find("rb").text
    mats = {m.get("name"): m for m in root.find("Material")}
    assert mats[rb].get("type") == "rigid body"
    doms = {d.get("name"): d.get("mat") for d in root.find("MeshDomains")}
    assert doms["probe"] == rb and all(doms[r] == r for r in model.mesh.regions)
    fixed_rot = [b for b in root.find("Rigid") if b.get("type") == "rigid_fixed"]
    assert len(fixed_rot) == 1
    assert all(fixed_rot[0].find(d).text == "1" for d in ("Ru_dof", "Rv_dof", "Rw_dof"))
    probe = [n for n in root.iter("Nodes") if n.get("name") == "probe"][0]
    zp = min(_floats(n.text)[2] for n in probe)
    assert zp > model.mesh.nodes[:, 2].max() * 1e3   # the rigid body's element shares no node


def _drive_items(root: ET.Element, mode: str) -> dict[str, int]:
    """tied direction -> load-curve id of the rigid body's drive."""
    items = {}
    for el in root.find("Rigid"):
        if mode == "displacement" and el.get("type") == "rigid_displacement":
            items[el.find("dof").text] = int(el.find("value").get("lc"))
        if mode == "force" and el.get("type") == "rigid_force":
            items[el.find("dof").text[1]] = int(el.find("value").get("lc"))
    return items


@pytest.mark.parametrize("name", ["phantom_membrane_gel", "invivo_static_force", "extension_dic_twopad"])
def test_example_models_read_back_value_by_value(tmp_path, name):
    path = example_model(name)
    root = _export(tmp_path, path)
    model = load_model(path)
    _check_mesh(root, model, straight=not name.startswith("invivo"))
    mats = {m.get("name"): m for m in root.find("Material")}
    for m in model.problem.materials:
        _check_material(mats[m.region], m)
    _check_boundary(root, model)
    # the [load] programme: a point per solution step, in mm (displacement) or N (force)
    rig = model.bc.rigid
    curves = {lc_id: pts for lc_id, pts in _curves(root).values()}
    items = _drive_items(root, rig.mode)
    assert sorted(items) == sorted("xyz"[c] for c in rig.components)
    t = np.concatenate([[0.0], model.load.times])
    want = np.array([model.load.value(x) for x in t]) * (1e3 if rig.mode == "displacement" else 1.0)
    for c in rig.components:
        pts = curves[items["xyz"[c]]]
        np.testing.assert_allclose(pts[:, 0], t, rtol=1e-15)
        np.testing.assert_allclose(pts[:, 1], want[:, c], rtol=1e-14, atol=1e-15)
    ctl = root.find("Control")
    n = int(ctl.find("time_steps").text)
    assert n == len(model.load.times) and float(ctl.find("step_size").text) * n == pytest.approx(t[-1])


_GOH_QLV = """
[model]
name = "goh-qlv-prestretched"
[geometry]
kind = "block"
size = ["10 mm", "8 mm"]
n = [2, 2]
indenter_diameter = "4 mm"
[[layers]]
name = "skin"
thickness = "1.5 mm"
elements = 1
law = "qlv"
options = { elastic = "goh", terms = 2, elastic_options = { families = 2, frame_angle = 0.3 } }
[layers.parameters]
c = "20 kPa"
k1 = "30 kPa"
k2 = 4.0
kappa = 0.15
gamma = "-35 deg"
k = "1 MPa"
g1 = 0.3
tau1 = "2 s"
g2 = 0.2
tau2 = "20 s"
[layers.prestress]
stretch = [1.1, 1.04]
angle = "25 deg"
[[layers]]
name = "fat"
thickness = "3 mm"
elements = 1
law = "ogden"
options = { terms = 2, volumetric = "log" }
[layers.parameters]
mu1 = "3 kPa"
alpha1 = 6.0
mu2 = "1 kPa"
alpha2 = -2.0
K = "200 kPa"
[[layers]]
name = "muscle"
thickness = "2 mm"
elements = 1
law = "neo-hookean"
[layers.parameters]
mu = "8 kPa"
lam = "80 kPa"
[boundary]
fixed = ["bottom"]
[indenter]
mode = "displacement"
[load]
kind = "sinusoid"
peak_to_peak = "1 mm"
frequency = "0.1 Hz"
periods = 1
steps_per_period = 8
"""


def test_goh_qlv_prestretch_ogden_and_neo_hookean_convert_as_documented(tmp_path):
    path = tmp_path / "goh.toml"
    path.write_text(_GOH_QLV)
    root = _export(tmp_path, path)
    model = build_model(read_model(path))
    _check_mesh(root, model)
    mats = {m.get("name"): m for m in root.find("Material")}
    assert mats["skin"].get("type") == "viscoelastic"
    assert mats["skin"].find("elastic").get("type") == "prestrain elastic"
    for m in model.problem.materials:
        _check_material(mats[m.region], m)
    goh = mats["skin"].find("elastic").find("elastic")
    assert float(goh.find("gamma").text) == pytest.approx(35.0, rel=1e-14)   # degrees, |gamma|
    _check_boundary(root, model)


def _session(path: Path, n_protocols: int = 1) -> tuple[Path, list[RobotRecord]]:
    rng = np.random.default_rng(3)
    records = []
    with create_experiment(path) as exp:
        for k in range(n_protocols):
            n = 240
            t = np.arange(n) / 40.0
            pos = np.zeros((n, 3))
            pos[:, 2] = -0.4e-3 * np.sin(np.pi * t / t[-1]) ** 2
            pos[:, :2] = rng.normal(0, 1e-6, (n, 2))
            force = rng.normal(0, 1e-4, (n, 3))     # sensor noise on every component
            force[:, 2] += 80.0 * pos[:, 2]
            rec = RobotRecord(time_s=t, tip_position=pos, tip_force=force,
                              protocol=Protocol("normal_indentation" if k == 0 else f"in_plane_{k:03d}"))
            exp.write_record(rec)
            records.append(rec)
    return path, records


def test_session_drive_is_the_record_in_mm_and_the_measured_force_in_newtons(tmp_path):
    session, (rec,) = _session(tmp_path / "s.h5")
    root = _export(tmp_path, example_model("phantom_membrane_gel"), "--session", str(session))
    model = load_model(example_model("phantom_membrane_gel"))
    _check_mesh(root, model)
    curves = _curves(root)
    items = _drive_items(root, "displacement")
    # the record is in the robot frame (z into the skin), the model in the skin frame (z out)
    flip = np.array([1.0, 1.0, -1.0])
    for c, axis in enumerate("xyz"):
        lc_id, pts = curves[f"recorded_tip_position_{axis}"]
        assert items[axis] == lc_id
        np.testing.assert_array_equal(pts[:, 0], rec.time_s)
        np.testing.assert_allclose(pts[:, 1], flip[c] * rec.tip_position[:, c] * 1e3, rtol=1e-15)
        _, fpts = curves[f"recorded_tip_force_{axis}"]
        np.testing.assert_allclose(fpts[:, 1], flip[c] * rec.tip_force[:, c], rtol=1e-15)
    ctl = root.find("Control")
    n, dt = int(ctl.find("time_steps").text), float(ctl.find("step_size").text)
    assert n * dt == pytest.approx(rec.time_s[-1]) and dt <= 0.5 + 1e-12   # [drive] max_step


def test_a_session_of_several_protocols_needs_protocol(tmp_path):
    session, recs = _session(tmp_path / "s.h5", 2)
    out = tmp_path / "m.feb"
    r = _run(str(example_model("phantom_membrane_gel")), "--session", str(session), "--out", str(out))
    assert r.exit_code == 2 and "--protocol" in r.output and not out.exists()
    root = _export(tmp_path, example_model("phantom_membrane_gel"), "--session", str(session),
                   "--protocol", recs[1].protocol.name)
    _, pts = _curves(root)["recorded_tip_position_z"]
    np.testing.assert_allclose(pts[:, 1], -recs[1].tip_position[:, 2] * 1e3, rtol=1e-15)


def _one_line_error(r, *needles: str) -> None:
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), r.output
    for n in needles:
        assert n in lines[0], (n, lines[0])


def test_features_without_an_febio_counterpart_are_named(tmp_path):
    out = tmp_path / "m.feb"
    # the Macaulay fibre switch of the in vivo examples, under --strict
    _one_line_error(_run(str(example_model("invivo_goh_qlv")), "--out", str(out), "--strict"),
                    "goh switch = 'macaulay'", "layers[0] (skin)")
    spec = _GOH_QLV.replace("families = 2", "families = 1")
    (tmp_path / "one.toml").write_text(spec)
    _one_line_error(_run(str(tmp_path / "one.toml"), "--out", str(out)), "goh families = 1")
    (tmp_path / "fx.toml").write_text(_GOH_QLV + '\n[[effects]]\nname = "layer-slip"\n')
    _one_line_error(_run(str(tmp_path / "fx.toml"), "--out", str(out)), "[[effects]] layer-slip")
    static = _GOH_QLV.replace('kind = "sinusoid"', 'kind = "ramp"\nvalue = [0, 0, "-0.2 mm"]\nsteps = 2')
    static = "\n".join(ln for ln in static.splitlines()
                       if not ln.startswith(("peak_to_peak", "frequency", "periods", "steps_per_period")))
    (tmp_path / "static.toml").write_text(static)
    _one_line_error(_run(str(tmp_path / "static.toml"), "--out", str(out)), "[load] without duration")
    assert not out.exists()


def test_bad_inputs_are_one_line(tmp_path):
    model = str(example_model("phantom_membrane_gel"))
    _one_line_error(_run(str(tmp_path / "none.toml"), "--out", str(tmp_path / "m.feb")), "no such model file")
    _one_line_error(_run(str(example_model("extension_relaxation_lumped")), "--out", str(tmp_path / "m.feb")),
                    "lumped model", "finite-element")
    _one_line_error(_run(model, "--out", str(tmp_path / "no" / "m.feb")), "--out", "does not exist")
    existing = tmp_path / "old.feb"
    existing.write_text("keep")
    _one_line_error(_run(model, "--out", str(existing)), "--overwrite")
    assert existing.read_text() == "keep"
    assert _run(model, "--out", str(existing), "--overwrite").exit_code == 0
    assert existing.read_text().startswith("<?xml")
    _one_line_error(_run(model, "--out", str(tmp_path / "p.feb"), "--protocol", "x"), "--protocol")


def test_the_macaulay_switch_is_exported_with_a_warning_naming_it(tmp_path):
    """Without --strict: FEBio's Holzapfel-Gasser-Ogden with its own switch (I4 > 1), the
    difference said in one warning line, the GOH parameters written as for switch = 'febio'."""
    out = tmp_path / "m.feb"
    r = _run(str(example_model("invivo_quick")), "--out", str(out))
    assert r.exit_code == 0, r.output
    warnings = [ln for ln in r.stderr.splitlines() if ln.startswith("warning:")]
    assert any("goh switch = 'macaulay'" in w and "I4 > 1" in w for w in warnings), r.stderr
    mats = {m.get("name"): m for m in ET.parse(out).getroot().iter("material")}
    goh = next(m for m in mats["skin"].iter() if m.get("type") == "Holzapfel-Gasser-Ogden")
    assert float(goh.findtext("k1")) == pytest.approx(20e3 * 1e-6, rel=1e-12)   # 20 kPa in MPa
    assert float(goh.findtext("gamma")) == pytest.approx(30.0, rel=1e-12)
