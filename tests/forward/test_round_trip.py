"""Round trip: a virtual-lab session made by truth model M, predicted by forward model M at the
true parameters, leaves residuals the size of the noise the lab added — no more, no less."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from skinkit.forward.residuals import chi2_range

# one worker solves the round trip (a module fixture) and runs every test on it
pytestmark = [pytest.mark.needs_plugins, pytest.mark.xdist_group("round_trip")]

PROTOCOLS = ("normal_indentation", "in_plane_000", "in_plane_090", "out_of_plane_330")

#: a small layered disc with QLV skin and the skin's natural tension (an effect), driven by
#: the recorded tip position; one period of each Table 12 protocol
MODEL = {
    "model": {"name": "round-trip"},
    "session": {"protocols": list(PROTOCOLS),
                "parameters": {p: {"periods": 1} for p in PROTOCOLS}},
    "geometry": {"kind": "disc", "diameter": "24 mm", "indenter_diameter": "4 mm", "n_inner": 2, "n_ring": 2},
    "layers": [
        {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "qlv",
         "options": {"elastic": "neo-hookean-ni", "terms": 1},
         "parameters": {"mu": "15 kPa", "K": "500 kPa", "g1": 0.3, "tau1": "2 s"}},
        {"name": "subdermal", "thickness": "3.5 mm", "elements": 1, "law": "neo-hookean-enu",
         "parameters": {"E": "10 kPa", "nu": 0.45}},
    ],
    "effects": [{"name": "prestress", "l1": 1.08, "l2": 1.02, "angle": "20 deg"}],
    "indenter": {"mode": "displacement"},
    "surface": {"fit": "auto", "outside": "nearest"},
    "drive": {"max_step": "1 s"},
}


@pytest.fixture(scope="module")
def trip(tmp_path_factory):
    from skinkit.forward import load, read_observations
    from skinkit.lab.session import make_session

    d = tmp_path_factory.mktemp("trip")
    truth = make_session(copy.deepcopy(MODEL), d / "s.h5", d / "t.json", seed=3, workers=2,
                         mesh="shared")
    model = load(copy.deepcopy(MODEL), workers=2)
    obs = read_observations(d / "s.h5")
    pred = model.predict(model.parameters(), obs)
    model.close()
    return obs, pred, json.loads((d / "t.json").read_text()) if not truth else truth


def test_session_has_the_table12_protocols(trip):
    obs, _, _ = trip
    assert obs.names == list(PROTOCOLS)
    for po in obs:
        assert {"tip_force", "tip_position", "points"} <= set(po.channels)


def test_chi2_per_sample_is_the_added_noise(trip):
    """Per protocol and channel, Σz²/n must lie in the 99.9 % interval of χ²_n/n, shifted by
    what the lab adds besides white noise: each tip-force component's constant tare offset
    o_j (drawn by the lab, read from the truth file) adds (o_j/σ_j)² to the expected value.
    The drive (tip position, σ 1-2 µm) moves the predicted force by stiffness x σ ≈ 0.1 mN
    after smoothing, far below the force noise (3.9 mN): no allowance. Points: their
    reference is frame 0 as measured, which the residual whitening accounts for.

    The noise levels are not the lab's: the reader estimates them from the record (second
    differences over N samples), so Σz²/n carries that estimate's error too: σ̂² of white
    noise from Δ²x has relative variance 2 Σρ²/N with ρ = (1, -2/3, 1/6) the correlations of
    Δ²x at lags 0, ±1, ±2 (Σρ² = 1.944), averaged over the three components; the interval
    widens by 3.3 of those standard deviations (99.9 %)."""
    obs, pred, truth = trip
    for proto, cname, cp in pred.items():
        ch = obs[proto].channels[cname]
        m = cp.mask(ch)
        z = ch.normalised(cp.values, m)
        n = int(m.sum())
        c2n = float(np.sum(z[m] ** 2)) / n
        shift = 0.0
        if cname == "tip_force":
            o = np.asarray(truth["offsets"][proto]["tip_force"]["skin_frame"])
            shift = float(np.mean((o / ch.noise) ** 2))
        lo, hi = chi2_range(n)
        if not ch.is_points:
            s_est = np.sqrt(2 * 1.944 / ch.values.shape[0] / 3)
            lo, hi = lo - 3.3 * s_est, hi + 3.3 * s_est
        assert lo + shift <= c2n <= hi + shift, (proto, cname, c2n, lo + shift, hi + shift)


def test_no_truth_in_the_session_file(trip, tmp_path):
    """The session holds no parameter of the truth (the lab's own test searches every attribute;
    here: the pre-stretch appears nowhere in the observations read back)."""
    obs, _, truth = trip
    assert "prestress" in json.dumps(truth)
    assert "prestress" not in json.dumps(obs.summary())


LUMPED = {
    "model": {"kind": "lumped", "name": "round-trip-lumped"},
    "session": {"protocols": ["in_plane_000"]},
    "lumped": {"axis": "x", "elastic": "exponential", "parameters": {"a": "20 mN", "b": 300.0},
               "relaxation": [{"g": 0.3, "tau": "3 s"}]},
}


def test_lumped_round_trip(tmp_path):
    """A lumped truth through the lab (Table 12 in-plane stretch along x, 1 kHz) predicted by
    the same model: the force along x within the same range as the FE round trip."""
    from skinkit.forward import load, read_observations
    from skinkit.lab.session import make_session
    truth = make_session(copy.deepcopy(LUMPED), tmp_path / "s.h5", tmp_path / "t.json", seed=5)
    m = load(copy.deepcopy(LUMPED))
    obs = read_observations(tmp_path / "s.h5", axis="x")
    pred = m.predict(m.parameters(), obs)
    (proto, cname, cp), = list(pred.items())
    ch = obs[proto].channels[cname]
    msk = cp.mask(ch)
    n = int(msk.sum())
    c2n = float(np.sum(ch.normalised(cp.values, msk)[msk] ** 2)) / n
    o = np.asarray(truth["offsets"][proto]["tip_force"]["skin_frame"])[0] / ch.noise[0]
    lo, hi = chi2_range(n)
    s_est = np.sqrt(2 * 1.944 / ch.values.shape[0])
    assert lo - 3.3 * s_est + o ** 2 <= c2n <= hi + 3.3 * s_est + o ** 2, c2n


TWOPAD = {
    "model": {"name": "round-trip-twopad"},
    "session": {"protocols": ["in_plane_000"], "parameters": {"in_plane_000": {"periods": 1}}},
    "geometry": {"kind": "twopad", "size": ["60 mm", "30 mm"], "pad_size": "8 mm", "gap": "28.5 mm",
                 "n_pad": 1, "n_gap": 4, "n_outer": 1, "n_side": 1},
    "layers": [
        {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "neo-hookean-ni",
         "parameters": {"mu": "20 kPa", "K": "500 kPa"}},
        {"name": "subdermal", "thickness": "3.5 mm", "elements": 1, "law": "neo-hookean-enu",
         "parameters": {"E": "2 kPa", "nu": 0.45}},
    ],
    "boundary": {"fixed": ["pad_fixed", "bottom", "sides"]},
    "indenter": {"mode": "displacement"},
    "surface": {"fit": "auto", "outside": "nearest"},
    "drive": {"max_step": "1 s"},
}


def test_twopad_round_trip(tmp_path):
    """The two-pad extension geometry through the lab (the moving pad pulled 1.5 mm along x):
    force and tracked points within the noise's range, as for the indentation model."""
    from skinkit.forward import load, read_observations
    from skinkit.lab.session import make_session
    truth = make_session(copy.deepcopy(TWOPAD), tmp_path / "s.h5", tmp_path / "t.json", seed=7, workers=1,
                         mesh="shared")
    m = load(copy.deepcopy(TWOPAD), workers=1)
    obs = read_observations(tmp_path / "s.h5")
    pred = m.predict(m.parameters(), obs)
    for proto, cname, cp in pred.items():
        ch = obs[proto].channels[cname]
        msk = cp.mask(ch)
        n = int(msk.sum())
        c2n = float(np.sum(ch.normalised(cp.values, msk)[msk] ** 2)) / n
        lo, hi = chi2_range(n)
        shift = 0.0
        if not ch.is_points:
            s_est = np.sqrt(2 * 1.944 / ch.values.shape[0] / 3)
            lo, hi = lo - 3.3 * s_est, hi + 3.3 * s_est
            o = np.asarray(truth["offsets"][proto]["tip_force"]["skin_frame"])
            shift = float(np.mean((o / ch.noise) ** 2))
        assert lo + shift <= c2n <= hi + shift, (cname, c2n, lo + shift, hi + shift)
