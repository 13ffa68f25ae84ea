"""The model's discretisation error carried as noise (the approximation-error approach).

Algebra first: the rank-r whitening is exactly (I + V Vᵀ)^(−1/2), and an objective whose
observations carry an error shifts the residual by its mean and whitens with its covariance.
Then the point of it, on a truth the model cannot share: a small layered disc solved by the
virtual lab on a mesh of its own (2x finer in-plane, 3x through the thickness, its own gradings;
~10x the unknowns), the model on its coarse mesh. The coarse mesh is too stiff, so a fit that
ignores it lands the moduli tens of standard errors low; carried as noise, the error moves each
modulus most of the way back and the residual towards the noise.

What is asserted and why: the approximation-error model claims honest intervals: with the
error carried, each modulus lies within its 95 % interval of the truth (measured on seeds 0-2:
within 0.6-1.3 standard errors, against 10-95 without). The truth is itself a finite mesh, whose
own error the lab bounds in its truth file; on a truth 4x finer still, the two moduli move a little
further (the plain fit falls further too): a mesh this coarse is not in its asymptotic range,
which is why the error's amplitude is a free unknown per component and radial band.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from skinkit.inverse.approximation import ModelError, apply, whitening
from skinkit.inverse.objective import Objective
from skinkit.schemas import (
    Channel,
    ChannelPrediction,
    Observations,
    Prediction,
    Protocol,
    ProtocolObservations,
)


def test_whitening_is_the_inverse_square_root():
    """(I − Q diag(shrink) Qᵀ)² = (I + V Vᵀ)⁻¹ to rounding, for V of rank 3 (one column tiny)."""
    rng = np.random.default_rng(0)
    V = rng.standard_normal((40, 3)) * np.array([30.0, 1.0, 1e-3])
    Q, shrink = whitening(V)
    W = apply(Q, shrink, np.eye(40))
    np.testing.assert_allclose(W @ W, np.linalg.inv(np.eye(40) + V @ V.T), atol=1e-10)
    np.testing.assert_allclose(W, W.T, atol=1e-12)


def _obs(values: np.ndarray) -> Observations:
    t = np.arange(values.shape[0]) * 0.01
    ch = Channel("tip_force", t, values, noise=[0.5, 0.5, 0.5])
    return Observations({"p": ProtocolObservations(Protocol("p", "trajectory"), {"tip_force": ch})})


def test_objective_adds_the_mean_and_whitens_with_the_covariance():
    """z = (I + VVᵀ)^(−1/2) W (y_h + m − y): the mean shifts the prediction, the basis whitens
    residual and Jacobian alike."""
    rng = np.random.default_rng(1)
    y = rng.standard_normal((20, 3))
    pred_v = rng.standard_normal((20, 3))
    d = rng.standard_normal((20, 3))
    mean = 0.3 * rng.standard_normal((20, 3))
    basis = 2.0 * rng.standard_normal((2, 20, 3))
    obs = _obs(y)
    pred = Prediction({"p": {"tip_force": ChannelPrediction(pred_v, {"a": d})}})
    plain = Objective(None, obs, ["a"]).residual(pred)
    err = ModelError({("p", "tip_force"): mean}, {("p", "tip_force"): basis}, 2)
    carried = Objective(None, obs.with_model_error(err), ["a"]).residual(pred)
    z0 = ((pred_v + mean - y) / 0.5).ravel()
    V = np.stack([(b / 0.5).ravel() for b in basis], axis=1)
    Wh = np.linalg.inv(np.linalg.cholesky(np.eye(60) + V @ V.T))     # any inverse square root
    # the χ² is the whitening's invariant: |z|² = z0ᵀ (I + VVᵀ)⁻¹ z0
    assert carried.z @ carried.z == pytest.approx(float((Wh @ z0) @ (Wh @ z0)), rel=1e-10)
    np.testing.assert_allclose(plain.z, ((pred_v - y) / 0.5).ravel())
    # residual and Jacobian go through the same linear map
    Q, s = whitening(V)
    np.testing.assert_allclose(carried.J[:, 0], apply(Q, s, (d / 0.5).ravel()), atol=1e-12)
    # the error survives the observations' copies (fitted, held out, select, until)
    assert obs.with_model_error(err).fitted().model_error is err
    cut = obs.with_model_error(err).until(0.095)
    assert cut.model_error.mean[("p", "tip_force")].shape == (10, 3)
    assert cut.model_error.basis[("p", "tip_force")].shape == (2, 10, 3)


@pytest.mark.needs_plugins
def test_a_truth_on_its_own_mesh_biases_the_fit_and_the_carried_error_restores_its_intervals():
    from skinkit.forward import load
    from skinkit.inverse import fit
    from skinkit.inverse.approximation import refit
    from skinkit.inverse.coverage import LabSessions
    from tests.inverse.test_discretisation_bias import _spec

    spec = _spec()
    lab = LabSessions(spec, workers=1)
    mesh = lab.truth.truth["mesh"]
    assert mesh["mode"] == "own" and mesh["truth_unknowns"] >= 8 * mesh["model_unknowns"]
    truth = {"skin.E": 60e3, "subdermal.E": 10e3}
    free = list(truth)
    model = load(copy.deepcopy(lab.model_spec), workers=1)
    try:
        obs = lab(0)
        r0 = fit(model, obs, free)
        r1, carried = refit(model, obs, r0, free, fit)
    finally:
        model.close()
    me = r1.extra["model_error"]
    assert carried.model_error is not None and me["passes"] == 2
    for n, v in truth.items():
        # the coarse mesh is too stiff: the plain fit's moduli far below, outside their intervals
        assert truth[n] - r0.parameters[n] > 10 * r0.se[n], (n, r0.parameters[n], r0.se[n])
        # carried as noise, the error leaves it within its 95 % interval of the truth
        assert abs(r1.parameters[n] - v) <= 1.96 * r1.se[n], (n, r0.parameters[n], r1.parameters[n], r1.se[n])
    assert r1.chi2_per_dof < r0.chi2_per_dof
    for c in ("tip_force", "points"):
        assert me["channels"][c]["rms_over_noise"] > 1, me["channels"]
    assert me["accounts_for"] is not None and me["accounts_for"] > 0.5


def test_the_error_varies_with_the_parameters_as_its_derivatives_say():
    """The tangent estimate (draws=None) carries the error's variation over the parameters'
    spread from the refined-minus-model derivatives at the calibration (one solve per mesh); each such column
    must be what the error itself does when that parameter moves by its spread: checked by
    solving both meshes again at θ_j + s θ_j (the second-order terms of a 10 % move of a modulus
    are a few per cent of the change; 10 % of its largest entry is allowed)."""
    from skinkit.forward import load
    from skinkit.inverse.approximation import ORDER_HIGH, ORDER_LOW, SPREAD, _differences, estimate
    from skinkit.inverse.coverage import LabSessions
    from skinkit.inverse.discretisation import richardson_factor
    from tests.inverse.test_discretisation_bias import _spec

    lab = LabSessions(_spec(), workers=1)
    obs = lab(0).fitted()
    free = ["skin.E", "subdermal.E"]
    model = load(copy.deepcopy(lab.model_spec), workers=1)
    fine = model.refined(2)
    try:
        p = model.parameters()
        err = estimate(model, obs, p, free, draws=None)
        s = err.summary
        assert s["variation"] == "tangent" and s["solves"] == {"model_mesh": 1, "refined_mesh": 1}
        sampled = estimate(model, obs, p, free, draws=1)
        assert sampled.summary["variation"] == "draws" and sampled.summary["solves"]["refined_mesh"] == 2
        assert sampled.rank == 3 + 9 + 2
        np.testing.assert_array_equal(sorted(sampled.mean), sorted(err.mean))
        assert err.rank == 3 + 9 + len(free)          # tip amplitudes, point bands, one per parameter
        r_mid = 0.5 * (richardson_factor(2, ORDER_LOW) + richardson_factor(2, ORDER_HIGH))
        base = _differences(model.predict(p, obs), fine.predict(fine.parameters(), obs), obs)
        for j, name in enumerate(free):
            h = SPREAD * p[name]
            up = p.with_values({name: p[name] + h})
            fine_up = fine.parameters().with_values(up.values())
            moved = _differences(model.predict(up, obs), fine.predict(fine_up, obs), obs)
            for key, b in err.basis.items():
                want = r_mid * (moved[key] - base[key])
                got = b[err.rank - len(free) + j]
                scale = float(np.max(np.abs(want)))
                assert scale > 0
                np.testing.assert_allclose(got, want, atol=0.1 * scale), (name, key)
    finally:
        fine.close()
        model.close()



@pytest.mark.needs_plugins
def test_a_pass_within_the_spread_moves_the_estimate_as_solving_again_would():
    """A later pass whose parameters stayed within the draws' spread moves the last estimate to
    first order (∂(fine − coarse)/∂θ · Δθ, derivatives from the estimate's own solves) instead of
    solving both meshes again. Checked against solving both again at the moved point (same
    seed, so the same draw): half a spread on each modulus leaves second-order terms, a few per
    cent of the mean's change, 10 % allowed; beyond the spread it is not used."""
    from skinkit.forward import load
    from skinkit.inverse.approximation import MOVE_SPREADS, SPREAD, estimate
    from skinkit.inverse.coverage import LabSessions
    from tests.inverse.test_discretisation_bias import _spec

    lab = LabSessions(_spec(), workers=1)
    obs = lab(0).fitted()
    free = ["skin.E", "subdermal.E"]
    model = load(copy.deepcopy(lab.model_spec), workers=1)
    try:
        p = model.parameters()
        err = estimate(model, obs, p, free)
        # opposite ways: a common scale of both moduli leaves a displacement-driven field alone
        near = p.with_values({"skin.E": p["skin.E"] * (1 + 0.5 * SPREAD),
                              "subdermal.E": p["subdermal.E"] * (1 - 0.5 * SPREAD)})
        far = p.with_values({"skin.E": p["skin.E"] * (1 + 1.5 * MOVE_SPREADS * SPREAD)})
        assert err.reaches(near) and not err.reaches(far)
        moved = err.moved(near, obs)
        solved = estimate(model, obs, near, free)
    finally:
        model.close()
    assert moved.reaches(near) and moved.summary["moved_from"] == {n: p[n] for n in free}
    # moves do not chain beyond the reach of where both meshes were solved: within the reach of
    # the moved point, beyond the origin's
    beyond = p.with_values({"skin.E": p["skin.E"] * (1 + (MOVE_SPREADS + 0.3) * SPREAD)})
    assert not moved.reaches(beyond)
    for key, want in solved.mean.items():
        change = want - err.mean[key]
        scale = float(np.max(np.abs(change)))
        assert scale > 1e-3 * float(np.max(np.abs(want))), key
        np.testing.assert_allclose(moved.mean[key], want, atol=0.1 * scale, err_msg=str(key))
        # the spread's columns are differences of differences: the draw's, unchanged
        np.testing.assert_allclose(moved.basis[key][-1], err.basis[key][-1])
