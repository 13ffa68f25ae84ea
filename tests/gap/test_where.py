"""Step 1 of the gap diagnosis ("Where"): the residual's decomposition and its tests against the noise.

Sessions are built from numpy: two protocols driven by a trapezoidal tip force (ramp 3 s, hold
2 s, ramp down 3 s, rest 2 s; 100 Hz), a predicted tip position and 48 tracked points on four
rings (21 frames at 1 Hz, frame 0 the measured reference, as the reader makes it). The
prediction is the truth, plus an injected excess where a test wants one.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from skinkit.errors import SkinkitError
from skinkit.forward.observations import sample_noise
from skinkit.gap.where import (
    BANDS,
    CYCLES,
    PHASES,
    cell_chi2,
    holm,
    holm_adjusted,
    locate,
    make_drive,
    noise_dof,
    samples,
)
from skinkit.inverse.objective import Objective
from skinkit.schemas import Channel, ChannelPrediction, Observations, Prediction, ProtocolObservations
from skinkit.schemas.protocol import Protocol

RATE, T, P, F = 100.0, 2000, 48, 21
SIG = np.array([1.6e-6, 1.6e-6, 1.0e-6])      # tip position noise [m] per axis (the lab's)
SN = 4e-6                                      # tracking noise [m]
ALPHA = 0.05


def trapezoid(t: np.ndarray) -> np.ndarray:
    ph = (t - 1.0) % 10.0
    return np.where(t < 1.0, 0.0, np.clip(ph / 3, 0, 1) - np.clip((ph - 5) / 3, 0, 1))


def rings() -> np.ndarray:
    ang = np.arange(12) * np.pi / 6 + np.pi / 12          # sector centres: no point on an edge
    return np.array([[r * np.cos(a), r * np.sin(a), 0.0] for r in (1.5e-3, 3e-3, 5e-3, 7e-3) for a in ang])


def session(seed: int, noise: str = "declared", excess=None, ar: float = 0.0):
    """(observations, prediction). ``noise``: how the tip position's σ is obtained — "declared"
    (the true σ), "sd2" (the reader's estimator on the record) or "rest" (the first 100 samples,
    detrended by a quadratic). ``excess(name, t, drv, pred_tip, pred_pts, ref, frame_times)``
    returns the prediction with an injected misfit; ``ar``: AR(1) coefficient of the tip noise."""
    rng = np.random.default_rng(seed)
    ref = rings()
    obs, pred, inputs = {}, {}, {}
    t = np.arange(T) / RATE
    drv = trapezoid(t)
    fr = np.arange(F) * (T / RATE / F)
    for i, name in enumerate(("a", "b")):
        force = np.zeros((T, 3))
        force[:, 2 - i] = 0.5 * drv
        force += rng.normal(0, 4e-3, (T, 3))
        pos = np.zeros((T, 3))
        pos[:, 2 - i] = 1e-3 * drv
        e = rng.normal(0, 1, (T, 3))
        if ar:
            from scipy.signal import lfilter
            e = lfilter([np.sqrt(1 - ar * ar)], [1, -ar], e, axis=0)
        Y = pos + e * SIG
        u = np.zeros((P, F, 3))
        u[:, :, 0] = 2e-4 * drv[np.searchsorted(t, fr)][None, :] * (1 + 100 * ref[:, :1])
        X = ref[:, None, :] + u + rng.normal(0, SN, (P, F, 3))
        if noise == "rest":
            tt = np.arange(100.0)
            sig = [np.std(Y[:100, j] - np.polyval(np.polyfit(tt, Y[:100, j], 2), tt), ddof=3)
                   for j in range(3)]
            tip = Channel("tip_position", t, Y, noise=sig, noise_source="rest segment (100 samples)")
        elif noise == "sd2":
            est = [sample_noise(Y[:, j]) for j in range(3)]
            src = ", ".join(sorted({h.split(" (")[0] for _, h in est}))
            tip = Channel("tip_position", t, Y, noise=[s for s, _ in est], noise_source=src)
        else:
            tip = Channel("tip_position", t, Y, noise=SIG, noise_source="declared")
        obs[name] = ProtocolObservations(Protocol(name), {
            "tip_force": Channel("tip_force", t, force, noise=4e-3, noise_source="declared"),
            "tip_position": tip,
            "points": Channel("points", fr, X, noise=SN, noise_source="tracker", reference=X[:, 0],
                              reference_frame=0)})
        ptip, ppts = pos, X[:, :1] + u            # a point is predicted from its measured reference
        if excess is not None:
            ptip, ppts = excess(name, t, drv, ptip.copy(), ppts.copy(), ref, fr)
        pred[name] = {"tip_position": ChannelPrediction(ptip), "points": ChannelPrediction(ppts)}
        inputs[name] = "tip_force"
    return Observations(obs, None, "synthetic"), Prediction(pred, inputs=inputs)


def cell(g, axis, label):
    (c,) = [c for c in g.cells if c.axis == axis and c.label == label]
    return c


# ------------------------------------------------------------------------------------ the residual
def test_sum_of_squares_is_the_objectives_chi2():
    obs, pred = session(1, noise="sd2")
    z = Objective(None, obs, [], "noise").residual(pred, jacobian=False).z
    ss = samples(obs, pred)
    assert sum(float(s.z @ s.z) for s in ss) == pytest.approx(float(z @ z), rel=1e-12)
    g = locate(obs, pred)
    assert g.chi2 == pytest.approx(float(z @ z), rel=1e-12)
    assert g.dof == z.size
    # every partition of every axis adds up to the same χ² (frequency: by Parseval)
    for part in {(c.axis, c.partition) for c in g.cells} - {("region", "radius"), ("region", "sector")}:
        got = sum(c.chi2 for c in g.cells if (c.axis, c.partition) == part)
        assert got == pytest.approx(g.chi2, rel=1e-9), part
    pts = sum(float(s.z @ s.z) for s in ss if s.channel == "points")
    for part in ("radius", "sector"):
        assert sum(c.chi2 for c in g.cells if c.partition == part) == pytest.approx(pts, rel=1e-12)
    # the per-point map covers every point; dof of the cells lose their share of parameters
    assert g.point_map["a"].shape == (P,) and np.all(np.isfinite(g.point_map["a"]))
    g5 = locate(obs, pred, n_params=5)
    assert g5.dof == z.size - 5
    assert sum(c.dof for c in g5.cells if c.axis == "protocol") == pytest.approx(z.size - 5)


def test_phases_cycles_and_band_of_the_drive():
    obs, _ = session(2)
    d = make_drive(obs["a"].channels["tip_force"])
    drv = trapezoid(d.time_s)
    ramp_up = (np.gradient(drv) > 0) & (drv > 0.1) & (drv < 0.9)
    ramp_dn = (np.gradient(drv) < 0) & (drv > 0.1) & (drv < 0.9)
    top = drv > 0.999
    # away from the corners (the smoothing spans 1/20 of a period) every sample is labelled right
    assert np.all(d.phase[ramp_up] == PHASES.index("loading"))
    assert np.all(d.phase[ramp_dn] == PHASES.index("unloading"))
    assert np.mean(d.phase[top] == PHASES.index("hold")) > 0.8
    # two periods of 10 s in 20 s: two cycles, the second starting at the trough near t = 11 s
    assert d.cycle.max() == 1
    assert abs(d.time_s[np.argmax(d.cycle == 1)] - 11.0) < 1.0
    # a trapezoid of period 10 s has > 95 % of its power at 0.1 Hz
    assert d.band[0] == pytest.approx(0.1) and d.band[1] < 0.35


# ---------------------------------------------------------------------------------- null sessions
@pytest.mark.parametrize("noise", ["rest", "sd2"])
def test_null_sessions_false_alarms(noise):
    """200 sessions of pure noise. If the global test and the Holm-corrected cells hold their
    level, each false-alarm count is at most binomial(200, 0.05) (mean 10); exceeding its 99.9 %
    point (21) has probability below 0.1 %. For the rest-segment noise, the plain χ² test (no
    allowance for the estimated σ) must fail: the σ̂² of each of the 6 tip components is
    uncertain by √(2/97) = 14 %, and χ²/dof of the whole residual then scatters by ≈ 0.04 against
    the χ² test's 0.011, so its false alarms are near P(Z > 0.42) ≈ 34 %."""
    n = 200
    bound = stats.binom.ppf(0.999, n, ALPHA)
    glob = cells = naive = nonwhite = dependent = 0
    for seed in range(n):
        obs, pred = session(100 + seed, noise=noise)
        g = locate(obs, pred)
        # the family's p-value is the level at which the family would first reject
        assert g.significant == (g.family_p <= ALPHA)
        glob += g.significant
        cells += any(c.significant for c in g.cells)
        naive += g.p_value < ALPHA
        nonwhite += any(not v["white"] for v in g.whiteness.values())
        dependent += any(not v["independent"] for v in g.cross_correlation.values())
    assert glob <= bound and cells <= bound
    assert nonwhite <= bound and dependent <= bound
    if noise == "rest":
        assert naive / n > 0.2


# ----------------------------------------------------------------------------------- localisation
def _hold_bias(name, t, drv, tip, pts, ref, fr):
    if name == "a":
        tip[drv > 0.999, 2] += 3.0 * SIG[2]
    return tip, pts


def _sector(name, t, drv, tip, pts, ref, fr):
    ang = np.degrees(np.arctan2(ref[:, 1], ref[:, 0])) % 360
    sel = (ang > 30) & (ang < 60)
    pts[sel, 1:, 0] += 3.0 * SN * drv[np.searchsorted(t, fr)][1:]
    return tip, pts


def _protocol(name, t, drv, tip, pts, ref, fr):
    if name == "b":
        tip += 1.0 * SIG * drv[:, None]
    return tip, pts


def _band(name, t, drv, tip, pts, ref, fr):
    tip += 0.5 * SIG * np.sin(2 * np.pi * 0.5 * t)[:, None]        # 0.5 Hz: 5x the drive's band
    return tip, pts


@pytest.mark.parametrize("excess, axis, partition, label", [
    (_hold_bias, "phase", "direction", "hold"),
    (_sector, "region", "sector", "sector 30-60 deg"),
    (_protocol, "protocol", "protocol", "b"),
    (_band, "frequency", "frequency", "1-10x input band"),
])
def test_injected_excess_is_localised(excess, axis, partition, label):
    obs, pred = session(7, excess=excess)
    g = locate(obs, pred)
    target = cell(g, axis, label)
    part = [c for c in g.cells if c.axis == axis and c.partition == partition]
    assert target.significant and g.significant          # a significant cell is a gap
    assert max(part, key=lambda c: c.share) is target
    # the other cells of its partition hold no injected excess: at most chance flags
    assert sum(c.significant for c in part if c is not target) == 0
    assert target in g.ranked()
    ranked_here = [c for c in g.ranked() if c.partition == partition]
    assert ranked_here[0] is target
    # shares are the fractions of the partition's excess: they sum to 1
    for p in {c.partition for c in g.cells}:
        sh = [c.share for c in g.cells if c.partition == p]
        if any(s > 0 for s in sh):
            assert sum(sh) == pytest.approx(1.0)
    # "before/after": the same cells evaluated on the exact prediction shrink to the noise
    clean = session(7)[1]
    after = cell_chi2(obs, clean, [(axis, label)])[(axis, label)]
    assert after[0] / after[1] < target.chi2_per_dof
    before = cell_chi2(obs, pred, [(axis, label)])[(axis, label)]
    assert before[0] == pytest.approx(target.chi2)


def test_large_excess_found_despite_estimated_noise():
    """With σ from a 100-sample rest segment the allowance is wide (≈ 3 × 14 % / √6 overall);
    a bias of 3σ in the holds of protocol a still stands out in the holds."""
    obs, pred = session(8, noise="rest", excess=lambda *a: _hold_bias(*a[:3], a[3], a[4], a[5], a[6]))
    g = locate(obs, pred)
    assert cell(g, "phase", "hold").significant
    assert not cell(g, "phase", "loading").significant


# --------------------------------------------------------------------------- whiteness and input
def test_whiteness_flags_ar1_and_cross_correlation_flags_input():
    obs, pred = session(9, ar=0.5)
    g = locate(obs, pred)
    # lag-1 autocorrelation 0.5 against a standard error 1/√6000: Q is in the thousands
    assert not g.whiteness["a/tip_position"]["white"]
    assert g.whiteness["a/tip_position"]["p_value"] < 1e-20
    assert g.whiteness["a/points"]["white"]
    obs, pred = session(10, excess=lambda n, t, drv, tip, pts, ref, fr: (tip + 0.5 * SIG * drv[:, None], pts))
    g = locate(obs, pred)
    for p in ("a", "b"):
        assert not g.cross_correlation[f"{p}/tip_position"]["independent"]
        assert g.cross_correlation[f"{p}/points"]["independent"]
    assert set(g.whiteness) == {"a/tip_position", "a/points", "b/tip_position", "b/points"}


# ------------------------------------------------------------------------------------ noise terms
def test_noise_dof_follows_the_noise_source():
    t = np.arange(500) / 100.0
    v = np.random.default_rng(0).normal(0, 1e-6, (500, 3))
    known = noise_dof(Channel("tip_position", t, v, noise=1e-6, noise_source="tracker"))
    assert np.all(np.isinf(known[0])) and np.all(known[1] == 0)
    sd2 = noise_dof(Channel("tip_position", t, v, noise=1e-6, noise_source="second differences"))
    assert np.allclose(sd2[0], 500 * 36 / 70) and np.allclose(sd2[1], 500)
    rest = noise_dof(Channel("tip_position", t, v, noise=1e-6, noise_source="rest segment (120 samples)"))
    assert np.allclose(rest[0], 117) and np.all(rest[1] == 0)


def test_holm():
    p = np.array([0.01, 0.04, 0.03, 0.005, np.nan])
    # sorted 0.005 <= 0.05/5, 0.01 <= 0.05/4, 0.03 > 0.05/3: the first two only
    assert holm(p, 0.05).tolist() == [True, False, False, True, False]
    # adjusted values: 5·0.005, max(4·0.01, ·), max(3·0.03, ·), max(2·0.04, ·), NaN counts as 1
    assert holm_adjusted(p) == pytest.approx([0.04, 0.09, 0.09, 0.025, 1.0])


def test_holm_adjusted_rejects_exactly_where_holm_does():
    rng = np.random.default_rng(3)
    for _ in range(200):
        p = rng.uniform(0, 0.1, rng.integers(1, 30)) ** rng.uniform(1, 3)
        adj = holm_adjusted(p)
        for a in (0.001, 0.01, 0.025, 0.05, 0.1):
            assert np.array_equal(holm(p, a), adj <= a)


# -------------------------------------------------------------------------------------- bad input
def test_bad_input_is_one_line():
    obs, pred = session(11)
    wrong = Prediction({"zzz": pred.protocols["a"]}, inputs={"zzz": "tip_force"})
    with pytest.raises(SkinkitError) as e:
        locate(obs, wrong)
    assert "zzz" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(SkinkitError, match="not predicted"):
        locate(obs, pred, protocols=["c"])
    bad = Prediction({"a": {"tip_position": ChannelPrediction(np.zeros((5, 3)))}})
    with pytest.raises(SkinkitError, match="shape"):
        samples(obs, bad)
    with pytest.raises(SkinkitError, match="tip_force_x|no 'tip_force_x'|must be one of|has no"):
        samples(obs, Prediction({"a": {"points_2d": ChannelPrediction(np.zeros((1, 1, 2)))}}))
    with pytest.raises(SkinkitError, match="unknown axis"):
        cell_chi2(obs, pred, [("time", "x")])


def test_labels():
    obs, pred = session(12)
    g = locate(obs, pred)
    assert {c.label for c in g.axis("channel")} == {"tip_position", "surface x", "surface y", "surface z"}
    assert {c.label for c in g.axis("phase")} == set(PHASES) | set(CYCLES)
    assert {c.label for c in g.axis("frequency")} <= set(BANDS)
    assert len([c for c in g.cells if c.partition == "sector"]) == 12
    assert len([c for c in g.cells if c.partition == "radius"]) == 4
    d = g.to_dict()
    import json
    json.dumps(d)
    assert set(d["cells"][0]) >= {"axis", "label", "chi2", "dof", "chi2_per_dof", "p_value", "significant",
                                  "share", "n"}
