"""``guide-friction``: a regularised Coulomb friction read by the force sensor, f tanh(v/v_s) per
axis, v the tip's velocity from the recorded position (a ``friction`` instrument entry).

Closed form against the drive's exact velocity (the Savitzky–Golay derivative's truncation error
bounded from the drive's third derivative), the sensitivity against central differences, the
exact null, the sign held still at rest under the position sensor's noise, and one-line errors
naming the entry."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from skinkit import registry
from skinkit.errors import ForwardError
from skinkit.forward import instrument as inst
from skinkit.forward import load
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

pytestmark = pytest.mark.needs_plugins

#: the element's stiffness [N/m], the drive's amplitude [m] and angular frequency [rad/s]
K, U, OMEGA = 200.0, 5e-3, 2 * math.pi * 0.2
H, DURATION = 0.01, 20.0
T = np.arange(0.0, DURATION + H / 2, H)
LEVEL = 0.005


def position(t: np.ndarray) -> np.ndarray:
    """U (1 − cos ωt)/2 [m]: smooth, at rest at t = 0."""
    return 0.5 * U * (1 - np.cos(OMEGA * np.asarray(t, float)))


def session(pos_x: np.ndarray) -> Observations:
    pos = np.zeros((T.size, 3))
    pos[:, 0] = pos_x
    chans = {"tip_position": Channel("tip_position", T, pos, noise=1.7e-6),
             "tip_force": Channel("tip_force", T, K * pos, noise=1.7e-3)}
    proto = Protocol("in_plane_000")
    return Observations({proto.name: ProtocolObservations(proto, chans)}, None, "guide friction")


def lumped(effects: list[dict[str, Any]], drive: str = "tip_position") -> dict[str, Any]:
    return {"model": {"kind": "lumped", "name": "linear"},
            "lumped": {"axis": "x", "drive": drive, "elastic": "linear", "parameters": {"k": K}},
            "effects": effects}


def force(spec: dict[str, Any], obs: Observations, values: dict[str, float] | None = None,
          names: list[str] | None = None) -> Any:
    with load(spec, workers=1) as m:
        ps = m.parameters()
        if values:
            ps = ps.with_values(values)
        pred = m.predict(ps, obs, sensitivities=names or False)
    (proto,) = pred.protocols.values()
    return proto["tip_force"]


def test_the_recorded_force_is_the_true_one_plus_the_smoothed_sign_of_the_velocity():
    obs = session(position(T))
    got = force(lumped([{"name": "guide-friction", "x": LEVEL}]), obs).values
    v = 0.5 * U * OMEGA * np.sin(OMEGA * T)
    expect = K * position(T) + LEVEL * np.tanh(v / 1e-4)
    # the local quadratic's slope over 2m + 1 samples errs by u‴/6 · h² Σk⁴/Σk² at the centre;
    # through tanh's largest slope 1/v_s that bounds the force's error (ends: half a window left out)
    m = 5
    k = np.arange(-m, m + 1)
    dv = 0.5 * U * OMEGA**3 / 6 * H**2 * (k**4).sum() / (k**2).sum()
    inner = slice(m, T.size - m)
    assert np.max(np.abs(got[inner, 0] - expect[inner])) <= LEVEL * dv / 1e-4 * (1 + 1e-6)
    assert np.all(got[:, 1:] == 0)


def test_the_level_is_linear_and_its_sensitivity_is_analytic():
    obs = session(position(T))
    spec = lumped([{"name": "guide-friction", "x": LEVEL}])
    cf = force(spec, obs, None, ["guide-friction.x"])
    up = force(spec, obs, {"guide-friction.x": LEVEL + 1e-3}).values
    dn = force(spec, obs, {"guide-friction.x": LEVEL - 1e-3}).values
    np.testing.assert_allclose(cf.d["guide-friction.x"], (up - dn) / 2e-3, rtol=0, atol=1e-12)


def test_the_null_is_exactly_nothing():
    obs = session(position(T))
    ref = force(lumped([]), obs).values
    assert np.array_equal(force(lumped([{"name": "guide-friction"}]), obs).values, ref)


def test_the_sign_holds_still_at_rest_under_the_position_noise():
    """At rest the encoder's noise (σ 1.6 µm) gives a velocity noise of σ/h √(12/(n(n²−1))) ≈ 15
    µm/s over the 11-sample window, a tenth of v_s: the basis' RMS stays near 0.15, far from a
    flickering ±1 (bound: twice that, the RMS of 2,001 samples being within a few % of it)."""
    sigma = 1.6e-6
    rng = np.random.default_rng(5)
    obs = session(1e-3 + sigma * rng.standard_normal(T.size))
    f = force(lumped([{"name": "guide-friction", "x": LEVEL}]), obs).values[:, 0] - K * obs.protocols[
        "in_plane_000"].channels["tip_position"].values[:, 0]
    n = 11
    expected = sigma / H * math.sqrt(12 / (n * (n * n - 1))) / 1e-4
    assert np.sqrt(np.mean((f / LEVEL) ** 2)) < 2 * expected


def test_a_friction_on_the_driving_channel_is_refused():
    obs = session(position(T))
    with pytest.raises(ForwardError) as err:
        force(lumped([{"name": "guide-friction", "x": LEVEL}], drive="tip_force"), obs)
    assert "friction on the driving channel" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(("table", "where"), [
    ({"velocity": 0.0}, "instrument[0].velocity"),
    ({"window": "-1 s"}, "instrument[0].window"),
    ({"source": "tip_force"}, "instrument[0].source"),
    ({"channel": "points"}, "instrument[0].channel"),
    ({"component": 3}, "instrument[0].component"),
])
def test_inadmissible_friction_entries_name_the_entry(table, where):
    entry = {"kind": "friction", "parameter": "f", "value": 0.005, **table}
    with pytest.raises(ForwardError) as err:
        inst.parse([entry])
    assert err.value.entry == where, err.value


def test_a_bias_refuses_a_friction_key():
    with pytest.raises(ForwardError) as err:
        inst.parse([{"kind": "bias", "parameter": "b", "value": 0.0, "channel": "tip_force", "window": 0.1}])
    assert err.value.entry == "instrument[0].window"


def test_the_effect_is_documented_and_declared_as_promised():
    e = registry.create("skinkit.effects", "guide-friction")
    assert {p.name: p.unit for p in e.parameters()} == {"x": "N", "y": "N", "z": "N"}
    assert e.null() == {"x": 0.0, "y": 0.0, "z": 0.0}
    doc = type(e).__doc__ or ""
    assert "Not covered" in doc and "Phenomenon" in doc
