"""The effect plugins (``skinkit.effects``) keep the contract of docs/guide/effects.md: every
installed effect, built-in or not, loads and satisfies the interface, declares SI units, bounds,
null and typical values, and ``apply`` edits a copy of a model description, only in the tables
the effect declares (``touches``); then the built-in effects make exactly their documented
edits. No solver runs here: null invariance and visibility of the predictions are checked by
the conformance kit (tests/plugin_surface) and the forward model's tests."""

from __future__ import annotations

import copy
import math
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from skinkit import registry
from skinkit.errors import EffectError
from skinkit.fem import lawkit
from skinkit.fem.model import build_model, read_model
from skinkit.interfaces import Effect, missing_members
from skinkit.units import si_unit

pytestmark = pytest.mark.needs_plugins

ROOT = Path(__file__).resolve().parents[2]
MODELS = ROOT / "docs" / "models"

#: every installed effect: a new one is checked like the built-in ones
EFFECTS = registry.names("skinkit.effects")


def effect(name: str) -> Any:
    return registry.create("skinkit.effects", name)


def typical(name: str) -> dict[str, float]:
    return {p.name: p.value for p in effect(name).parameters()}


def of_kind(kind: str) -> list[str]:
    """The installed effects that apply to models of ``kind``."""
    return [n for n in EFFECTS if kind in effect(n).kinds]


def not_of_kind(kind: str) -> list[str]:
    return [n for n in EFFECTS if kind not in effect(n).kinds]


def touches(name: str, kind: str) -> set[str] | None:
    """The top-level tables the effect declares it changes on a ``kind`` model (None: undeclared)."""
    declared = dict(getattr(effect(name), "touches", {}) or {})
    return set(declared[kind]) if kind in declared else None


def builtin_names() -> set[str]:
    """The effects the skinkit-plugins distribution registers (its pyproject.toml)."""
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib

    meta = tomllib.loads((ROOT / "plugins" / "pyproject.toml").read_text(encoding="utf-8"))
    return set(meta["project"]["entry-points"]["skinkit.effects"])


@pytest.fixture(scope="module")
def goh_qlv() -> dict[str, Any]:
    """The in vivo model: skin GOH inside a one-term QLV over a neo-Hookean subdermal layer."""
    from skinkit.fem.discretisation import pin_mesh
    # the example's physics on its earlier 9,747-unknown mesh: the effects' edits do not depend
    # on the mesh, and building the converged one for every case would only cost time
    return pin_mesh(read_model(MODELS / "invivo_goh_qlv.toml"), [2, 2], n_inner=3, n_ring=3, grading=1.6)


@pytest.fixture(scope="module")
def static_force() -> dict[str, Any]:
    """The pre-stretched neo-Hookean (``neo-hookean-ni``) skin under force control."""
    from skinkit.fem.discretisation import pin_mesh
    return pin_mesh(read_model(MODELS / "invivo_static_force.toml"), [1, 2], n_inner=2, n_ring=3, grading=1.6)


@pytest.fixture(scope="module")
def plain_nh(static_force) -> dict[str, Any]:
    """The same without the skin's pre-stretch: an isotropic skin every FE effect fits."""
    spec = copy.deepcopy(static_force)
    del spec["layers"][0]["prestress"]
    return spec


@pytest.fixture(scope="module")
def lumped() -> dict[str, Any]:
    return {"model": {"kind": "lumped", "name": "lumped-linear"}, "lumped": {"element": "linear", "k": 200.0}}


# -- registration and declarations --------------------------------------------------------------------
def test_every_builtin_effect_is_registered():
    assert builtin_names() <= set(EFFECTS)


@pytest.mark.parametrize("name", EFFECTS)
def test_every_effect_satisfies_the_protocol(name):
    e = effect(name)
    assert missing_members(e, Effect) == [], name
    assert isinstance(e, Effect)
    assert e.name == name
    assert e.kinds and set(e.kinds) <= {"fe", "lumped"}, name
    for kind, tables in dict(getattr(e, "touches", {}) or {}).items():
        assert kind in e.kinds and tables, (name, kind)


@pytest.mark.parametrize("name", EFFECTS)
def test_declared_parameters_are_si_bounded_with_null_and_typical_inside(name):
    e = effect(name)
    params = e.parameters()
    null = e.null()
    assert params and [p.name for p in params] == list(null)
    for p in params:
        assert p.unit == si_unit(p.unit), f"{name}.{p.name} is not in SI"
        assert p.lower < p.upper, p
        assert p.lower <= null[p.name] <= p.upper, p
        assert p.lower <= p.value <= p.upper, p
    # the typical magnitude must differ from the null somewhere, or the effect could never be seen
    assert any(p.value != null[p.name] for p in params), name


def test_the_typical_magnitudes_are_those_the_guidance_asks_for():
    """Spot checks in the units a reader thinks in (the full list is docs/guide/effects.md's table)."""
    assert typical("viscoelastic") == pytest.approx({"g1": 0.3, "tau1": 2.0})
    assert typical("prestress") == pytest.approx({"l1": 1.10, "l2": 1.03, "angle": math.radians(20)})
    assert typical("fibres")["k1"] == pytest.approx(20e3)
    assert typical("thickness")["delta"] == pytest.approx(0.3e-3)
    assert typical("force-offset") == pytest.approx({"x": 0.02, "y": 0.02, "z": 0.02})
    assert typical("tracking-bias") == pytest.approx({"scale": 0.01, "rotation": math.radians(0.5)})


# -- every effect: copy, no mutation, only its own tables, a valid description --------------------
def _apply_or_refuse(name: str, spec: dict[str, Any], p: dict[str, float]) -> dict[str, Any] | None:
    """``apply``'s result, or None when the effect refuses the model with an error naming it
    (``prestress`` on an already pre-stretched skin, ``fibres`` on a skin with fibres)."""
    try:
        return effect(name).apply(spec, p)
    except EffectError as exc:
        assert exc.entry == f"effects.{name}", exc
        return None


@pytest.mark.parametrize("spec_name", ["goh_qlv", "static_force", "plain_nh"])
@pytest.mark.parametrize("name", of_kind("fe"))
def test_apply_edits_a_copy_and_only_its_own_tables(name, spec_name, request):
    base = request.getfixturevalue(spec_name)
    before = copy.deepcopy(base)
    touched = touches(name, "fe")
    for p in (effect(name).null(), typical(name)):
        out = _apply_or_refuse(name, base, p)
        assert base == before, "apply modified its input"
        if out is None:
            assert spec_name != "plain_nh", f"{name} refuses the isotropic skin every FE effect fits"
            continue
        if touched is not None:
            assert set(out) - set(base) <= touched
            assert {k: v for k, v in out.items() if k not in touched} == \
                {k: v for k, v in base.items() if k not in touched}
        out["layers"][0]["name"] = "changed"  # the copy is deep: editing it leaves the input alone
        assert base == before


@pytest.mark.parametrize("name", of_kind("fe"))
def test_applied_descriptions_are_valid_models_at_null_and_typical(name, plain_nh, goh_qlv):
    for spec in (plain_nh, goh_qlv):
        for p in (effect(name).null(), typical(name)):
            out = _apply_or_refuse(name, spec, p)
            assert out is not None or spec is not plain_nh, name
            if out is not None:
                build_model(out, require_load=False)


@pytest.mark.parametrize("name", of_kind("lumped"))
def test_lumped_effects_edit_a_copy_and_only_their_own_tables(name, lumped):
    before = copy.deepcopy(lumped)
    out = effect(name).apply(lumped, typical(name))
    assert lumped == before
    touched = touches(name, "lumped")
    if touched is not None:
        assert {k: v for k, v in out.items() if k not in touched} == \
            {k: v for k, v in lumped.items() if k not in touched}
    assert out["lumped"]["k"] == 200.0 and out["lumped"]["element"] == "linear"


@pytest.mark.parametrize("name", not_of_kind("lumped"))
def test_an_fe_effect_on_a_lumped_model_is_an_error_naming_it(name, lumped):
    with pytest.raises(EffectError) as exc:
        effect(name).apply(lumped, effect(name).null())
    assert exc.value.entry == f"effects.{name}"
    assert "lumped" in exc.value.problem


@pytest.mark.parametrize("name", not_of_kind("fe"))
def test_a_lumped_effect_on_an_fe_model_is_an_error_naming_it(name, plain_nh):
    with pytest.raises(EffectError) as exc:
        effect(name).apply(plain_nh, effect(name).null())
    assert exc.value.entry == f"effects.{name}"


@pytest.mark.parametrize("name", [n for n in EFFECTS if getattr(effect(n), "once", True)])
def test_a_second_application_is_an_error_naming_the_effect(name, plain_nh, lumped):
    # an effect that leaves no trace to recognise declares once = False (thickness only moves an
    # interface); the forward model refuses the same effect twice in [[effects]] anyway
    for kind, spec in (("fe", plain_nh), ("lumped", lumped)):
        if kind not in effect(name).kinds:
            continue
        once = effect(name).apply(spec, typical(name))
        with pytest.raises(EffectError) as exc:
            effect(name).apply(once, typical(name))
        assert exc.value.entry == f"effects.{name}"


def test_unknown_parameters_are_refused_and_missing_ones_take_the_null(plain_nh):
    with pytest.raises(EffectError, match="unknown parameter"):
        effect("prestress").apply(plain_nh, {"l3": 1.0})
    out = effect("prestress").apply(plain_nh, {"l1": 1.2})
    assert out["layers"][0]["prestress"]["stretch"] == [1.2, 1.0]
    assert out["layers"][0]["prestress"]["angle"] == 0.0


# -- the edits, effect by effect ----------------------------------------------------------------------
def test_viscoelastic_adds_the_next_prony_term_to_a_qlv_skin(goh_qlv):
    out = effect("viscoelastic").apply(goh_qlv, {"g1": 0.2, "tau1": 30.0})
    skin, old = out["layers"][0], goh_qlv["layers"][0]
    assert skin["law"] == "qlv"
    assert skin["options"] == {**old["options"], "terms": 2}
    assert skin["parameters"] == {**old["parameters"], "g2": 0.2, "tau2": 30.0}
    assert out["bindings"] == {"viscoelastic.g1": "skin.g2", "viscoelastic.tau1": "skin.tau2"}
    assert out["layers"][1] == goh_qlv["layers"][1]


def test_viscoelastic_wraps_any_other_law_in_qlv_with_its_options(plain_nh):
    spec = copy.deepcopy(plain_nh)
    spec["layers"][0]["name"] = "dermis"  # the skin is the top layer, whatever its name
    spec["layers"][0]["options"] = {"volumetric": "log"}
    out = effect("viscoelastic").apply(spec, effect("viscoelastic").null())
    skin = out["layers"][0]
    assert skin["law"] == "qlv"
    assert skin["options"] == {"elastic": "neo-hookean-ni", "terms": 1,
                               "elastic_options": {"volumetric": "log"}}
    assert skin["parameters"] == {**spec["layers"][0]["parameters"], "g1": 0.0, "tau1": 2.0}
    assert out["bindings"] == {"viscoelastic.g1": "dermis.g1", "viscoelastic.tau1": "dermis.tau1"}


def test_viscoelastic_refuses_moduli_summing_to_one(goh_qlv):
    # the model's own g1 = 0.3: another 0.75 would leave no elastic equilibrium modulus
    with pytest.raises(EffectError, match="sum below 1"):
        effect("viscoelastic").apply(goh_qlv, {"g1": 0.75})


def test_lumped_viscoelastic_appends_a_relaxation_term(lumped):
    out = effect("viscoelastic").apply(lumped, {"g1": 0.3, "tau1": 2.0})
    assert out["lumped"]["relaxation"] == [{"g": 0.3, "tau": 2.0}]
    assert out["bindings"] == {"viscoelastic.g1": "lumped.g1", "viscoelastic.tau1": "lumped.tau1"}
    spec = copy.deepcopy(lumped)
    spec["lumped"]["relaxation"] = [{"g": 0.1, "tau": 0.5}]
    out = effect("viscoelastic").apply(spec, {"g1": 0.3})
    assert out["lumped"]["relaxation"][0] == {"g": 0.1, "tau": 0.5}
    assert out["bindings"]["viscoelastic.g1"] == "lumped.g2"


def test_prestress_writes_the_skin_prestress_and_binds_it(plain_nh, static_force):
    out = effect("prestress").apply(plain_nh, typical("prestress"))
    assert out["layers"][0]["prestress"] == {"stretch": [1.10, 1.03],
                                             "angle": pytest.approx(math.radians(20))}
    assert out["bindings"] == {f"prestress.{k}": f"skin.prestretch.{k}" for k in ("l1", "l2", "angle")}
    with pytest.raises(EffectError) as exc:
        effect("prestress").apply(static_force, effect("prestress").null())
    assert exc.value.entry == "effects.prestress" and "pre-stress" in exc.value.problem


@pytest.mark.parametrize("volumetric", [None, "log"])
def test_fibres_turn_the_neo_hookean_skin_into_goh_exactly_at_the_null(plain_nh, volumetric):
    spec = copy.deepcopy(plain_nh)
    if volumetric:
        spec["layers"][0]["options"] = {"volumetric": volumetric}
    out = effect("fibres").apply(spec, effect("fibres").null())
    skin, old = out["layers"][0], spec["layers"][0]
    assert skin["law"] == "goh"
    assert skin["options"] == {"families": 1, "switch": "macaulay", "volumetric": volumetric or "quadratic"}
    assert skin["parameters"]["c"] == old["parameters"]["mu"]
    assert skin["parameters"]["k"] == old["parameters"]["K"]
    assert skin["parameters"]["k1"] == 0.0
    assert out["bindings"] == {f"fibres.{k}": f"skin.{k}" for k in ("k1", "k2", "kappa", "gamma")}
    # the constitutive response at the null is the neo-Hookean's: same stress for any deformation
    m_old = build_model(spec, require_load=False).problem.materials[0]
    m_new = build_model(out, require_load=False).problem.materials[0]
    rng = np.random.default_rng(1)
    F = np.eye(3) + 0.2 * rng.standard_normal((5, 3, 3))
    C = np.einsum("nki,nkj->nij", F, F)
    S_old = lawkit.stress(m_old.law, C, m_old.params)
    S_new = lawkit.stress(m_new.law, C, m_new.params)
    assert np.allclose(S_new, S_old, rtol=1e-12, atol=1e-9 * np.abs(S_old).max())
    # and at the typical magnitude the fibres stiffen a stretch along gamma (and nothing else changes)
    fib = effect("fibres").apply(spec, typical("fibres"))
    typ = build_model(fib, require_load=False).problem.materials[0]
    g = typical("fibres")["gamma"]
    a = np.array([math.cos(g), math.sin(g), 0.0])
    F1 = np.eye(3) + 0.1 * np.outer(a, a)
    C1 = (F1.T @ F1)[None]
    s_typ = a @ lawkit.stress(typ.law, C1, typ.params)[0] @ a
    assert s_typ > a @ lawkit.stress(m_old.law, C1, m_old.params)[0] @ a


def test_fibres_extend_a_qlv_wrapped_neo_hookean_and_refuse_other_laws(plain_nh, goh_qlv):
    wrapped = effect("viscoelastic").apply(plain_nh, typical("viscoelastic"))
    out = effect("fibres").apply(wrapped, typical("fibres"))
    skin = out["layers"][0]
    assert skin["law"] == "qlv" and skin["options"]["elastic"] == "goh" and skin["options"]["terms"] == 1
    assert skin["options"]["elastic_options"] == {"families": 1, "switch": "macaulay",
                                                  "volumetric": "quadratic"}
    assert skin["parameters"]["g1"] == 0.3  # the viscous term stays
    assert out["bindings"]["viscoelastic.g1"] == "skin.g1" and out["bindings"]["fibres.k1"] == "skin.k1"
    # qlv's elastic law defaults to neo-hookean-ni: a qlv skin without the option fits too
    del wrapped["layers"][0]["options"]["elastic"]
    assert effect("fibres").apply(wrapped, {})["layers"][0]["options"]["elastic"] == "goh"
    with pytest.raises(EffectError) as exc:
        effect("fibres").apply(goh_qlv, effect("fibres").null())
    assert exc.value.entry == "effects.fibres" and "neo-hookean-ni" in exc.value.problem


def test_layer_slip_is_a_band_one_element_row_below_the_interface(goh_qlv):
    out = effect("layer-slip").apply(goh_qlv, {"ratio": 0.2})
    # skin 1.5 mm; subdermal 3.5 mm in 2 element layers: one row is 1.75 mm, half of it 0.875 mm
    assert out["fields"] == [{"name": "layer-slip", "kind": "band", "layers": ["subdermal"],
                              "depth": pytest.approx(1.5e-3 + 0.875e-3),
                              "half_width": pytest.approx(0.875e-3), "ratio": 0.2}]
    assert "bindings" not in out  # the field's ratio is named layer-slip.ratio itself


def test_layer_effects_need_a_second_layer(plain_nh):
    single = copy.deepcopy(plain_nh)
    single["layers"] = single["layers"][:1]
    for name in ("layer-slip", "fascia", "thickness"):
        with pytest.raises(EffectError) as exc:
            effect(name).apply(single, effect(name).null())
        assert exc.value.entry == f"effects.{name}" and "layers" in exc.value.problem


def test_fascia_is_a_band_in_the_last_layer_at_its_depth(goh_qlv):
    out = effect("fascia").apply(goh_qlv, {"ratio": 10.0, "depth": 4e-3})
    assert out["fields"] == [{"name": "fascia", "kind": "band", "layers": ["subdermal"], "depth": 4e-3,
                              "half_width": pytest.approx(0.875e-3), "ratio": 10.0}]
    # the typical depth (4 mm) is 80 % of the in vivo models' 5 mm
    assert typical("fascia")["depth"] == pytest.approx(0.8 * 5e-3)
    with pytest.raises(EffectError, match="not in the last layer"):
        effect("fascia").apply(goh_qlv, {"depth": 1e-3})  # inside the skin


def test_inclusion_is_a_field_on_the_skin(goh_qlv):
    out = effect("inclusion").apply(goh_qlv, typical("inclusion"))
    assert out["fields"] == [{"name": "inclusion", "kind": "inclusion", "layers": ["skin"],
                              "x": pytest.approx(3e-3), "y": pytest.approx(3e-3),
                              "radius": pytest.approx(2e-3), "ratio": 3.0}]


def test_preconditioning_softens_the_skin_or_the_lumped_element(goh_qlv, lumped):
    out = effect("preconditioning").apply(goh_qlv, {"softening": 0.2})
    # the default form is driven by the loading cycles: its scale "cycles" goes with it
    assert out["fields"] == [{"name": "preconditioning", "kind": "softening", "layers": ["skin"],
                              "softening": 0.2, "cycles": 1.0}]
    out = effect("preconditioning").apply(lumped, {"softening": 0.2})
    assert out["lumped"]["preconditioning"] == {"form": "cycles", "softening": 0.2, "cycles": 1.0}
    assert out["bindings"] == {"preconditioning.softening": "lumped.softening",
                               "preconditioning.cycles": "lumped.cycles"}


def test_thickness_moves_the_interface_and_keeps_the_total(goh_qlv):
    out = effect("thickness").apply(goh_qlv, {"delta": 0.3e-3})
    t = [L["thickness"] for L in out["layers"]]
    assert all(isinstance(x, float) for x in t)  # "1.5 mm" strings are written back in metres
    assert t == pytest.approx([1.8e-3, 3.2e-3])
    assert sum(t) == pytest.approx(5e-3, abs=1e-15)
    null = effect("thickness").apply(goh_qlv, effect("thickness").null())
    assert [L["thickness"] for L in null["layers"]] == [1.5e-3, 3.5e-3]
    thin = copy.deepcopy(goh_qlv)
    thin["layers"][0]["thickness"] = "0.5 mm"
    with pytest.raises(EffectError, match="effects.thickness"):
        effect("thickness").apply(thin, {"delta": -0.8e-3})


def test_support_compliance_makes_the_rim_elastic(goh_qlv):
    out = effect("support-compliance").apply(goh_qlv, {"compliance": 1e-6})
    assert out["boundary"] == {"fixed": ["outer", "bottom"], "compliance": {"sets": ["outer"], "value": 1e-6}}
    block = {"model": {"name": "b"}, "geometry": {"kind": "block", "size": [0.01, 0.01], "n": [2, 2]},
             "layers": goh_qlv["layers"], "boundary": {"fixed": ["bottom"]}}
    with pytest.raises(EffectError, match="no fixed rim"):
        effect("support-compliance").apply(block, {"compliance": 1e-6})


def test_instrument_effects_write_their_entries(goh_qlv):
    out = effect("indenter-tilt").apply(goh_qlv, {"angle": 0.05, "azimuth": 1.0})
    assert out["instrument"] == [{"kind": "tilt", "parameter": "indenter-tilt.angle", "value": 0.05,
                                  "azimuth": 1.0, "azimuth_parameter": "indenter-tilt.azimuth"}]
    for name, basis in (("force-offset", "constant"), ("force-drift", "time")):
        out = effect(name).apply(goh_qlv, {"x": 1.0e-3, "y": 2.0e-3, "z": 3.0e-3})
        assert out["instrument"] == [
            {"kind": "bias", "parameter": f"{name}.{a}", "value": v, "channel": "tip_force", "component": i,
             "basis": basis} for i, (a, v) in enumerate(zip("xyz", (1e-3, 2e-3, 3e-3), strict=True))]
    out = effect("robot-compliance").apply(goh_qlv, {"compliance": 1e-3})
    assert out["instrument"] == [{"kind": "series", "parameter": "robot-compliance.compliance", "value": 1e-3,
                                  "channel": "tip_position", "source": "tip_force"}]
    out = effect("tracking-bias").apply(goh_qlv, {"scale": 0.01, "rotation": 0.002})
    assert out["instrument"] == [
        {"kind": "similarity", "parameter": "tracking-bias.scale", "value": 0.01, "channel": "points",
         "mode": "scale"},
        {"kind": "similarity", "parameter": "tracking-bias.rotation", "value": 0.002, "channel": "points",
         "mode": "rotation"}]


def test_instrument_entries_accumulate_across_effects(goh_qlv):
    out = effect("force-offset").apply(goh_qlv, typical("force-offset"))
    out = effect("force-drift").apply(out, typical("force-drift"))
    out = effect("robot-compliance").apply(out, typical("robot-compliance"))
    assert [e["parameter"] for e in out["instrument"]] == \
        [f"force-offset.{a}" for a in "xyz"] + [f"force-drift.{a}" for a in "xyz"] + \
        ["robot-compliance.compliance"]


def test_effects_compose_into_one_valid_description(plain_nh):
    """Every FE effect in one model (thickness first, so the layer-slip band sits on the moved
    interface): the bindings of all survive and the result builds."""
    spec = plain_nh
    for name in ("thickness", "viscoelastic", "prestress", "fibres", "layer-slip", "fascia", "inclusion",
                 "preconditioning", "support-compliance", "indenter-tilt", "force-offset", "force-drift",
                 "robot-compliance", "tracking-bias"):
        spec = effect(name).apply(spec, typical(name))
    # viscoelastic 2, prestress 3, fibres 4, support-compliance 1
    assert len(spec["bindings"]) == 2 + 3 + 4 + 1
    assert {f["name"] for f in spec["fields"]} == {"layer-slip", "fascia", "inclusion", "preconditioning"}
    slip = next(f for f in spec["fields"] if f["name"] == "layer-slip")
    assert slip["depth"] - slip["half_width"] == pytest.approx(spec["layers"][0]["thickness"])
    build_model(spec, require_load=False)


# -- the plugin guide's third-party examples -----------------------------------------------------------
def _guide_effect(module: str, cls: str) -> Any:
    guide = (ROOT / "docs" / "guide" / "writing-plugins.md").read_text(encoding="utf-8")
    files = dict(re.findall(r"```\w+ file=(\S+)\n(.*?)```", guide, flags=re.S))
    src = files[f"skinkit-extra-effects/skinkit_extra_effects/{module}.py"]
    assert f"skinkit_extra_effects.{module}:{cls}" in files["skinkit-extra-effects/pyproject.toml"]
    ns: dict[str, Any] = {}
    exec(compile(src, f"skinkit_extra_effects/{module}.py", "exec"), ns)  # noqa: S102 - our own documentation
    return ns[cls]()


def test_the_plugin_guide_ageing_example_is_a_band_over_the_skin(goh_qlv):
    e = _guide_effect("ageing", "SkinAgeing")
    assert missing_members(e, Effect) == []
    before = copy.deepcopy(goh_qlv)
    out = e.apply(goh_qlv, {"ratio": 1.5})
    assert goh_qlv == before
    m = build_model(out, require_load=False)
    field = m.problem.fields[0]
    # φ = ratio throughout the skin (depths 0 to 1.5 mm), 1 at the null
    d = np.linspace(0.0, 1.5e-3, 7)[None, :]
    X = np.zeros(d.shape + (3,))
    assert np.allclose(field.value(X, d, 0.0), 1.5, rtol=0, atol=1e-12)
    null = build_model(e.apply(goh_qlv, e.null()), require_load=False).problem.fields[0]
    assert np.all(null.value(X, d, 0.0) == 1.0)
    with pytest.raises(EffectError, match="effects.skin-ageing"):
        e.apply(out, {"ratio": 1.5})
    with pytest.raises(EffectError, match="effects.skin-ageing"):
        e.apply({"model": {"kind": "lumped"}, "lumped": {}}, {"ratio": 1.5})


def test_the_plugin_guide_sensor_zero_example_biases_the_measuring_axis(goh_qlv, lumped):
    e = _guide_effect("zero", "SensorZero")
    fe = e.apply(goh_qlv, {"offset": 0.02})
    assert fe["instrument"] == [{"kind": "bias", "parameter": "sensor-zero.offset", "value": 0.02,
                                 "channel": "tip_force", "component": 2, "basis": "constant"}]
    assert e.parameters()[0].unit == "N" and e.parameters()[0].value == pytest.approx(0.02)
    spec = copy.deepcopy(lumped)
    spec["lumped"]["axis"] = "-y"
    assert e.apply(spec, {})["instrument"][0]["component"] == 1
