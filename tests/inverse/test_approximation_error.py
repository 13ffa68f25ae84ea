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


def _disc_two_moduli():
    """The small layered disc's session (seed 0, truth on the model's mesh), its two moduli, and
    its model loaded on one worker (the caller closes it)."""
    from skinkit.forward import load
    from skinkit.inverse.coverage import LabSessions
    from tests.inverse.test_discretisation_bias import _spec

    lab = LabSessions(_spec(), workers=1)
    return lab(0), ["skin.E", "subdermal.E"], load(copy.deepcopy(lab.model_spec), workers=1)


def test_the_error_varies_with_the_parameters_as_its_derivatives_say():
    """The tangent estimate (draws=None) carries the error's variation over the parameters'
    spread from the refined-minus-model derivatives at the calibration (one solve per mesh); each such column
    must be what the error itself does when that parameter moves by its spread: checked by
    solving both meshes again at θ_j + s θ_j (the second-order terms of a 10 % move of a modulus
    are a few per cent of the change; 10 % of its largest entry is allowed)."""
    from skinkit.inverse.approximation import ORDER_HIGH, ORDER_LOW, SPREAD, _differences, estimate
    from skinkit.inverse.discretisation import richardson_factor

    session, free, model = _disc_two_moduli()
    obs = session.fitted()
    fine = model.refined(2)
    try:
        p = model.parameters()
        err = estimate(model, obs, p, free, draws=None)
        s = err.summary
        assert s["variation"] == "tangent" and s["solves"] == {"model_mesh": 1, "refined_mesh": 1}
        sampled = estimate(model, obs, p, free, draws=1)
        assert sampled.summary["variation"] == "draws" and sampled.summary["draws_from"] == "derivatives"
        assert sampled.summary["solves"] == {"model_mesh": 1, "refined_mesh": 1}
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
    from skinkit.inverse.approximation import MOVE_SPREADS, SPREAD, estimate

    session, free, model = _disc_two_moduli()
    obs = session.fitted()
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


@pytest.mark.needs_plugins
def test_a_draw_moved_to_by_the_derivatives_is_the_draw_solved():
    """The sampled estimate's draw is the calibration's difference moved by its derivatives, not
    solved: one solve per mesh instead of two. Checked against the same draw (same seed) solved
    on both meshes: a 10 % spread leaves second-order terms of a few per cent of the draw's
    change; 10 % of it (whitened) is allowed, and the means (which hold half the draw, times the
    Richardson factor) agree within 10 % of the draw's largest change."""
    from skinkit.bench.mesh_error import draw_linearity
    from skinkit.inverse.approximation import estimate

    session, free, model = _disc_two_moduli()
    obs = session.fitted()
    try:
        p = model.parameters()
        moved = estimate(model, obs, p, free, seed=3)
        solved = estimate(model, obs, p, free, seed=3, solve_draws=True)
    finally:
        model.close()
    assert moved.summary["draws_from"] == "derivatives" and solved.summary["draws_from"] == "solves"
    assert solved.summary["solves"] == {"model_mesh": 2, "refined_mesh": 2}
    miss = draw_linearity(solved, moved, obs)
    assert miss is not None and miss < 0.1, miss
    assert moved.rank == solved.rank
    d0, d1 = solved.source.diffs
    for key, want in solved.mean.items():
        change = float(np.max(np.abs(d1[key] - d0[key])))
        np.testing.assert_allclose(moved.mean[key], want, atol=0.1 * change + 1e-30, err_msg=str(key))


@pytest.mark.needs_plugins
def test_the_first_pass_starts_where_the_carried_chi2_is_lower():
    """A calibration the mesh's error has dragged far off (here both moduli a hundredth of the
    truth's) is a poor start for the first pass; the calibration's own start (the user's prior) is
    taken instead when the χ² carrying the error is lower there, and not otherwise."""
    from skinkit.inverse import fit
    from skinkit.inverse.approximation import _first_start, estimate

    obs, free, model = _disc_two_moduli()
    said: list[str] = []
    try:
        truth = {n: model.parameters()[n] for n in free}
        r = fit(model, obs, free, max_iterations=3)
        carried = obs.with_model_error(estimate(model, obs, r.parameters, free))
        r.extra["history"][0]["x"] = [truth[n] for n in r.extra["free"]]
        r.parameters = r.parameters.with_values({n: 0.01 * v for n, v in truth.items()})
        assert _first_start(model, carried, r, free, "noise", said.append) == truth
        assert "starts there" in said[-1]
        r.parameters = r.parameters.with_values(truth)
        r.extra["history"][0]["x"] = [0.01 * truth[n] for n in r.extra["free"]]
        assert _first_start(model, carried, r, free, "noise", said.append) == truth
        assert len(said) == 1
    finally:
        model.close()


def test_the_refined_member_carries_r_minus_one_of_the_same_pair():
    """Richardson's exact − coarse = R d gives exact − fine = (R − 1) d: R uniform over
    [R(2), R(1)] makes R − 1 uniform over the same width, so the refined member's mean and its
    spread's columns scale by (R̄ − 1)/R̄ and the order's amplitude columns are unchanged."""
    from skinkit.inverse.approximation import ORDER_HIGH, ORDER_LOW, _assemble
    from skinkit.inverse.discretisation import richardson_factor

    rng = np.random.default_rng(4)
    key = ("p", "tip_force")
    diffs = [{key: rng.standard_normal((10, 3))} for _ in range(3)]     # calibration and two draws
    groups = {key: [np.broadcast_to(np.arange(3) == j, (10, 3)).copy() for j in range(3)]}
    m0, b0, r0 = _assemble(diffs, None, groups, 2)
    m1, b1, r1 = _assemble(diffs, None, groups, 2, "refined")
    r_mid = 0.5 * (richardson_factor(2, ORDER_LOW) + richardson_factor(2, ORDER_HIGH))
    k = (r_mid - 1.0) / r_mid
    assert r0 == r1 == 3 + 3
    np.testing.assert_allclose(m1[key], k * m0[key], rtol=1e-13)
    np.testing.assert_allclose(b1[key][:3], b0[key][:3], rtol=1e-13)
    np.testing.assert_allclose(b1[key][3:], k * b0[key][3:], rtol=1e-13)


def test_resolution_is_the_whitened_share_of_the_signature_the_mesh_misses():
    """ρ_j = ‖W ∂(fine − coarse)/∂θ_j‖ / ‖W ∂coarse/∂θ_j‖ over the channels, each whitened by its
    own noise; a parameter only the refined mesh sees is infinite, one neither sees 0."""
    from skinkit.inverse.approximation import resolution

    rng = np.random.default_rng(5)
    s1, s2 = rng.standard_normal((20, 3)), rng.standard_normal((20, 3))
    t = np.arange(20) * 0.01
    ch = {"tip_force": Channel("tip_force", t, np.zeros((20, 3)), noise=[0.5, 0.5, 0.5]),
          "tip_position": Channel("tip_position", t, np.zeros((20, 3)), noise=[2.0, 2.0, 2.0])}
    obs = Observations({"p": ProtocolObservations(Protocol("p", "trajectory"), ch)})
    coarse = Prediction({"p": {"tip_force": ChannelPrediction(np.zeros((20, 3)), d={"a": s1, "b": s1}),
                               "tip_position": ChannelPrediction(np.zeros((20, 3)), d={"a": s2, "b": s2})}})
    derivs = {("p", "tip_force"): np.stack([0.3 * s1, 0.0 * s1, s1, 0.0 * s1]),
              ("p", "tip_position"): np.stack([0.3 * s2, 2.0 * s2, s2, 0.0 * s2])}
    rho = resolution(coarse, derivs, obs, ["a", "b", "c", "d"])
    assert rho["a"] == pytest.approx(0.3, rel=1e-12)
    # only the position channel's signature is misrepresented, twice over: weighted by its noise
    w1, w2 = np.sum((s1 / 0.5) ** 2), np.sum((s2 / 2.0) ** 2)
    assert rho["b"] == pytest.approx(np.sqrt(4 * w2 / (w1 + w2)), rel=1e-12)
    assert rho["c"] == np.inf and rho["d"] == 0.0      # seen by the refined mesh alone; by neither


def test_the_fit_summary_warns_of_the_parameters_the_mesh_cannot_render():
    """Over the limit, worst first (null in JSON for one only the refined mesh sees); the rest
    unnamed; a fit on the refined mesh is not warned of its model mesh's resolution."""
    from skinkit.inverse.approximation import RESOLUTION_LIMIT, describe, unresolved

    res = {"skin.E": 0.06, "inclusion.a": 1.15, "inclusion.x": 0.97, "inclusion.y": None}
    assert unresolved(res) == ["inclusion.y", "inclusion.a", "inclusion.x"]
    assert unresolved({"skin.E": RESOLUTION_LIMIT}) == []
    summary = {"factor": 2, "unknowns": 7395, "unknowns_refined": 50787, "channels": {}, "resolution": res}
    (warn,) = [ln for ln in describe(summary) if "warning" in ln]
    assert "inclusion.y (refined mesh only), inclusion.a (1.1), inclusion.x (0.97) do" in warn
    assert "skin.E" not in warn
    assert not any("warning" in ln for ln in describe(dict(summary, member="refined")))
    lines = describe(dict(summary, resolution={"inclusion.y": float("inf")}))
    (inf,) = [ln for ln in lines if "warning" in ln]
    assert "inclusion.y (refined mesh only) does" in inf


@pytest.mark.needs_plugins
def test_the_mesh_resolves_the_moduli_but_not_a_region_smaller_than_its_elements():
    """On the small layered disc (its ring elements several millimetres across) the refined
    mesh renders what the moduli do within a few tenths of their signature, but a stiff disc
    1 mm across (a fraction of an element) shifts with its centre and radius in a way the model's
    mesh only smears: the fit of such a region moves to the refined mesh, the moduli's do not
    (measured: moduli 0.26-0.32; the disc's centre and radius tens of times the limit; 3 mm across
    they are 0.47 and 0.33, under it)."""
    from skinkit.forward import load
    from skinkit.inverse.approximation import RESOLUTION_LIMIT, estimate
    from skinkit.inverse.coverage import LabSessions
    from tests.inverse.test_discretisation_bias import _spec

    spec = _spec()
    spec["effects"] = [{"name": "inclusion", "ratio": 4.0, "x": 0.0025, "y": 0.0, "radius": 0.0005}]
    lab = LabSessions(spec, workers=1)
    obs = lab(0).fitted()
    model = load(copy.deepcopy(lab.model_spec), workers=1)
    try:
        moduli = ["skin.E", "subdermal.E"]
        region = ["inclusion.x", "inclusion.radius"]
        rho = estimate(model, obs, model.parameters(), moduli + region).summary["resolution"]
    finally:
        model.close()
    assert max(rho[n] for n in moduli) < RESOLUTION_LIMIT, rho
    assert max(rho[n] for n in region) > RESOLUTION_LIMIT, rho


def test_on_the_refined_mesh_the_carried_error_keeps_the_intervals_honest():
    """The fit moved to the refined mesh, carrying that mesh's own error from the same pair, on
    a truth of its own mesh (the lab's, graded its own way), noiseless so that what is left is
    the bias: each modulus within its 95 % interval of the truth (measured: −1.4 and −0.1
    standard errors; on the model's mesh −0.8 and +1.2), where the refined mesh fitted with
    nothing carried is tens of standard errors off (it is no finer than the truth, whose own
    error the pair's difference stands for). ``auto`` keeps resolved moduli on the model's mesh."""
    from skinkit.forward import load
    from skinkit.inverse import fit
    from skinkit.inverse.approximation import refit
    from skinkit.inverse.coverage import LabSessions
    from tests.inverse.test_discretisation_bias import _spec

    lab = LabSessions(_spec(), workers=1)
    truth = {"skin.E": 60e3, "subdermal.E": 10e3}
    free = list(truth)
    model = load(copy.deepcopy(lab.model_spec), workers=1)
    try:
        obs = lab.noiseless()
        r0 = fit(model, obs, free)
        fine, _ = refit(model, obs, r0, free, fit, member="refined")
        auto, _ = refit(model, obs, r0, free, fit, member="auto", passes=1)
    finally:
        model.close()
    me = fine.extra["model_error"]
    assert me["member"] == "refined" and auto.extra["model_error"]["member"] == "model"
    for n, v in truth.items():
        assert abs(fine.parameters[n] - v) <= 1.96 * fine.se[n], (n, fine.parameters[n], fine.se[n])
    # the refined mesh's own error is the smaller part of the pair's: (R − 1)/R of the model's
    assert me["largest_over_noise"] < auto.extra["model_error"]["largest_over_noise"]
