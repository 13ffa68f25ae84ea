"""The noise model of a robot record: spikes, autoregressive colour from the rest segment,
prewhitening. Truths are generated here with numpy (AR recursions, spikes at known samples),
not with the code under test."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit.errors import SchemaError
from skinkit.forward import noise_model as nm
from skinkit.forward.observations import channels_from_record
from skinkit.schemas import Protocol, RobotRecord
from skinkit.schemas.ar_filter import colour_series, whiten_series


def _ar1(n: int, phi: float, rng: np.random.Generator) -> np.ndarray:
    """Stationary AR(1) with unit marginal standard deviation."""
    e = rng.normal(size=n) * np.sqrt(1 - phi ** 2)
    x = np.empty(n)
    x[0] = rng.normal()
    for t in range(1, n):
        x[t] = phi * x[t - 1] + e[t]
    return x


def test_ar_fit_recovers_the_coefficient_and_whitening_decorrelates():
    rng = np.random.default_rng(3)
    n, phi = 2000, 0.9
    x = _ar1(n, phi, rng)
    est, se, sigma = nm.fit_ar(x, max_order=4)
    # least squares AR(1): standard error sqrt((1 - φ²)/n) ≈ 0.0097; allow 4 of them
    assert est.size >= 1 and abs(est[0] - phi) < 4 * np.sqrt((1 - phi ** 2) / n) + 0.05 * (est.size > 1)
    assert se == pytest.approx(np.sqrt(1 - phi ** 2), rel=0.1)
    z = x / sigma
    w = whiten_series(z, np.ones(n, bool), est, sigma / se)
    # white, unit variance: lag-1 correlation within 4/√n, variance within 4·√(2/n)
    assert abs(np.corrcoef(w[:-1], w[1:])[0, 1]) < 4 / np.sqrt(n)
    assert abs(np.var(w) - 1) < 4 * np.sqrt(2 / n)
    back = colour_series(w, np.ones(n, bool), est, sigma / se)
    np.testing.assert_allclose(back, z, atol=1e-10)


def test_white_noise_keeps_order_zero_mostly():
    rng = np.random.default_rng(5)
    orders = [nm.fit_ar(rng.normal(size=500))[0].size for _ in range(40)]
    # BIC's penalty log(494) ≈ 6.2 for one more coefficient: P(χ²₁ > 6.2) ≈ 1.3 % per order tried
    assert sum(o > 0 for o in orders) <= 5


def test_spikes_found_and_none_invented():
    rng = np.random.default_rng(7)
    n = 20000
    for x in (rng.normal(size=n), _ar1(n, 0.9, rng)):
        assert nm.spikes(x).size == 0
        pos = np.sort(rng.choice(np.arange(10, n - 10), 10, replace=False))
        y = x.copy()
        y[pos] += rng.uniform(10, 30, 10) * rng.choice([-1, 1], 10)
        np.testing.assert_array_equal(nm.spikes(y), pos)
    # a step is a signal, not a spike
    step = np.concatenate([np.zeros(500), 40 * np.ones(500)]) + rng.normal(size=1000)
    assert nm.spikes(step).size == 0


def _record(n_rest: int, phi: float, seed: int = 0, spikes: int = 0) -> RobotRecord:
    rng = np.random.default_rng(seed)
    rate = 100.0
    n_move = 3000
    t = np.arange(n_rest + n_move) / rate
    u = np.concatenate([np.zeros(n_rest), 5e-3 * np.sin(np.pi * np.arange(n_move) / n_move) ** 2])
    f_true = 40.0 * u
    noise = 2e-3 * _ar1(t.size, phi, rng)
    f = f_true + noise
    if spikes:
        f[rng.choice(np.arange(n_rest + 10, t.size - 10), spikes, replace=False)] += 0.05
    pos = 1e-6 * rng.normal(size=(t.size, 3))          # an encoder's white noise, 1 µm
    pos[:, 2] += u
    force = 2e-3 * rng.normal(size=(t.size, 3))
    force[:, 2] = f
    return RobotRecord(time_s=t, tip_position=pos, tip_force=force,
                       protocol=Protocol("ramp", kind="trajectory"))


def test_record_channels_carry_the_coloured_noise_model_and_spikes():
    rec = _record(600, 0.9, spikes=6)
    ch = channels_from_record(rec)["tip_force"]
    assert ch.coloured and ch.noise_ar[2].size >= 1
    assert "rest segment (6" in ch.noise_source and "6 spike(s) left out" in ch.noise_source
    assert int(ch.outliers.sum()) == 6 and not ch.valid[ch.outliers].any()
    # the marginal level of the AR noise (2 mN), not the second differences' smaller one
    assert ch.noise[2] == pytest.approx(2e-3, rel=0.2)


def test_white_noise_found_white_in_a_rest_segment_says_so():
    # the colour was looked for and not found: the source says it (a reader then trusts the level)
    ch = channels_from_record(_record(600, 0.0, seed=3))["tip_force"]
    assert not ch.coloured and "white by the rest segment (6" in ch.noise_source, ch.noise_source
    short = channels_from_record(_record(50, 0.0, seed=3))["tip_force"]
    assert "rest segment" not in short.noise_source


def test_the_true_model_fits_coloured_noise_at_chi2_one():
    rec = _record(800, 0.9, seed=11)
    ch = channels_from_record(rec)["tip_force"]
    pos = rec.tip_position[:, 2]
    pred = np.zeros_like(ch.values)
    pred[:, 2] = -40.0 * pos            # skin frame: z flips
    m = ch.fit_mask()
    m[:, :2] = False
    z = ch.normalised(pred, m)[m]
    # χ²/ν of n standard normals: 1 ± √(2/n); four of those
    assert abs(np.mean(z ** 2) - 1) < 4 * np.sqrt(2 / z.size) + 0.05
    white = channels_from_record(rec, noise="white")["tip_force"]
    zw = white.normalised(pred, m)[m]
    assert np.mean(zw ** 2) > 2         # white noise assumed: coloured noise reads as a gap


def test_ar_noise_needs_a_rest_segment():
    rec = _record(50, 0.5)
    with pytest.raises(SchemaError, match=r"has \d+ samples, at least 200 are needed"):
        channels_from_record(rec, noise="ar")
    with pytest.raises(SchemaError, match="--noise"):
        channels_from_record(rec, noise="pink")
