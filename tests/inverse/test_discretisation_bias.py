"""A parameter identified on the default (coarse) mesh from a
virtual session generated on a fine mesh is biased by the discretisation; the bias must lie
within the discretisation error the fit reports.

Why the bounds. With Richardson's estimate at refinement 2 and an assumed order 1, the
reported bias is ``b = 2 (θ_h − θ_{h/2})``, while the truth on a 3x mesh leaves the coarse
fit a bias ``(1 − 3^{-p}) β`` with ``β`` the bias against the exact solution. For a true order
p between 1 and 2, ``θ_h − θ_{h/2} = (1 − 2^{-p}) β``, so the measured bias over the reported
one is ``(1 − 3^{-p}) / (2 (1 − 2^{-p}))``: 0.67 at p = 1, 0.64 at p = 1.3, 0.59 at p = 2.
The shift is taken in ln E, in which a modulus enters the force linearly (a neo-Hookean force
scales with E at fixed ν), so one Gauss-Newton step comes close even for a large bias; it
still understates a bias of order one a little (exp(1 − r) against 1/r for a force ratio r),
which moves the ratio up, not past 1 for biases below ~60 %… the test allows 0.3 to 1, plus
three standard errors of noise on either side.
"""

from __future__ import annotations

import numpy as np
import pytest

from skinkit.fem.discretisation import refined_spec
from skinkit.forward import load
from skinkit.inverse import fit
from skinkit.inverse.coverage import LabSessions
from skinkit.inverse.discretisation import (
    DiscretisationError,
    attach,
    estimate,
    extrapolated,
    residual_check,
    richardson_factor,
)

# the laws, effects and optimisers these tests use are built-in plugins
pytestmark = pytest.mark.needs_plugins


def _spec() -> dict:
    """A small layered disc (neo-Hookean skin over subdermal tissue, 735 unknowns), a 4 mm bonded
    indenter, one normal-indentation period: the mesh-null benchmark's two-layer case."""
    from skinkit.bench.mesh_nulls import CASES

    return CASES["disc-two-layers"]()[0]


def test_richardson_factor_and_extrapolation_are_exact_on_a_power_law():
    """y(h) = y* + C h^p: the extrapolation from h and h/2 recovers y* exactly at the true p."""
    from skinkit.schemas import ChannelPrediction, Prediction
    y_star, C, p = 2.0, 0.7, 1.3
    coarse = Prediction({"a": {"tip_force": ChannelPrediction(np.full((4, 3), y_star + C))}})
    fine = Prediction({"a": {"tip_force": ChannelPrediction(np.full((4, 3), y_star + C * 2 ** -p))}})
    ex = extrapolated(coarse, fine, 2, p)
    np.testing.assert_allclose(ex.protocols["a"]["tip_force"].values, y_star, rtol=1e-14)
    assert richardson_factor(2, 1.0) == pytest.approx(2.0)
    with pytest.raises(DiscretisationError, match="order"):
        richardson_factor(2, 0.0)


def test_residual_check_separates_what_the_parameters_absorb():
    """e inside J's span is absorbed (χ²_exact = |z|² and the bias is the lstsq shift); e
    orthogonal to it and to z adds to the residual the exact model would leave."""
    rng = np.random.default_rng(3)
    J = rng.standard_normal((400, 2))
    z = rng.standard_normal(400)
    z -= J @ np.linalg.lstsq(J, z, rcond=None)[0]          # a fit's residual: orthogonal to J
    e = J @ np.array([0.5, -2.0])
    chk = residual_check(z, J, e)
    np.testing.assert_allclose(chk["bias"], [0.5, -2.0], rtol=1e-12)
    assert chk["chi2_exact"] == pytest.approx(float(z @ z), rel=1e-10)
    assert chk["chi2_discretisation"] == pytest.approx(float(e @ e))


def test_fine_mesh_truth_coarse_fit_bias_within_reported_error():
    spec = _spec()
    truth = refined_spec(spec, 3)
    lab = LabSessions(truth, workers=1, mesh="shared")
    model_spec = dict(lab.model_spec)
    model_spec["geometry"] = spec["geometry"]
    model_spec["layers"] = spec["layers"]
    model = load(model_spec, workers=1)
    obs = lab(0)
    name = "subdermal.E"
    true_value = 10e3
    r = fit(model, obs, [name])
    est = estimate(model, obs, r.parameters, [name])
    attach(r, est)
    d = r.extra["discretisation"]
    assert d["unknowns_refined"] > 5 * d["unknowns"]
    reported = d["parameters"][name]["bias"]
    se = d["parameters"][name]["se"]
    measured = r.parameters[name] - true_value
    # the coarse mesh is stiff: the fitted modulus comes out low, well beyond the noise
    assert measured < -10 * se, (measured, se)
    assert np.sign(reported) == np.sign(measured)
    assert 0.3 * abs(reported) - 3 * se <= abs(measured) <= abs(reported) + 3 * se, (measured, reported, se)
    # the force channel carries an error the check names in newtons
    assert d["channels"]["tip_force"]["rms"] > 0
    # the fit's residual is mostly discretisation error: an exact model would leave near noise
    assert d["chi2_exact"] < d["chi2"]
