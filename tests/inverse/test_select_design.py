"""Model selection (AIC, AICc, held-out and k-fold error) and experimental design (D-optimal
protocol ranking) on lumped models cheap enough to fit many times.

Sessions are the library's programmes laid out as the virtual lab lays them out
(:func:`skinkit.lab.session.plan_protocol`, :func:`skinkit.lab.session.skeleton`), sampled at
100 Hz, predicted by the model at known parameters, plus Gaussian noise at the lab's declared
levels on the predicted channel (the drive is left exact, so the residual is exactly the noise
model the statistics assume).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.forward import load
from skinkit.inverse.design import DesignError, rank_protocols
from skinkit.inverse.selection import SelectionError, akaike_weights, parse_subsets, select
from skinkit.lab.sensors import SensorModel
from skinkit.lab.session import plan_protocol, skeleton
from skinkit.schemas import Channel, Observations, ProtocolObservations

STEP = 10   # 1 kHz programme -> 100 Hz session

POLY = {"model": {"kind": "lumped", "name": "poly"},
        "lumped": {"axis": "x", "elastic": "polynomial", "drive": "tip_position",
                   "parameters": {"c1": 150.0, "c2": 0.0, "c3": 0.0}}}
#: the truth: a quadratic stiffening (c2 x² = 68 mN at 1.5 mm: 17 force noise levels), no cubic term
TRUTH = {"lumped.c1": 200.0, "lumped.c2": 3e4, "lumped.c3": 0.0}
C1, C12, C123 = ["lumped.c1"], ["lumped.c1", "lumped.c2"], ["lumped.c1", "lumped.c2", "lumped.c3"]


def planned(name: str, **parameters):
    p = plan_protocol(name, parameters)
    p.time_s, p.drive_robot = p.time_s[::STEP], p.drive_robot[::STEP]
    return p


def session(model, names, values=None, seed=0) -> Observations:
    """Protocols ``names`` predicted by ``model`` at ``values`` plus the lab's noise."""
    sk = skeleton([planned(n) for n in names], SensorModel(), None, None)
    pred = model.predict(model.parameters().with_values(values or {}), sk)
    rng = np.random.default_rng(seed)
    out = {}
    for po in sk:
        ch = dict(po.channels)
        for c, cp in pred.protocols[po.name].items():
            o = ch[c]
            noisy = cp.values + o.noise * rng.standard_normal(cp.values.shape)
            ch[c] = Channel(c, o.time_s, noisy, noise=o.noise)
        out[po.name] = ProtocolObservations(po.protocol, ch)
    return Observations(out, None, "test")


def by_free(result, free):
    return next(r for r in result["rows"] if r["free"] == free)


# -- selection ---------------------------------------------------------------------------------
@pytest.mark.needs_plugins
def test_aic_prefers_the_true_structure_and_kfold_error_is_one_noise_level():
    """Three protocols (x > 0, x < 0, 30° off x), 9,003 force samples.

    * [c1] lacks the c2 x² the data need: its χ² grows by thousands (17 noise levels at the
      peaks), so its ΔAIC is far above 10 (Burnham & Anderson: 'essentially no support').
    * [c1, c2, c3] adds a parameter whose true value is 0: AIC_sup − AIC_true =
      N ln(χ²_sup/χ²_true) + 2 ≈ 2 − X with X = χ²_true − χ²_sup ~ χ²(1), so it lies in
      (2 − 10.8, 2] with probability 0.999 — never below −8.8, never above 2.
    * the true structure's χ²/dof is 1 ± √(2/9001) = ±0.015: within 5 of those.
    * k-fold by protocol with the true structure: each left-out protocol is predicted by a
      fit on the other two; the pooled RMS is 1 ± 0.015 (noise) plus the estimate's own
      error (≈ k/N_fit relative): within 0.08 of 1. Without c2 it is many noise levels.
    """
    m = load(POLY)
    obs = session(m, ["in_plane_000", "in_plane_180", "in_plane_030"], TRUTH)
    res = select(m, obs, [C1, C12, C123])
    assert res["best"] == C12 or res["best"] == C123
    true, sup, small = by_free(res, C12), by_free(res, C123), by_free(res, C1)
    assert small["delta_aic"] > 100
    d = sup["aic"] - true["aic"]
    assert -8.8 < d <= 2 + 1e-6, d
    assert abs(true["chi2_per_dof"] - 1) < 0.075
    assert abs(true["kfold_rms"] - 1) < 0.08, true["kfold"]
    assert small["kfold_rms"] > 3
    assert set(true["kfold"]) == {"in_plane_000", "in_plane_180", "in_plane_030"}
    # AICc = AIC + 2(k+1)(k+2)/(n-k-2); Akaike weights sum to 1 and follow exp(-Δ/2)
    for row in res["rows"]:
        k, n = row["k"], row["n"]
        assert row["aicc"] == pytest.approx(row["aic"] + 2 * (k + 1) * (k + 2) / (n - k - 2), rel=1e-12)
        assert row["aic"] == pytest.approx(n * math.log(row["chi2"] / n) + 2 * (k + 1), rel=1e-12)
    assert sum(r["weight_aic"] for r in res["rows"]) == pytest.approx(1.0)
    assert true["weight_aic"] / sup["weight_aic"] == pytest.approx(math.exp(-(true["aic"] - sup["aic"]) / 2))
    assert [r["rank"] for r in res["rows"]] == [1, 2, 3]
    assert json.loads(json.dumps(res)) == res   # JSON-ready


@pytest.mark.needs_plugins
def test_session_held_out_protocol_is_predicted_at_one_noise_level():
    """A protocol the session marks held out is never fitted and is predicted by the fit on
    the others: with the true structure its RMS is 1 ± √(2/3001) = ±0.026 plus the
    estimate's error; within 0.1 of 1."""
    m = load(POLY)
    obs = session(m, ["in_plane_000", "in_plane_180", "in_plane_030"], TRUTH, seed=3)
    res = select(m, obs.with_held_out(["in_plane_030"]), [C12], folds=None)
    row = res["rows"][0]
    assert res["fitted_protocols"] == ["in_plane_000", "in_plane_180"]
    assert set(row["held_out"]) == {"in_plane_030"}
    assert abs(row["held_out_rms"] - 1) < 0.1
    assert row["kfold"] == {} and row["kfold_rms"] is None


def test_selection_bad_input_is_one_clear_error():
    m = load(POLY)
    one = session(m, ["in_plane_000"], TRUTH)
    with pytest.raises(SelectionError, match="one fitted protocol.*at least two"):
        select(m, one, [C12])
    two = session(m, ["in_plane_000", "in_plane_180"], TRUTH)
    with pytest.raises(SelectionError, match="lumped.k, which the model does not have"):
        select(m, two, [C1, ["lumped.k"]])
    with pytest.raises(SelectionError, match="subset 2 repeats subset 1"):
        select(m, two, [C12, list(reversed(C12))])
    with pytest.raises(SelectionError, match="--folds"):
        select(m, two, [C12], folds="cycles")
    assert parse_subsets(" a,b ; a,b,c ;") == [["a", "b"], ["a", "b", "c"]]
    with pytest.raises(SelectionError, match="no subset"):
        parse_subsets(" ; ")
    e = math.exp(-1)
    assert akaike_weights([0.0, 2.0]) == pytest.approx([1 / (1 + e), e / (1 + e)])


# -- design ------------------------------------------------------------------------------------
def test_log_det_gain_is_exact_for_a_model_linear_in_its_parameters():
    """F = c1 x + c2 x² is linear in (c1, c2): the noise-weighted Jacobian of a protocol is
    [x(t), x(t)²]/σ whatever the parameters, x(t) the programme along x. The session is
    in_plane_060 (x = 0.75 mm peak), the candidate in_plane_000 (1.5 mm): the gain must be
    log det(F + G) − log det F of those hand-built matrices, and the standard errors the
    square roots of the diagonals of the inverses (the ridge, 1e-10 in scaled units, moves
    them by < 1e-12 relative)."""
    m = load(POLY)
    obs = session(m, ["in_plane_060"], TRUTH)
    sigma = obs["in_plane_060"].channels["tip_force"].noise[0]

    def info(name):
        x = planned(name).drive_robot[:, 0]
        J = np.stack([x, x * x], axis=1) / sigma
        return J.T @ J

    F, G = info("in_plane_060"), info("in_plane_000")
    exact = np.linalg.slogdet(F + G)[1] - np.linalg.slogdet(F)[1]
    res = rank_protocols(m, obs, TRUTH, C12, ["in_plane_000"])
    row = res["ranking"][0]
    assert row["gain"] == pytest.approx(exact, rel=1e-9)
    se0, se1 = np.sqrt(np.diag(np.linalg.inv(F))), np.sqrt(np.diag(np.linalg.inv(F + G)))
    for i, nm in enumerate(C12):
        assert res["current"]["parameters"][nm]["se"] == pytest.approx(se0[i], rel=1e-9)
        assert row["se_after"][nm] == pytest.approx(se1[i], rel=1e-9)
        assert row["se_reduction"][nm] == pytest.approx(1 - se1[i] / se0[i], rel=1e-9)


def test_repeating_a_protocol_doubles_the_information_through_the_force_driven_twin():
    """A force-driven exponential element x = ln(1 + F/a)/b (nonlinear in a and b) on a
    session of in_plane_000, its tip force the closed form a (e^{bx} − 1) of the programme.
    The candidate in_plane_000 is a trajectory: a twin driven by position predicts the force
    it would record, and the model predicts the position from it — the session again, so
    G = F exactly: gain = n ln 2 and every standard error shrinks by 1/√2. in_plane_090 does
    not move x: force 0, position 0, ∂x/∂a = ∂x/∂b = 0 there: gain 0."""
    spec = {"model": {"kind": "lumped", "name": "exp-force"},
            "lumped": {"axis": "x", "elastic": "exponential", "drive": "tip_force",
                       "parameters": {"a": "15 mN", "b": 320.0}}}
    m = load(spec)
    a, b = 0.015, 320.0
    sk = skeleton([planned("in_plane_000")], SensorModel(), None, None)
    po = sk["in_plane_000"]
    X = po.channels["tip_position"].values
    Fx = np.zeros_like(X)
    Fx[:, 0] = a * np.expm1(b * X[:, 0])
    chans = dict(po.channels, tip_force=Channel("tip_force", po.channels["tip_force"].time_s, Fx,
                                                 noise=po.channels["tip_force"].noise))
    obs = Observations({"in_plane_000": ProtocolObservations(po.protocol, chans)}, None, "test")
    res = rank_protocols(m, obs, None, ["lumped.a", "lumped.b"], ["in_plane_090", "in_plane_000"])
    best, last = res["ranking"]
    assert best["protocol"] == "in_plane_000" and best["drive"] == "tip_position"
    assert best["gain"] == pytest.approx(2 * math.log(2), rel=1e-8)
    for nm in ("lumped.a", "lumped.b"):
        assert best["se_reduction"][nm] == pytest.approx(1 - 1 / math.sqrt(2), rel=1e-8)
    assert last["protocol"] == "in_plane_090" and abs(last["gain"]) < 1e-12
    assert last["pins_down"] is None and "adds (almost) nothing" in last["message"]


def test_a_fast_protocol_pins_down_the_relaxation_a_slow_one_cannot():
    """QLV with a linear element k and one Prony term (g1 = 0.4, τ = 50 ms). On 0.1 Hz
    sinusoids ωτ = 0.03: the force is k(1 − g1) x + k g1 τ ẋ + O((ωτ)²), so the session
    determines k(1 − g1) well and k and g1 apart only through the small rate term — g1 is
    weak. Another slow protocol (0.05 Hz, 6,001 samples) adds information mostly along the
    direction already known; a fast one (2 Hz, ωτ = 0.63, 3 periods: 151 samples, 1/40 as
    many) separates k from g1. The design must rank the fast one first and credit it with
    the larger reduction of g1's standard error; a protocol that does not move x adds 0."""
    spec = {"model": {"kind": "lumped", "name": "qlv"},
            "lumped": {"axis": "x", "elastic": "linear", "drive": "tip_position", "parameters": {"k": 200.0},
                       "relaxation": [{"g": 0.4, "tau": 0.05}]}}
    m = load(spec)
    obs = session(m, ["in_plane_000"])
    fast = ("in_plane_000", {"frequency": 2.0, "periods": 3})
    slow = ("in_plane_000", {"frequency": 0.05})
    res = rank_protocols(m, obs, None, ["lumped.k", "lumped.g1"], [slow, "in_plane_090", fast])
    assert res["current"]["weakest"] == "lumped.g1"
    order = [r["label"] for r in res["ranking"]]
    assert order == ["in_plane_000(frequency=2, periods=3)", "in_plane_000(frequency=0.05)", "in_plane_090"]
    f, s, z = res["ranking"]
    assert f["samples"] * 30 < s["samples"]
    assert f["se_reduction"]["lumped.g1"] > s["se_reduction"]["lumped.g1"]
    assert abs(z["gain"]) < 1e-12
    assert "lumped.g1" in f["message"] and f["message"].startswith("in_plane_000(frequency=2, periods=3)")


def test_design_bad_input_and_models_the_library_cannot_drive():
    m = load(POLY)
    obs = session(m, ["in_plane_000"], TRUTH)
    with pytest.raises(DesignError, match="unknown protocol 'nope'"):
        rank_protocols(m, obs, None, C12, ["nope"])
    with pytest.raises(DesignError, match="no parameter"):
        rank_protocols(m, obs, {"lumped.k": 1.0}, C12)
    # a dynamic (K-B-I) model is driven by force only: a trajectory cannot drive it
    kbi = load({"model": {"kind": "lumped", "name": "kbi"},
                "lumped": {"family": "kbi", "axis": "x", "drive": "tip_force",
                           "parameters": {"K": 1450.0, "B": 4.76, "I": 0.0155}}})
    t = np.arange(0, 1.0, 1e-3)
    f = np.zeros((t.size, 3))
    f[:, 0] = 0.5 + 0.1 * np.sin(2 * np.pi * 5 * t)
    chans = {"tip_force": Channel("tip_force", t, f, noise=3.85e-3),
             "tip_position": Channel("tip_position", t, 0 * f, noise=1.6e-6)}
    from skinkit.schemas import Protocol
    kobs = Observations({"rec": ProtocolObservations(Protocol("rec"), chans)}, None, "test")
    with pytest.raises(DesignError, match="no candidate protocol of the library applies.*cannot be driven"):
        rank_protocols(kbi, kobs, None, ["lumped.K"], ["in_plane_000"])


# -- command line ------------------------------------------------------------------------------
TOML = """
[model]
kind = "lumped"
name = "poly-x"
[lumped]
axis = "x"
drive = "tip_position"
elastic = "polynomial"
[lumped.parameters]
c1 = {c1}
c2 = {c2}
"""


@pytest.fixture(scope="module")
def lab_session(tmp_path_factory):
    from skinkit.lab.session import make_session
    d = tmp_path_factory.mktemp("sel")
    (d / "truth.toml").write_text(TOML.format(c1=200.0, c2=3e4))
    (d / "model.toml").write_text(TOML.format(c1=150.0, c2=0.0))
    make_session(str(d / "truth.toml"), d / "s.h5", d / "t.json", seed=1,
                 protocols="in_plane_000,in_plane_180")
    return d


def _one_line_error(r, what):
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and what in lines[0], r.output


def test_cli_bad_input_is_one_line(lab_session):
    from skinkit.cli import cli
    d = lab_session
    run = CliRunner().invoke
    base = [str(d / "model.toml"), str(d / "s.h5")]
    _one_line_error(run(cli, ["select", *base, "--subsets", "lumped.c1;lumped.nope"]), "lumped.nope")
    _one_line_error(run(cli, ["select", *base, "--subsets", "lumped.c1", "--folds", "cycles"]), "--folds")
    _one_line_error(run(cli, ["select", *base, "--subsets", ";"]), "--subsets")
    _one_line_error(run(cli, ["select", *base, "--subsets", "lumped.c1", "--objective", "nope"]),
                    "--objective")
    _one_line_error(run(cli, ["design", *base, "--candidates", "in_plane_000,nope"]), "nope")
    _one_line_error(run(cli, ["design", *base, "--at", str(d / "none.json")]), "--at")
    (d / "bad.json").write_text("{\"parameters\": {\"lumped.k\": {\"value\": 1}}}")
    _one_line_error(run(cli, ["design", *base, "--at", str(d / "bad.json")]), "lumped.k")


@pytest.mark.needs_plugins
def test_cli_select_and_design_json(lab_session):
    from skinkit.cli import cli
    d = lab_session
    base = [str(d / "model.toml"), str(d / "s.h5")]
    r = CliRunner().invoke(cli, ["select", *base, "--subsets", "lumped.c1;lumped.c1,lumped.c2", "--json"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.stdout)
    assert res["best"] == C12 and by_free(res, C1)["delta_aic"] > 100
    fitted = by_free(res, C12)["parameters"]
    fit_json = {"parameters": {n: {"value": v["value"], "free": True} for n, v in fitted.items()}}
    (d / "fit.json").write_text(json.dumps(fit_json))
    r = CliRunner().invoke(cli, ["design", *base, "--at", str(d / "fit.json"), "--candidates",
                                 "in_plane_090,in_plane_000", "--json"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.stdout)
    assert res["free"] == C12
    # the session is in_plane_000 + in_plane_180: repeating in_plane_000 adds, in_plane_090 cannot
    assert [x["protocol"] for x in res["ranking"]] == ["in_plane_000", "in_plane_090"]
    r = CliRunner().invoke(cli, ["design", *base, "--free", "lumped.c1", "--candidates", "in_plane_000"])
    assert r.exit_code == 0 and "in_plane_000: log det gain" in r.output
