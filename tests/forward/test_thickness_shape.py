"""A layer's thickness through the FE forward model by the shape derivative: against central
differences of whole solves, on a viscoelastic model fitted to a curved surface with points
embedded below it (every geometric term: moved nodes, moved depths, the fit's fading offsets,
points read at moved local coordinates), in both drive modes; and an elastic model on a compliant rim."""

from __future__ import annotations

import copy

import _directional
import numpy as np
import pytest
from test_fe_forward import SPEC, _cap, session

from skinkit.schemas import Observations

pytestmark = pytest.mark.needs_plugins


def _model(mode: str, delta: float):
    from skinkit.forward import load
    spec = copy.deepcopy(SPEC)
    spec["indenter"]["mode"] = mode
    spec["surface"] = {"fit": True, "outside": "nearest"}
    spec["output"] = {"point_depth": "0.3 mm"}
    spec["effects"] = [{"name": "thickness", "delta": delta}]
    return load(spec, workers=1)


@pytest.mark.parametrize(("mode", "delta"), [("force", 3e-4), ("displacement", 0.0)])
def test_thickness_by_the_shape_derivative_matches_central_differences(mode, delta):
    """``thickness.delta`` at a typical value and at its null: every channel's derivative against
    central differences of whole solves with h = 1e-6 of its scale (0.3 mm, or 23 µm at 0),
    through the QLV skin's history. Tolerance 2e-5 of the channel's largest derivative, as for
    the engine's other parameters (test_fe_forward): truncation (h/t)² < 1e-7, solver error
    ~rtol / h = 1e-6 relative; the design velocity's own differences add < 1e-9."""
    m = _model(mode, delta)
    base = session(mode)
    obs = Observations(base.protocols, _cap(), "test")
    name = "thickness.delta"
    pred = m.predict(m.parameters(), obs, sensitivities=[name])
    assert pred.methods == {name: "analytic (shape)"}
    p = m.parameters().param(name)
    scale = abs(p.value) if p.value else 0.01 * (p.upper - p.lower)
    _, worst = _directional.check(m, obs, [name], {name: scale}, seed=5, tol=2e-5, pred=pred)
    assert worst > 0
    # the derivative is not trivially zero in any channel the thickness moves
    for _, c, cp in pred.items():
        assert np.abs(cp.d[name]).max() > 0, c


def test_thickness_with_an_elastic_support_matches_central_differences():
    """An elastic model on a compliant rim (``support-compliance``): the rim's springs (face area
    over compliance) change as the layers' side faces do, a term the derivative must carry
    (leaving it out errs by 7 % here). Tolerance 2e-5 as above; measured 2.5e-7."""
    from test_effects_forward import BASE
    from test_effects_forward import session as oblique

    from skinkit.forward import load
    spec = copy.deepcopy(BASE)
    spec["effects"] = [{"name": "thickness", "delta": 3e-4},
                       {"name": "support-compliance", "compliance": 1e-6}]
    m = load(spec, workers=1)
    name = "thickness.delta"
    pred = m.predict(m.parameters(), oblique(), sensitivities=[name])
    assert pred.methods == {name: "analytic (shape)"}
    _directional.check(m, oblique(), [name], {name: 3e-4}, seed=3, tol=2e-5, pred=pred)
