"""Law parameters checked from the physics: each built-in law refuses what has
no positive small-strain shear or bulk stiffness (and Ogden's μᵢαᵢ ≤ 0 or αᵢ = 0, QLV's
Σ gᵢ ≥ 1) naming the parameter; the conformance kit checks that what a law's declared ranges
and conditions admit responds physically, so a third-party law that forgets a condition fails."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit import registry
from skinkit.fem import lawkit
from skinkit.fem.conformance import check_law, check_ranges, initial_moduli, parameter_sets
from skinkit.fem.errors import ModelError
from skinkit.fem.hyper import iso_I1, kinematics
from skinkit.schemas import Parameter

pytestmark = pytest.mark.needs_plugins


def _law(name, **opts):
    return registry.create("skinkit.laws", name, **opts)


def _defaults(law, **kw):
    return dict(lawkit.default_parameters(law), **kw)


# (law, options, overrides, the parameter named ("" for a joint condition), words of the reason)
REFUSED = [
    ("neo-hookean", {}, {"mu": 0.0}, "mu", "shear modulus"),
    ("neo-hookean-ni", {}, {"mu": 0.0}, "mu", "shear modulus"),
    ("neo-hookean-ni", {}, {"K": 0.0}, "K", "bulk modulus"),
    ("neo-hookean-enu", {}, {"E": 0.0}, "E", "Young's modulus"),
    ("mooney-rivlin", {}, {"c1": 0.0, "c2": 0.0}, "", "c1 + c2 must be positive"),
    ("mooney-rivlin", {}, {"K": 0.0}, "K", "bulk modulus"),
    ("ogden", {}, {"mu1": -5e3, "alpha1": 5.0}, "mu1", "mu_i alpha_i > 0"),
    ("ogden", {}, {"mu1": -5e3, "alpha1": -5.0}, "mu1", "shear modulus is sum mu_i"),
    ("ogden", {}, {"mu1": 0.0}, "mu1", "mu_i alpha_i > 0"),
    ("ogden", {}, {"alpha1": 0.0}, "alpha1", "non-zero"),
    ("ogden", {"terms": 2}, {"alpha2": 0.005}, "alpha2", "non-zero"),
    ("ogden", {}, {"K": 0.0}, "K", "bulk modulus"),
    ("goh", {}, {"c": 0.0}, "c", "fibres carry no load"),
    ("goh", {}, {"k": 0.0}, "k", "bulk modulus"),
    ("qlv", {"terms": 2}, {"g1": 0.6, "g2": 0.4}, "", "sum below 1"),
    ("qlv", {"elastic": "ogden"}, {"alpha1": 0.0}, "alpha1", "non-zero"),
    ("qlv", {"elastic": "goh"}, {"c": 0.0}, "c", "shear modulus"),
]


@pytest.mark.parametrize(("name", "opts", "over", "param", "words"), REFUSED,
                         ids=[f"{c[0]}-{i}" for i, c in enumerate(REFUSED)])
def test_builtin_law_refuses_unphysical_parameters(name, opts, over, param, words):
    law = _law(name, **opts)
    with pytest.raises(ModelError) as err:
        lawkit.check_parameters(law, _defaults(law, **over), "layers[0].parameters")
    entry = "layers[0].parameters" + (f".{param}" if param else "")
    assert str(err.value).startswith(f"{entry}: "), str(err.value)
    assert words in str(err.value)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(("name", "opts"), [
    ("neo-hookean", {}), ("neo-hookean-ni", {}), ("neo-hookean-enu", {}), ("mooney-rivlin", {}),
    ("ogden", {"terms": 1}), ("ogden", {"terms": 3}), ("goh", {}), ("goh", {"switch": "macaulay"}),
    ("qlv", {"elastic": "goh", "terms": 2}), ("qlv", {"elastic": "ogden"})])
def test_builtin_laws_admit_only_physical_responses(name, opts):
    law = _law(name, **opts)
    res = check_ranges(law)
    assert res.passed, res.detail
    rep = check_law(law)
    assert rep.passed, str(rep)
    assert {"initial moduli and tension", "admissible ranges"} <= {c.name for c in rep.checks}


def test_initial_moduli_match_closed_forms():
    """Isotropic small strain: CC = λ I⊗I + 2μ 𝕀, so bulk λ + 2μ/3 and shear μ; the compressible
    neo-Hookean (FEBio) has exactly those Lamé constants at C = I, the uncoupled one μ and K.
    Analytic tangents: agreement to rounding."""
    m = initial_moduli(_law("neo-hookean"), {"mu": 1e4, "lam": 4e4})
    assert m["shear"] == pytest.approx(1e4, rel=1e-12)
    assert m["bulk"] == pytest.approx(4e4 + 2e4 / 3, rel=1e-12)
    m = initial_moduli(_law("neo-hookean-ni"), {"mu": 1e4, "K": 2.5e5})
    assert m["shear"] == pytest.approx(1e4, rel=1e-12)
    assert m["bulk"] == pytest.approx(2.5e5, rel=1e-12)
    # Mandel eigenvalues of an isotropic tangent: 3K (once) and 2μ (five times)
    assert m["min_eigenvalue"] == pytest.approx(2e4, rel=1e-12)


def test_parameter_sets_cover_each_bound():
    law = _law("neo-hookean-enu")
    sets = parameter_sets(law, n=8, seed=3)
    assert any(s["E"] == 0.0 for s in sets)                   # a closed lower bound, as declared
    assert any(s["nu"] == pytest.approx(0.4999) for s in sets)
    assert any(s["nu"] == pytest.approx(-0.99) for s in sets)
    assert all(np.isfinite(list(s.values())).all() for s in sets)


# -- third-party laws: the kit finds what their authors forgot ------------------------------

class ThirdPartyNH:
    """An uncoupled neo-Hookean as an outside author might write it: energy only."""

    name = "third-party-nh"
    complex_safe = True

    def parameters(self):
        return [Parameter("mu", 1e4, "Pa", 0.0, np.inf), Parameter("K", 2.5e5, "Pa", 0.0, np.inf)]

    def energy(self, C, p):
        Cinv, J, I1 = kinematics(C)
        I1b, _ = iso_I1(C, Cinv, J, I1)
        return 0.5 * p["mu"] * (I1b - 3) + 0.5 * p["K"] * (J - 1) ** 2


class ThirdPartyNHChecked(ThirdPartyNH):
    """The same with the conditions its closed lower bounds cannot express."""

    def inadmissible(self, p):
        return lawkit.require_positive(p, ["mu", "K"], "a small-strain modulus")


class OgdenWithoutConditions:
    """Ogden's law as it was: μ over the whole line, no μα > 0 condition, α only bounded."""

    name = "ogden-unchecked"
    complex_safe = False

    def __init__(self):
        self._law = _law("ogden")

    def parameters(self):
        return [Parameter("mu1", 1e4, "Pa", -np.inf, np.inf), Parameter("alpha1", 8.0, "1", 0.5, 30.0),
                Parameter("K", 2.5e5, "Pa", 1.0, np.inf)]

    def energy(self, C, p):
        return self._law.energy(C, p)

    def stress(self, C, p):
        return self._law.stress(C, p)


class WrongSignBulk(ThirdPartyNHChecked):
    """A sign slip in the volumetric term: the reference state is unstable under expansion."""

    def energy(self, C, p):
        Cinv, J, I1 = kinematics(C)
        I1b, _ = iso_I1(C, Cinv, J, I1)
        return 0.5 * p["mu"] * (I1b - 3) - 0.5 * p["K"] * (J - 1) ** 2


def test_third_party_law_admitting_zero_moduli_fails_the_kit():
    rep = check_law(ThirdPartyNH())
    assert not rep.passed
    (bad,) = [c for c in rep.checks if not c.passed]
    assert bad.name == "admissible ranges"
    assert "not positive" in bad.detail and "inadmissible(p)" in bad.detail
    assert check_law(ThirdPartyNHChecked()).passed


def test_unconditioned_ogden_fails_on_negative_modulus():
    res = check_ranges(OgdenWithoutConditions())
    assert not res.passed
    assert "mu1=-" in res.detail   # a negative μ₁ with α₁ > 0: compression under tension


def test_wrong_sign_is_caught_at_the_parameters_checked():
    rep = check_law(WrongSignBulk())
    failed = {c.name: c.detail for c in rep.checks if not c.passed}
    assert "initial moduli and tension" in failed
    assert "bulk" in failed["initial moduli and tension"]
