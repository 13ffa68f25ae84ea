"""Law plugins and the law machinery: conformance, derived stress/tangent, parameter checks."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit import registry
from skinkit.fem import lawkit
from skinkit.fem.conformance import check_law, sample_deformations
from skinkit.fem.errors import ModelError
from skinkit.fem.hyper import iso_I1, kinematics
from skinkit.interfaces import Law
from skinkit.schemas import Parameter

pytestmark = pytest.mark.needs_plugins

LAWS = [("neo-hookean", {}), ("neo-hookean-ni", {}), ("neo-hookean-ni", {"volumetric": "log"}),
        ("neo-hookean-enu", {}), ("mooney-rivlin", {}), ("ogden", {"terms": 1}),
        ("ogden", {"terms": 3}), ("goh", {}), ("goh", {"families": 1, "frame_angle": 0.4}),
        ("goh", {"switch": "macaulay"}),
        ("qlv", {"elastic": "goh", "terms": 2}), ("qlv", {"elastic": "ogden"})]


@pytest.mark.parametrize(("name", "opts"), LAWS)
def test_builtin_laws_pass_conformance(name, opts):
    law = registry.create("skinkit.laws", name, **opts)
    assert isinstance(law, Law)
    rep = check_law(law)
    assert rep.passed, str(rep)


class EnergyOnlyNH:
    """A third-party law written as an energy only (complex safe)."""

    name = "test-energy-only"
    complex_safe = True

    def parameters(self):
        return [Parameter("mu", 1e4, "Pa", 0, np.inf), Parameter("K", 2.5e5, "Pa", 0, np.inf)]

    def inadmissible(self, p):
        # the bounds admit 0, where the law has no shear or bulk stiffness (the conformance
        # kit's "admissible ranges" check finds that)
        return lawkit.require_positive(p, ["mu", "K"], "a small-strain modulus")

    def energy(self, C, p):
        Cinv, J, I1 = kinematics(C)
        I1b, _ = iso_I1(C, Cinv, J, I1)
        return 0.5 * p["mu"] * (I1b - 3) + 0.5 * p["K"] * (J - 1) ** 2


class EnergyOnlyReal(EnergyOnlyNH):
    """The same law, not declared complex safe: central differences are used."""

    complex_safe = False


@pytest.mark.parametrize("cls", [EnergyOnlyNH, EnergyOnlyReal])
def test_energy_only_law_gets_stress_and_tangent(cls):
    law = cls()
    ref = registry.create("skinkit.laws", "neo-hookean-ni")
    p = {"mu": 1e4, "K": 2.5e5}
    F = sample_deformations(8, seed=3)
    C = np.einsum("nkI,nkJ->nIJ", F, F)
    S, CC = lawkit.response(law, C, p)
    S_ref, CC_ref = lawkit.response(ref, C, p)
    # complex step: rounding only; central differences: h² truncation with h = 1e-6 on
    # O(1) strains and eps/h rounding, both below 1e-8 of the tangent's scale
    tol = 1e-9 if law.complex_safe else 1e-6
    assert np.abs(S - S_ref).max() <= tol * np.abs(S_ref).max()
    assert np.abs(CC - CC_ref).max() <= tol * np.abs(CC_ref).max()
    assert check_law(law).passed


def test_neo_hookean_enu_matches_thesis_constants():
    """Thesis Eqs 7.8-7.10: C10 = E/(4(1+ν)), D = 6(1-2ν)/E, W = C10(Ī1-3) + (J-1)²/D."""
    E, nu = 3e4, 0.48
    law = registry.create("skinkit.laws", "neo-hookean-enu")
    C10, D = E / (4 * (1 + nu)), 6 * (1 - 2 * nu) / E
    F = sample_deformations(5, seed=1)
    C = np.einsum("nkI,nkJ->nIJ", F, F)
    Cinv, J, I1 = kinematics(C)
    W_ref = C10 * (J ** (-2 / 3) * I1 - 3) + (J - 1) ** 2 / D
    np.testing.assert_allclose(law.energy(C, {"E": E, "nu": nu}), W_ref, rtol=1e-12)


def test_goh_fibres_only_in_tension():
    law = registry.create("skinkit.laws", "goh", families=1)
    p = lawkit.default_parameters(law)
    p["gamma"] = 0.0
    p0 = dict(p, k1=0.0)
    # fibre along x compressed: the fibre term must vanish (κ-dispersed fibres too)
    C = np.diag([0.8 ** 2, 1 / 0.8, 1 / 0.8])[None]
    np.testing.assert_allclose(law.stress(C, p), law.stress(C, p0), rtol=0, atol=1e-12)
    C = np.diag([1.2 ** 2, 1 / 1.2, 1 / 1.2])[None]
    assert law.stress(C, p)[0, 0, 0] > law.stress(C, p0)[0, 0, 0] + 1.0


def test_goh_energy_matches_febio_form():
    """Ψ = c/2(Ī1-3) + k1/(2k2) Σ(exp(k2 Ē²)-1) + k/2 (ln J)², Ē = κ(Ī1-3)+(1-3κ)(Ī4-1)."""
    law = registry.create("skinkit.laws", "goh", families=2)
    p = {"c": 1e4, "k1": 2e4, "k2": 3.0, "kappa": 0.2, "gamma": 0.5, "k": 1e5}
    F = np.diag([1.2, 1.05, 0.85])
    C = F.T @ F
    J = np.linalg.det(F)
    I1b = J ** (-2 / 3) * np.trace(C)
    W = 0.5 * p["c"] * (I1b - 3) + 0.5 * p["k"] * np.log(J) ** 2
    for s in (1, -1):
        a = np.array([np.cos(p["gamma"]), s * np.sin(p["gamma"]), 0])
        I4b = J ** (-2 / 3) * a @ C @ a
        if I4b > 1:
            E = p["kappa"] * (I1b - 3) + (1 - 3 * p["kappa"]) * (I4b - 1)
            W += p["k1"] / (2 * p["k2"]) * (np.exp(p["k2"] * E ** 2) - 1)
    np.testing.assert_allclose(law.energy(C[None], p)[0], W, rtol=1e-13)


def test_parameter_errors_name_the_entry():
    law = registry.create("skinkit.laws", "goh")
    p = lawkit.default_parameters(law)
    with pytest.raises(ModelError, match=r"skin\.kappa.*outside its admissible range"):
        lawkit.check_parameters(law, dict(p, kappa=0.4), "skin")
    with pytest.raises(ModelError, match="missing parameter"):
        lawkit.check_parameters(law, {k: v for k, v in p.items() if k != "k1"}, "skin")
    with pytest.raises(ModelError, match="unknown parameter"):
        lawkit.check_parameters(law, dict(p, mu=1.0), "skin")


def test_stress_parameter_derivative_matches_differences():
    for name in ("goh", "ogden", "neo-hookean-enu"):
        law = registry.create("skinkit.laws", name)
        p = lawkit.default_parameters(law)
        C = np.einsum("nkI,nkJ->nIJ", *(sample_deformations(4, seed=2),) * 2)
        for q in lawkit.parameter_names(law):
            d = lawkit.stress_parameter_derivative(law, C, p, q)
            h = 1e-5 * max(abs(p[q]), 1e-3)
            fd = (lawkit.stress(law, C, dict(p, **{q: p[q] + h}))
                  - lawkit.stress(law, C, dict(p, **{q: p[q] - h}))) / (2 * h)
            scale = max(np.abs(fd).max(), 1e-12 * np.abs(lawkit.stress(law, C, p)).max(), 1e-300)
            # central differences with a relative step 1e-5: truncation ~1e-10, rounding
            # ~eps/1e-5 ~ 1e-11 of the stress; 1e-5 relative leaves ample margin
            assert np.abs(d - fd).max() <= 1e-5 * scale + 1e-9, (name, q)
