"""Objective grids, profile likelihoods and the plots of a fit.

Virtual sessions: a lumped exponential (Fung) element with a force-sensor zero, F = a(e^(bx) − 1)
+ offset, driven by two ramps of the recorded position (50 Hz, 30 s, force noise 5 mN); its
residual is linear in a and offset and nonlinear in b. A linear element (F = kx + offset) is
exactly linear in both. Noise is Gaussian at the level the channels state, so with the
``noise`` weighting 2φ is a χ².
"""

from __future__ import annotations

import copy
import math
import warnings

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.forward import load
from skinkit.inverse import Objective
from skinkit.inverse.grid import CHI2_1_95, CHI2_2_95, GridError, objective_grid, span_from_se
from skinkit.inverse.scaling import Scaling
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

NOISE_F = 5e-3
X_MAX = 9e-3


def spec(kind: str) -> dict:
    el = {"linear": ("linear", {"k": 30.0}), "fung": ("exponential", {"a": "15 mN", "b": 320.0})}[kind]
    return {"model": {"kind": "lumped", "name": f"test-{kind}"},
            "lumped": {"axis": "x", "elastic": el[0], "parameters": el[1]},
            "instrument": [{"kind": "bias", "parameter": "offset.x", "value": "-20 mN",
                            "channel": "tip_force", "component": 0, "basis": "constant"}]}


def session(model, seed: int = 0) -> Observations:
    """Two ramp-hold-return protocols (to 9 and 6 mm), predicted at the model's own values plus noise."""
    t = np.arange(0, 30.0001, 0.02)
    skel = {}
    for k, amp in enumerate((X_MAX, 6e-3)):
        x = amp * np.clip(t / 5, 0, 1) * (t < 15) + amp * np.clip((20 - t) / 5, 0, 1) * (t >= 15)
        X = np.full((t.size, 3), np.nan)
        X[:, 0] = x
        chans = {"tip_position": Channel("tip_position", t, X, noise=1e-6),
                 "tip_force": Channel("tip_force", t, np.where(np.isnan(X), np.nan, 0.0), noise=NOISE_F)}
        skel[f"ramp{k}"] = ProtocolObservations(Protocol(f"ramp{k}", kind="external"), chans)
    obs = Observations(skel, None, "virtual")
    pred = model.predict(model.parameters(), obs)
    rng = np.random.default_rng(seed)
    out = {}
    for po in obs:
        ch = dict(po.channels)
        for c, cp in pred.protocols[po.name].items():
            o = ch[c]
            noisy = np.where(o.valid, cp.values + o.noise * rng.standard_normal(cp.values.shape), np.nan)
            ch[c] = Channel(c, o.time_s, noisy, noise=o.noise)
        out[po.name] = ProtocolObservations(po.protocol, ch)
    return Observations(out, None, "virtual")


@pytest.fixture(scope="module")
def fung():
    m = load(spec("fung"))
    return m, session(m)


def _conditional_se(model, obs, params, pair) -> np.ndarray:
    """Standard errors of the pair with every other parameter held fixed: √diag((JᵀJ)⁻¹)."""
    res, _ = Objective(model, obs, list(pair)).evaluate(params)
    return np.sqrt(np.diag(np.linalg.inv(res.J.T @ res.J)))


def test_grid_minimum_is_where_the_noise_allows(fung):
    """Grid about the truth, ±4 conditional se: the truth lies inside the 99.99 % joint region of
    the grid's own minimum (2Δφ = Δχ² ≤ χ²₂(0.9999) = 18.4 with known noise), and the minimum
    lies within 4.3 se (the extent of that region along an axis, √18.4) plus one grid step of
    the truth in each parameter."""
    model, obs = fung
    truth = model.parameters()
    pair = ("lumped.a", "lumped.b")
    se = _conditional_se(model, obs, truth, pair)
    sc = Scaling.for_parameters(truth, list(pair))
    span = span_from_se(sc, np.array([truth[p] for p in pair]), se, 4.0)
    g = objective_grid(model, obs, pair, n=11, span=span, around=truth)
    assert g["n_forward"] == 11 * 11 + 1 and not g["failed"]
    assert g["parameters"]["lumped.a"]["values"][5] == pytest.approx(truth["lumped.a"], rel=1e-12)
    d2 = 2 * (g["centre_objective"] - g["minimum"]["objective"])
    assert 0 <= d2 <= 18.4
    for k, p in enumerate(pair):
        step = 8 * se[k] / 10
        assert abs(g["minimum"][p] - truth[p]) <= math.sqrt(18.4) * se[k] + step, p
    # the objective is φ = ½ Σ z², the quantity skinkit.inverse.fit minimises: at the centre ½ χ²
    res, _ = Objective(model, obs, []).evaluate(truth, jacobian=False)
    assert g["centre_objective"] == pytest.approx(0.5 * float(res.z @ res.z), rel=1e-12)


@pytest.mark.needs_plugins
def test_grid_is_the_gauss_newton_quadratic_near_the_optimum(fung):
    """A 3 × 3 grid about the fitted optimum, steps δ of 2 conditional se (½δᵀHδ ≈ 2 per axis).

    With z(±δ) = z₀ ± a + q/2 (a odd, q even in δ), exactly:
    ½[φ(+δ) + φ(−δ)] − φ₀ = ½|a|² + ½ z₀·q + ⅛|q|², and φ(+δ) − φ(−δ) = 2 z₀·a + a·q.
    Gauss–Newton predicts ½|Jδ|² and 2 z₀ᵀJδ (= 0 at the optimum). q = y(+δ) + y(−δ) − 2y₀ is
    the model's own curvature (the data cancel), computed here; z₀·q is a sum of noise against
    it, N(0, |q|²) at most, so 4|q| bounds it; |a|² − |Jδ|² is of fourth order (δ³ terms of a,
    relative (x_max Δb)² ≈ 1e-4 here), allowed 0.2 % of the quadratic; a·q ≤ |Jδ||q| (5 % for
    the δ³ part of a). Measured: the even differences agree with ½|Jδ|² to 3e-4 across the
    valley and 0.6 % along it, well inside."""
    from skinkit.inverse import fit

    model, obs = fung
    r = fit(model, obs, ["lumped.a", "lumped.b", "offset.x"], ftol=1e-12, xtol=1e-10)
    best = r.parameters
    pair = ("lumped.a", "lumped.b")
    se = _conditional_se(model, obs, best, pair)
    sc = Scaling.for_parameters(best, list(pair))
    c = sc.to_scaled(np.array([best[p] for p in pair]))
    span = span_from_se(sc, np.array([best[p] for p in pair]), 2 * se, 1.0)
    g = objective_grid(model, obs, pair, n=3, span=span, around=best)
    phi = np.array(g["objective"], float)
    obj = Objective(model, obs, list(pair))
    res0, _ = obj.evaluate(best)
    z0, J = res0.z, res0.J * sc.dvalue_dscaled(c)[None, :]      # ∂z/∂θ in scaled coordinates
    for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
        d = np.array([di * span[0], dj * span[1]])
        zp, _ = obj.evaluate(best.with_values(dict(zip(pair, sc.to_values(c + d), strict=True))), False)
        zm, _ = obj.evaluate(best.with_values(dict(zip(pair, sc.to_values(c - d), strict=True))), False)
        q = zp.z + zm.z - 2 * z0
        quad = 0.5 * float((J @ d) @ (J @ d))
        assert quad > 1.5   # every step leaves the noise: 2 se along the valley, far more across it
        even = 0.5 * (phi[1 + di, 1 + dj] + phi[1 - di, 1 - dj]) - phi[1, 1]
        tol = 2 * np.linalg.norm(q) + np.linalg.norm(q) ** 2 / 8 + 0.002 * quad
        assert abs(even - quad) <= tol, (di, dj, even, quad, tol)
        odd = phi[1 + di, 1 + dj] - phi[1 - di, 1 - dj]
        gn = 2 * float(z0 @ (J @ d))
        assert abs(odd - gn) <= np.linalg.norm(J @ d) * np.linalg.norm(q) * 1.05 + 0.002 * quad, (di, dj)
        assert abs(gn) < 0.1   # the fitted optimum: the gradient is nearly zero


@pytest.mark.needs_plugins
def test_profile_interval_is_wald_for_a_linear_model():
    """F = kx + offset is linear in both: the profile φ̃(k) is exactly a parabola, its signed root
    a straight line, so the profile interval is θ̂ ± 1.96 se to the re-fits' tolerance."""
    from skinkit.inverse.grid import profile_likelihood

    m = load(spec("linear"))
    obs = session(m, seed=3)
    pr = profile_likelihood(m, obs, "lumped.k", n=9)
    lo, hi = pr["interval"]
    wlo, whi = pr["wald_interval"]
    assert abs(lo - wlo) < 1e-3 * pr["se"] and abs(hi - whi) < 1e-3 * pr["se"]
    assert pr["threshold"] == pytest.approx(CHI2_1_95 * pr["inflation"])
    assert pr["free"] == ["offset.x"] and pr["estimate"] == pytest.approx(30.0, abs=5 * pr["se"])


@pytest.mark.needs_plugins
def test_profile_interval_agrees_with_fisher_for_a_nearly_linear_parameter(fung):
    """a in F = a(e^(bx) − 1) + offset, b and the offset re-fitted at each value. a and the offset
    enter linearly; b does not: ∂F/∂b = a x e^(bx) changes by a relative x Δb over Δb, so over
    the interval (Δb, b re-fitted along the a–b valley, x ≤ 9 mm) the model departs from linear
    by ≈ x_max Δb (asserted below 5 %). The interval ends then move by that fraction of their 1.96 se
    distance: 0.1 se is a safe bound."""
    from skinkit.inverse.grid import profile_likelihood

    model, obs = fung
    pr = profile_likelihood(model, obs, "lumped.a", n=9)
    assert set(pr["free"]) == {"lumped.b", "offset.x"}
    # how far b moves while a crosses its interval: the slope of the re-fitted b times 1.96 se_a
    db = abs(np.polyfit(pr["values"], pr["others"]["lumped.b"], 1)[0]) * 1.96 * pr["se"]
    assert X_MAX * db < 0.05
    lo, hi = pr["interval"]
    wlo, whi = pr["wald_interval"]
    assert lo is not None and hi is not None
    assert abs(lo - wlo) < 0.1 * pr["se"] and abs(hi - whi) < 0.1 * pr["se"]
    # the χ² reading: at the interval's ends 2Δφ = 3.84 s, along the profile
    assert pr["delta_2phi"][4] == pytest.approx(0.0, abs=1e-3)
    assert max(pr["delta_2phi"]) > pr["threshold"]


def _png(path) -> None:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000, path


@pytest.mark.needs_plugins
def test_plots_of_a_lumped_fit_are_written(fung, tmp_path):
    """A lumped session has tip channels only: loops and the correlation matrix; the grid and
    the profile plots from their dicts (with the fit's ellipses attached)."""
    from skinkit.inverse import fit
    from skinkit.inverse.grid import attach_covariance, profile_likelihood
    from skinkit.inverse.plots import fit_plots, grid_plot, profile_plot

    model, obs = fung
    r = fit(model, obs)
    paths = fit_plots(model, obs, r, tmp_path / "fit")
    assert sorted(p.name for p in paths) == ["correlation.png", "loops.png"]
    for p in paths:
        _png(p)
    names = r.extra["free"]
    g = objective_grid(model, obs, ("lumped.a", "lumped.b"), n=9, around=r.parameters, span=0.05)
    g = attach_covariance(g, names, r.covariance, {n: r.parameters[n] for n in names},
                          r.identifiability["inflation"])
    assert g["ellipse_level"] == pytest.approx(CHI2_2_95)
    cond, marg = np.array(g["covariance_conditional"]), np.array(g["covariance_marginal"])
    assert np.all(np.diag(cond) <= np.diag(marg) * (1 + 1e-9))   # fixing the others never widens
    _png(grid_plot(g, tmp_path / "grid.png"))
    _png(profile_plot(profile_likelihood(model, obs, "lumped.b", n=5), tmp_path / "profile.png"))


@pytest.mark.needs_plugins
def test_plots_of_a_finite_element_fit_with_points(tmp_path):
    """The small layered disc of ``skinkit bench fit`` (two protocols, 36 tracked points): all four
    plots. At the truth the points' noise-normalised residuals are standard normals, so the
    pooled mean square of the residual map is 1 ± 4√(2/2160) (2160 samples)."""
    from skinkit.bench.fit import SPEC, bench_session
    from skinkit.inverse import fit
    from skinkit.inverse.plots import fit_plots, point_residuals

    model = load(copy.deepcopy(SPEC), workers=1)
    obs = bench_session(model, seed=1)
    r = fit(model, obs, ["skin.mu", "subdermal.E"], max_iterations=2)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        paths = fit_plots(model, obs, r, tmp_path)
    assert sorted(p.name for p in paths) == ["correlation.png", "loops.png", "residual_map.png",
                                             "trajectories.png"]
    for p in paths:
        _png(p)
    # a fallback to matplotlib is allowed on a machine VTK cannot render on, but never silent
    fallback = [w for w in caught if "pyvista could not render" in str(w.message)]
    assert len(fallback) <= 1
    pred = model.predict(model.parameters(), obs)
    panels = point_residuals(obs, pred)
    ms = np.mean(np.concatenate([p["rms"] ** 2 for p in panels]))
    assert abs(ms - 1) < 4 * math.sqrt(2 / 2160)


def _one_line_error(r, what: str) -> None:
    assert r.exit_code != 0
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and what in lines[0], r.output


def test_cli_bad_input_is_one_line(tmp_path):
    from skinkit.cli import cli

    model = load(spec("fung"))
    obs = session(model)
    po = obs["ramp0"]
    t = po.channels["tip_force"].time_s
    rec = np.column_stack([t, po.channels["tip_position"].values[:, 0] * 1e3,
                           po.channels["tip_force"].values[:, 0]])
    csv = tmp_path / "rec.csv"
    np.savetxt(csv, rec, delimiter=",", header="time_s,displacement_mm,force_N", comments="")
    toml = tmp_path / "fung.toml"
    toml.write_text('[model]\nkind = "lumped"\nname = "test-fung"\n[lumped]\naxis = "x"\n'
                    'elastic = "exponential"\n[lumped.parameters]\na = "15 mN"\nb = 320.0\n')
    run = CliRunner().invoke
    base = [str(toml), str(csv), "--out", str(tmp_path / "out")]
    _one_line_error(run(cli, ["grid", *base, "--pair", "lumped.a,lumped.nope"]), "lumped.nope")
    _one_line_error(run(cli, ["grid", *base, "--pair", "lumped.a,lumped.a"]), "twice")
    _one_line_error(run(cli, ["grid", *base, "--pair", "lumped.a,lumped.b", "--n", "2"]), "--n")
    _one_line_error(run(cli, ["grid", *base, "--pair", "lumped.a"]), "--pair")
    _one_line_error(run(cli, ["grid", *base, "--pair", "lumped.a,lumped.b", "--span", "4se"]), "--at")
    _one_line_error(run(cli, ["profile-likelihood", *base, "--parameter", "lumped.nope"]), "lumped.nope")
    _one_line_error(run(cli, ["profile-likelihood", *base, "--parameter", "lumped.a", "--n", "1"]), "--n")
    with pytest.raises(GridError, match="at least 3"):
        objective_grid(model, obs, ("lumped.a", "lumped.b"), n=2)
    # and a good grid through the command line: JSON on stdout, the PNG written
    r = run(cli, ["grid", *base, "--pair", "lumped.a,lumped.b", "--n", "3", "--span", "0.01"])
    assert r.exit_code == 0, r.output
    _png(tmp_path / "out" / "grid.png")
