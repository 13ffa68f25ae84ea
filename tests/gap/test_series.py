"""The compact measured-against-predicted series a gap report keeps: at most 500 samples per
channel (first and last kept), tip channels per component, tracked points as their mean
displacement from the reference over the points both measured and predicted."""

from __future__ import annotations

import numpy as np

from skinkit.gap.html_series import section_series
from skinkit.gap.series import MAX_SAMPLES, compact_series, decimation
from skinkit.schemas import (
    Channel,
    ChannelPrediction,
    Observations,
    Prediction,
    Protocol,
    ProtocolObservations,
)


def _session(T: int = 1200) -> tuple[Observations, Prediction, np.ndarray]:
    t = np.linspace(0.0, 12.0, T)
    ref = np.column_stack([np.linspace(-5e-3, 5e-3, 6), np.zeros(6), np.zeros(6)])
    u = 1e-3 * np.sin(t)                                  # every point moves 1 mm along x
    pts = ref[:, None, :] + np.array([1.0, 0.0, 0.0]) * u[None, :, None]
    valid = np.ones(pts.shape, bool)
    valid[0, 10:20] = False                                # one point lost for ten frames
    force = np.column_stack([np.zeros(T), np.zeros(T), -2.0 * u / 1e-3])
    obs = Observations({"indent": ProtocolObservations(Protocol("indent"), {
        "points": Channel("points", t, pts, valid=valid, noise=np.full(3, 1e-5), reference=ref),
        "tip_force": Channel("tip_force", t, force, noise=np.full(3, 1e-3))})})
    pred = Prediction({"indent": {"points": ChannelPrediction(pts + 1e-4),
                                  "tip_force": ChannelPrediction(1.1 * force)}})
    return obs, pred, u


def test_decimation_keeps_the_ends_and_at_most_the_limit():
    keep = decimation(1234)
    assert keep[0] == 0 and keep[-1] == 1233 and len(keep) <= MAX_SAMPLES
    assert np.array_equal(decimation(40), np.arange(40))


def test_points_as_mean_displacement_and_forces_per_component():
    obs, pred, u = _session()
    s = compact_series(obs, {"calibrated": pred})["indent"]
    assert s["held_out"] is False
    pts, f = s["channels"]["points"], s["channels"]["tip_force"]
    keep = decimation(u.size)
    assert len(pts["time_s"]) == len(keep) <= MAX_SAMPLES and pts["unit"] == "m"
    assert np.allclose(pts["measured"][0], u[keep], atol=1e-9)
    assert np.allclose(pts["predicted"]["calibrated"][0], u[keep] + 1e-4, atol=1e-9)
    assert np.allclose(pts["measured"][1], 0.0, atol=1e-12)
    assert f["components"] == ["x", "y", "z"] and f["unit"] == "N"
    assert np.allclose(f["predicted"]["calibrated"][2], 1.1 * np.array(f["measured"][2]), rtol=1e-5)


def test_the_section_draws_every_protocol_and_says_when_there_is_none():
    obs, pred, _ = _session(300)
    html = section_series({"series": compact_series(obs, {"calibrated": pred})})
    assert html.count('data-protocol="indent"') == 1 and html.count("data:image/png;base64,") == 1
    assert "keeps no predicted time series" in section_series({})
