"""Where a diagnosis spends its time: the stage clock's accounting (nested stages charged their own
time only, predictions counted where they happen) and a real diagnosis recorded by stage."""

from __future__ import annotations

import copy
import time

import pytest

from skinkit.forward import stages


def test_nested_stages_are_charged_their_own_time_and_solves():
    with stages.recording() as clock:
        t0 = time.perf_counter()
        with stages.stage("outer"):
            time.sleep(0.05)
            stages.count(3, 2, {"a": "analytic"})
            with stages.stage("inner"):
                t1 = time.perf_counter()
                time.sleep(0.1)
                stages.count(3, 0)
                stages.count(3, 1, {"a": "central-difference", "b": "analytic"})
            inner = time.perf_counter() - t1
            stages.count(3, 0, {"a": "analytic"})
        total = time.perf_counter() - t0
    s = {r["name"]: r for r in clock.to_dict()["stages"]}
    # the inner stage's time is its own; the outer is charged the rest, not both
    assert s["inner"]["seconds"] >= 0.1 and s["outer"]["seconds"] >= 0.05
    assert s["inner"]["seconds"] <= inner
    assert s["outer"]["seconds"] + s["inner"]["seconds"] <= total
    assert (s["outer"]["forward_equivalents"], s["inner"]["forward_equivalents"]) == (2, 2)
    assert (s["outer"]["protocol_solves"], s["inner"]["sensitivity_columns"]) == (6, 1)
    # a parameter differentiated numerically anywhere stays reported so
    assert clock.methods == {"a": "central-difference", "b": "analytic"}


def test_marks_outside_a_recording_do_nothing():
    with stages.stage("x"):
        stages.count(1, 1, {"a": "analytic"})
    with stages.recording() as clock:
        pass
    assert clock.to_dict()["forward_equivalents"] == 0


@pytest.mark.needs_plugins
def test_a_diagnosis_is_recorded_by_stage():
    """The mesh-null benchmark's gel with a force offset withheld (truth on the model's mesh): the
    calibration, the score sensitivities and the refit are stages of their own; the clock sees
    at least the predictions the report counts, and every parameter's derivative, the support's
    compliance at its null included, is analytic."""
    from skinkit.bench.gap_cases import plugin_values
    from skinkit.bench.mesh_nulls import CASES
    from skinkit.gap.diagnose import diagnose
    from skinkit.inverse.coverage import LabSessions

    spec, free = CASES["disc-gel"]()
    truth = copy.deepcopy(spec)
    typical, _, _ = plugin_values("force-offset")
    truth["effects"] = [{"name": "force-offset", **typical}]
    lab = LabSessions(truth, workers=1, mesh="shared")
    model = copy.deepcopy(lab.model_spec)
    model["effects"] = []
    with stages.recording() as clock:
        rep = diagnose(model, lab(0), effects=["support-compliance", "force-offset"], free=free, workers=1,
                       max_effects=1, candidates=1, model_error=False, error_estimate=False).to_dict()
    prof = clock.to_dict()
    names = [s["name"] for s in prof["stages"]]
    assert {"calibration", "score sensitivities", "reporting"} <= set(names), names
    by = {s["name"]: s for s in prof["stages"]}
    assert by["calibration"]["forward_equivalents"] >= 2
    assert by["score sensitivities"]["forward_equivalents"] >= 1
    if rep["named"]:
        assert f"refit {rep['named'][0]}" in by
    assert prof["forward_equivalents"] >= rep["n_forward"]
    assert {"gel.E", "support-compliance.compliance"} <= set(prof["methods"])
    assert set(prof["methods"].values()) == {"analytic"}, prof["methods"]
