"""The gap diagnosis never names an effect for a residual that discretisation
explains. Truth: a small neo-Hookean disc solved on a mesh refined 2x (no effect at all); model:
the same disc on its own, coarse mesh. The mesh is stiff, so the calibrated model leaves a residual
far above the noise, and candidate effects that soften the response (a thinner skin, a
compliant support, an inclusion) pass their score tests. With the discretisation check the
diagnosis solves the calibrated model on the 2x mesh, projects that error's signature out, and
names nothing, saying why; the candidates' raw tests are still reported as significant (so the
check, not a weak gap, is what stops the naming).

One homogeneous layer: under a displacement drive its response is linear in E, so the check's
linearisation about the calibrated point is exact and the test isolates the rule. (With two
layers and a mesh so coarse that the fitted modulus is half the truth, the linear projection
leaves part of the mesh error standing; the report then says how little of the excess an
exactly solved model would explain.)"""

from __future__ import annotations

import copy

import pytest

from skinkit.bench.mesh_nulls import CASES
from skinkit.fem.discretisation import refined_spec
from skinkit.gap.diagnose import diagnose

pytestmark = pytest.mark.needs_plugins


def test_discretisation_error_is_not_named_as_an_effect():
    from skinkit.inverse.coverage import LabSessions

    spec, _ = CASES["disc-gel"]()
    lab = LabSessions(refined_spec(spec, 2), workers=1, mesh="shared")
    model = copy.deepcopy(lab.model_spec)
    model["geometry"], model["layers"] = spec["geometry"], spec["layers"]
    rep = diagnose(model, lab(0), effects=["thickness", "support-compliance", "inclusion"],
                   free=["gel.E"], workers=1, max_effects=1, candidates=1, model_error=False)
    d = rep.to_dict()
    assert rep.named == [], d["messages"]
    assert d["gap"]["significant"], "the coarse mesh should leave a gap far above the noise"
    raw = [c["effect"] for c in d["candidates"] if c.get("significant")]
    assert raw, "some candidate's raw score test should be significant, or the check is not exercised"
    disc = d["discretisation"]
    assert set(raw) <= set(disc["explains"])
    assert disc["unknowns_refined"] > 5 * disc["unknowns"]
    # the mesh error alone, in noise units, is far above ν: it can carry the whole gap
    assert disc["chi2_discretisation"] > disc["dof"]
    text = " ".join(d["messages"])
    assert "discretisation" in text.lower() and "Not named" in text
