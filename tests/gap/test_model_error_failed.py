"""A diagnosis whose model error cannot be estimated still answers, and says so.

The model's refined copy (its mesh refined 2x, eight times the unknowns) is refused here for real
by the model's own size limit (``[solver] max_unknowns`` set between the model's unknowns and the
refined copy's), as a finite-element model whose finer mesh meets an instability, or exceeds the
machine, fails in its estimate. The calibration stands, the diagnosis goes on without the error,
and the report's warnings say what is missing and why."""

from __future__ import annotations

import copy

import pytest

pytestmark = pytest.mark.needs_plugins


def test_a_failed_model_error_estimate_is_a_warning_not_a_lost_diagnosis():
    from skinkit.bench.mesh_nulls import CASES
    from skinkit.gap.diagnose import diagnose
    from skinkit.inverse.coverage import LabSessions

    spec, _ = CASES["disc-gel"]()
    lab = LabSessions(spec, workers=1)
    model = copy.deepcopy(lab.model_spec)
    n = lab.truth.truth["mesh"]["model_unknowns"]
    model.setdefault("solver", {})["max_unknowns"] = 2 * n      # the model, not its 2x refinement
    said: list[str] = []
    rep = diagnose(model, lab(0), effects=["support-compliance"], free=["gel.E"], workers=1,
                   max_effects=1, candidates=1, progress=said.append)
    d = rep.to_dict()
    assert d["model_error"] is None and d["discretisation"] is None
    failed = [w for w in d["warnings"] if w["kind"] == "model-error-failed"]
    assert len(failed) == 1 and failed[0]["where"] == "model error"
    assert "max_unknowns" in failed[0]["message"] or "unknowns" in failed[0]["message"]
    assert any(failed[0]["message"] in m for m in d["messages"])
    assert any("could not be estimated" in line for line in said)
    # the calibration it fell back on is the plain fit's: a modulus and an interval
    assert d["fit"]["parameters"]["gel.E"] > 0 and d["fit"]["se"]["gel.E"] > 0
