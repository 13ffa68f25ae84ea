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
