"""Model-file cases, each through ``skinkit solve`` on a small file derived from an
example in docs/models: one ``error:`` line naming the file's own entry and exit status 2, or a
solve whose sensitivities list every parameter of the model. No NumPy warning reaches the user."""

from __future__ import annotations

import copy
import json
import math
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit import registry
from skinkit.cli import cli
from skinkit.fem import lawkit
from skinkit.fem.errors import ModelError, SolverError
from skinkit.fem.mesh import block_mesh, disc_mesh
from skinkit.fem.model import build_model
from skinkit.fem.problem import Material, Problem
from skinkit.fem.solver import NewtonSolver
from tests.core._model_files import to_toml

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

pytestmark = pytest.mark.needs_plugins

MODELS = Path(__file__).resolve().parents[2] / "docs" / "models"


def example(name: str) -> dict:
    return tomllib.loads((MODELS / name).read_text(encoding="utf-8"))


def static_force() -> dict:
    """invivo_static_force.toml (pre-stretched skin, force control) on its coarsest mesh."""
    from skinkit.fem.discretisation import pin_mesh
    s = pin_mesh(example("invivo_static_force.toml"), [1, 1], n_inner=1, n_ring=1, grading=1.6)
    s["load"]["steps"] = 2
    return s


def cube() -> dict:
    """phantom_cube_box.toml on a 2 x 2 x 1 mesh."""
    from skinkit.fem.discretisation import pin_mesh
    s = pin_mesh(example("phantom_cube_box.toml"), [1], n=[2, 2])
    s["geometry"]["indenter_diameter"] = "12 mm"
    s["load"]["steps"] = 2
    return s


def solve(spec: dict, tmp_path: Path, *extra: str):
    path = tmp_path / "m.toml"
    path.write_text(to_toml(spec), encoding="utf-8")
    return CliRunner().invoke(cli, ["solve", str(path), "--no-vtu", "--out", str(tmp_path / "out"), *extra])


def one_error(r, entry: str, *words: str) -> str:
    assert r.exit_code == 2, (r.exit_code, r.output)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr  # no warning, no traceback before the message
    assert lines[0].startswith(f"error: {entry}: "), lines[0]
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert "mesh." not in lines[0]
    return lines[0]


def _ogden(mu1, alpha1):
    def f(s):
        s["layers"][0].update(law="ogden", parameters={"mu1": mu1, "alpha1": alpha1, "K": "250 kPa"})
    return f


def _qlv_two_terms(g1, g2):
    def f(s):
        s["layers"][0].update(law="qlv", options={"elastic": "neo-hookean-ni", "terms": 2},
                              parameters={"mu": "15 kPa", "K": "500 kPa", "g1": g1, "g2": g2,
                                          "tau1": "1 s", "tau2": "10 s"})
        s["load"]["duration"] = "1 s"
    return f


def _layer(i, **kw):
    def f(s):
        s["layers"][i].update(kw)
    return f


def _prestress(**kw):
    def f(s):
        s["layers"][0]["prestress"] = {**s["layers"][0]["prestress"], **kw}
    return f


# (base model, mutation, the entry named, words of the reason)
CASES = [
    (cube, _ogden("-5 kPa", 5.0), "layers[0].parameters.mu1", ["mu_i alpha_i > 0"]),
    (cube, _ogden("-5 kPa", -5.0), "layers[0].parameters.mu1", ["shear modulus"]),
    (cube, _ogden("5 kPa", 0.0), "layers[0].parameters.alpha1", ["non-zero"]),
    (cube, _ogden("5 kPa", 0.001), "layers[0].parameters.alpha1", ["non-zero"]),
    (static_force, _layer(0, elements="two"), "layers[0].elements", ["whole number"]),
    (static_force, _layer(0, elements=1.7), "layers[0].elements", ["whole number"]),
    (static_force, _qlv_two_terms(0.6, 0.6), "layers[0].parameters", ["sum below 1"]),
    (static_force, _qlv_two_terms(0.5, 0.5), "layers[0].parameters", ["sum below 1"]),
    (static_force, _prestress(stretch=["a lot", 1.03]), "layers[0].prestress.stretch[0]", ["number"]),
    (static_force, _prestress(angle="twenty"), "layers[0].prestress.angle", ["number"]),
    (static_force, lambda s: s["layers"][0].update(prestress={"F0": [[1.1, 0, 0], [0, "x", 0], [0, 0, 1]]}),
     "layers[0].prestress.F0", ["numbers"]),
    # quantities whose dimension is not 1, given in quotes without a unit
    (static_force, _layer(0, thickness="1.5"), "layers[0].thickness", ["no unit"]),
    (static_force, _layer(0, thickness="0.0015"), "layers[0].thickness", ["no unit"]),
    (static_force, _prestress(angle="20"), "layers[0].prestress.angle", ["no unit"]),
    (static_force, lambda s: s["geometry"].update(diameter="40"), "geometry.diameter", ["no unit"]),
    (static_force, lambda s: s["load"].update(value=[0, 0, "-0.02"]), "load.value[2]", ["no unit"]),
    (cube, lambda s: s["layers"][0]["parameters"].update(mu="5000"), "layers[0].parameters.mu",
     ["no unit"]),
    # the file's entries, not the mesh generator's
    (static_force, lambda s: s["geometry"].update(n_inner=0), "geometry.n_inner", ["[1, 200]"]),
    (static_force, lambda s: s["geometry"].update(indenter_diameter="40 mm"),
     "geometry.indenter_diameter", ["smaller than the disc"]),
    # found by the property test: a degenerate mesh, a table for a name, a norm that overflows
    (static_force, lambda s: s["geometry"].update(indenter_diameter=1e-300), "geometry", ["thin"]),
    (cube, lambda s: s["model"].update(name={"x": 1}), "model.name", ["string"]),
    (cube, lambda s: s["load"].update(value=[0, 0, -1e300]), "load.value", ["plausible range"]),
    (static_force, lambda s: s["layers"][0].update(law="qlv", options={
        "elastic": "neo-hookean-ni", "elastic_options": {"thicknes": 1}}), "layers[0].options",
     ["thicknes"]),
    (static_force, lambda s: s["layers"][0].update(law="qlv", options={"terms": [1]}),
     "layers[0].options", ["terms"]),
    (static_force, lambda s: s["model"].update(kind="fem"), "model.kind", ["'fe' or 'lumped'"]),
    # a layer's fit bounds: known parameters, [lower, upper] in the law's unit, inside the law's
    # admissible range and around the file's value
    (cube, _layer(0, bounds={"mus": ["1 kPa", "9 kPa"]}), "layers[0].bounds.mus", ["unknown parameter"]),
    (cube, _layer(0, bounds={"mu": ["9 kPa", "1 kPa"]}), "layers[0].bounds.mu", ["not below"]),
    (cube, _layer(0, bounds={"mu": ["1 kPa"]}), "layers[0].bounds.mu", ["[lower, upper]"]),
    (cube, _layer(0, bounds={"mu": ["1 kPa", "2 kPa"]}), "layers[0].bounds.mu", ["outside [1000, 2000]"]),
    (cube, _layer(0, bounds={"mu": ["-1 kPa", "9 kPa"]}), "layers[0].bounds.mu", ["admissible range"]),
    (cube, _layer(0, bounds={"mu": ["1 mm", "9 mm"]}), "layers[0].bounds.mu", ["unit"]),
    # parameters far beyond any tissue: refused before the arithmetic overflows
    (cube, lambda s: s["layers"][0]["parameters"].update(mu="1e300 kPa"), "layers[0].parameters.mu",
     ["plausible range"]),
]


@pytest.mark.parametrize(("base", "mutate", "entry", "words"), CASES,
                         ids=[f"{c[2]}-{i}" for i, c in enumerate(CASES)])
def test_issue_case_is_one_line_naming_the_file_entry(tmp_path, base, mutate, entry, words):
    spec = base()
    mutate(spec)
    one_error(solve(spec, tmp_path), entry, *words)
    assert not (tmp_path / "out").exists()


def test_a_layers_bounds_narrow_what_a_fit_may_give_it():
    """``bounds`` in a layer narrow its parameter's range in the model's parameters (what every
    fit, calibration and refit searches within); the others keep the law's admissible range."""
    from skinkit.forward import load

    spec = cube()
    spec["layers"][0]["bounds"] = {"mu": ["1 kPa", "20 kPa"]}
    with load(spec) as m, load(cube()) as plain:
        mu, mu0 = m.parameters().param("gel.mu"), plain.parameters().param("gel.mu")
        K, K0 = m.parameters().param("gel.K"), plain.parameters().param("gel.K")
    assert (mu.lower, mu.upper) == pytest.approx((1e3, 2e4)) and mu.value == mu0.value
    assert (K.lower, K.upper) == (K0.lower, K0.upper)


def test_dimensionless_quantities_may_be_quoted_numbers(tmp_path):
    spec = static_force()
    spec["layers"][1]["parameters"]["nu"] = "0.45"
    spec["layers"][0]["prestress"]["stretch"] = ["1.10", 1.03]
    assert build_model(spec).problem.materials[1].params["nu"] == 0.45


def test_negative_ogden_modulus_is_why_it_is_refused():
    """μ₁ = -5 kPa, α₁ = 5 (refused above) would answer tension with compression: the Cauchy
    stress along an isochoric 10 % stretch has the sign of μ₁ (the law's stress is checked
    directly; a model file cannot carry these values any more)."""
    law = registry.create("skinkit.laws", "ogden")
    lam = 1.1
    F = np.diag([lam, lam ** -0.5, lam ** -0.5])
    C = (F.T @ F)[None]
    for mu in (-5e3, 5e3):
        S = lawkit.stress(law, C, {"mu1": mu, "alpha1": 5.0, "K": 2.5e5})[0]
        sigma = F @ S @ F.T / np.linalg.det(F)
        assert np.sign(sigma[0, 0] - sigma[1, 1]) == np.sign(mu)


def test_ogden_small_strain_shear_modulus_is_sum_of_mu():
    """The law's form is Abaqus's, 2μᵢ/αᵢ² (...): the small-strain shear modulus is Σ μᵢ (the
    classic form's Σ μᵢᶜαᵢ/2 with μᵢᶜ = 2μᵢ/αᵢ), the quantity whose sign the checks guard.
    CC₁₂₁₂ at C = I is that modulus; the tangent is a central difference of the spectral stress,
    good to about 1e-7 of its scale (h² truncation, eps/h rounding with h = 1e-6)."""
    law = registry.create("skinkit.laws", "ogden", terms=2)
    p = {"mu1": 3e3, "alpha1": 6.0, "mu2": 1e3, "alpha2": -3.0, "K": 1e5}
    CC = lawkit.tangent(law, np.eye(3)[None], p)[0]
    assert CC[0, 1, 0, 1] == pytest.approx(4e3, rel=1e-5)


def test_mesh_generators_name_the_file_entries():
    with pytest.raises(ModelError, match=r"^geometry\.n_inner: "):
        disc_mesh(0.04, 0.004, [("skin", 0.0015, 1)], n_inner=0)
    with pytest.raises(ModelError, match=r"^geometry\.indenter_diameter: "):
        disc_mesh(0.04, 0.05, [("skin", 0.0015, 1)])
    with pytest.raises(ModelError, match=r"^layers\[1\]\.elements: "):
        disc_mesh(0.04, 0.004, [("skin", 0.0015, 1), ("sub", 0.003, 0)])
    with pytest.raises(ModelError, match=r"^layers: "):
        block_mesh((0.01, 0.01, 0.005), (2, 2, 1), [("a", 0.001, 1), ("b", 0.001, 1)])


class _Overflowing:
    """A law whose stress overflows beyond 1 % strain (exp of a huge argument): the arithmetic
    warns where the engine already knows the residual is not finite."""

    name = "test-overflowing"
    complex_safe = True

    def parameters(self):
        from skinkit.schemas import Parameter
        return [Parameter("mu", 1e4, "Pa", 0, np.inf), Parameter("K", 1e6, "Pa", 0, np.inf)]

    def energy(self, C, p):
        I1 = C[..., 0, 0] + C[..., 1, 1] + C[..., 2, 2]
        return p["mu"] * np.exp(1e6 * (I1 - 3) ** 2) + 0.5 * p["K"] * (I1 - 3) ** 2


def test_numerics_warnings_stay_out_of_the_way():
    spec = cube()
    model = build_model(spec)
    m0 = model.problem.materials[0]
    law = _Overflowing()
    problem = Problem(model.mesh, [Material(m0.region, law, {"mu": 1e4, "K": 1e6})], intorder=4)
    opts = copy.copy(model.options)
    opts.max_cuts = 2
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(SolverError, match="not finite|inverted|gave up"):
            NewtonSolver(problem, model.bc, opts).run(model.load.times)
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], caught


def _qlv_prestressed(viscous: bool) -> dict:
    s = static_force()
    s["layers"][0].update(law="qlv", options={"elastic": "neo-hookean-ni", "terms": 1},
                          parameters={"mu": "15 kPa", "K": "500 kPa", "g1": 0.3, "tau1": "1 s"})
    if viscous:
        s["load"]["duration"] = "1 s"
    s["output"] = {"sensitivities": True}
    return s


EXPECTED = ["skin.mu", "skin.K", "skin.g1", "skin.tau1", "skin.prestretch.l1", "skin.prestretch.l2",
            "skin.prestretch.angle", "subdermal.E", "subdermal.nu"]


@pytest.mark.parametrize("viscous", [False, True])
def test_every_parameter_has_a_sensitivity_static_and_viscous(tmp_path, viscous):
    r = solve(_qlv_prestressed(viscous), tmp_path, "--json")
    assert r.exit_code == 0, r.output
    info = json.loads(r.stdout)
    assert info["parameters"] == EXPECTED
    for st in info["steps"]:
        d = np.array(st["d_tip_displacement_m"])
        assert d.shape == (3, len(EXPECTED))
        assert np.all(np.isfinite(d))
    # the pre-stretch moves the tip (force control): its derivative is not a placeholder zero
    dz = np.array(info["steps"][-1]["d_tip_displacement_m"])[2]
    assert abs(dz[EXPECTED.index("skin.prestretch.l1")]) > 0


def test_viscous_prestretch_sensitivity_matches_differences(tmp_path):
    """d(tip z)/d(l1) through the QLV history against a central difference of two solves
    (h = 1e-4: truncation ~h² of an O(1) relative curvature, far below the 1e-3 allowed)."""
    from skinkit.fem.run import solve_model
    spec = _qlv_prestressed(True)
    _, info = solve_model(build_model(spec))
    d = np.array(info["steps"][-1]["d_tip_displacement_m"])[2, EXPECTED.index("skin.prestretch.l1")]
    h = 1e-4
    z = []
    for sgn in (1, -1):
        s = copy.deepcopy(spec)
        s["layers"][0]["prestress"]["stretch"][0] = 1.10 + sgn * h
        s["output"] = {}
        z.append(solve_model(build_model(s))[1]["steps"][-1]["tip_displacement_m"][2])
    fd = (z[0] - z[1]) / (2 * h)
    assert math.isclose(d, fd, rel_tol=1e-3), (d, fd)


def test_effects_in_the_file_are_solved_not_ignored(tmp_path):
    """``[[effects]] name = "prestress"`` gives the answer of the same pre-stretch written in
    the layer (it was ignored by ``skinkit solve``: the answer of another model)."""
    base = static_force()
    base["layers"][0].pop("prestress")
    with_effect = copy.deepcopy(base)
    with_effect["effects"] = [{"name": "prestress", "l1": 1.2, "l2": 1.0, "angle": 0.0}]
    written = copy.deepcopy(base)
    written["layers"][0]["prestress"] = {"stretch": [1.2, 1.0], "angle": 0.0}
    out = []
    for i, s in enumerate((with_effect, written, base)):
        d = tmp_path / str(i)
        d.mkdir()
        r = solve(s, d, "--json")
        assert r.exit_code == 0, r.output
        out.append(json.loads(r.stdout)["steps"][-1]["tip_displacement_m"][2])
    assert out[0] == pytest.approx(out[1], rel=1e-12)
    assert abs(out[0] - out[2]) > 1e-3 * abs(out[2])


def test_lumped_model_is_refused_by_solve(tmp_path):
    r = CliRunner().invoke(cli, ["solve", str(MODELS / "extension_relaxation_lumped.toml"),
                                 "--out", str(tmp_path / "out")])
    assert r.exit_code == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "lumped" in lines[0] and "skinkit predict" in lines[0], r.stderr
