"""The withheld-effect benchmark on truths with a mesh of their own: an effect's signature is the
truth with it less the truth without it, both on the truth's mesh, so the model's own
discretisation error is neither counted as the effect's nor lets a null look visible.

Exact checks: the no-effect truth against itself has signature 0 (the same arrays), while the
model's prediction against it does not: the model mesh's force error on this disc is about 20
noise levels RMS (``docs/results/mesh-nulls.md``), far beyond the detection threshold."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit.bench import gap_cases as gc
from skinkit.bench.mesh_nulls import CASES

pytestmark = [pytest.mark.needs_plugins, pytest.mark.slow]


@pytest.fixture(scope="module")
def base() -> gc._Base:
    spec, free = CASES["disc-two-layers"]()
    b = gc._base(spec, free, 1, "own")
    yield b
    gc.release()


def test_the_truth_without_an_effect_has_no_signature(base: gc._Base) -> None:
    s = base.signature(base.lab)
    assert s["raw"] == 0.0 and s["projected"] == 0.0


def test_the_models_mesh_error_is_not_an_effects(base: gc._Base) -> None:
    # the model's own prediction against the own-mesh truth: what the old signature counted
    res = base._objective(base.obs).residual(base.pred, jacobian=False)
    assert float(res.z @ res.z) > base.critical_excess
    # what a fit absorbs is judged on the model's response plus the signature: with none, the
    # model's own prediction, which it fits exactly
    shifted = gc._shifted(base.obs, base.obs, base.pred)
    res = base._objective(shifted).residual(base.pred, jacobian=False)
    assert float(res.z @ res.z) < 1e-12 * base.n


def test_the_cases_record_both_meshes(base: gc._Base) -> None:
    m = gc.meshes(base.lab)
    assert m["mesh"] == "own" and m["truth_unknowns"] >= 8 * m["model_unknowns"], m
    assert np.isfinite(base.critical_excess)


def test_the_oracle_measures_chi2_with_the_diagnosis_noise_model() -> None:
    """The oracle (the model with the truth's structure) nests the calibrated model: on the noise
    model the diagnosis used — the session carrying the model's mesh error — its χ² cannot exceed
    the calibration's, and an effect whose projected signature is many detection thresholds must
    read visible. Fitted on the raw session instead, the mesh error (tens of noise levels) would
    make its χ² far above the diagnosis's and every effect case "not visible"."""
    from skinkit.bench.gap_score import assess

    spec, free = CASES["disc-two-layers"]()
    payload = {"id": "drift", "kind": "effect", "magnitude": "moderate", "seed": 0,
               "effects": [gc.effect_at("force-drift", 1.0)], "spec": spec, "free": free, "workers": 1,
               "mesh": "own", "diagnose": {"max_effects": 1, "candidates": 2}}
    try:
        rec = gc.run_case(payload)
    finally:
        gc.release()
    assert "error" not in rec, rec.get("error")
    assert rec["signature"]["multiple"] > 10, rec["signature"]
    before, orc = rec["report"]["chi2"], rec["oracle"]
    assert orc["dof"] == before["dof_before"] - 3
    assert orc["chi2"] <= before["before"] * (1 + 1e-6), (orc["chi2"], before["before"])
    assert assess(rec)["visible"] is True
