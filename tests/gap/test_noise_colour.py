"""Significance against a noise model estimated from a short rest segment.

An AR(1) noise of φ 0.9 has its power near frequency 0 set by (1 − φ)²: coefficients fitted to
500 rest samples (standard deviation about 0.02, biased about −(2 + 4φ)/n) move the prewhitened
spectrum there by ±40 %, so a slow direction of the residual (a drift, a softening over
cycles) tested against χ² as if the noise were known is rejected far more often than α. The
tests refer it to m·F(q, ν), m and ν from the coefficients' bias and covariance
(:func:`skinkit.forward.noise_model.ar_sampling`, :func:`skinkit.gap.score.colour_variance`).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from skinkit.forward import noise_model as nm
from skinkit.gap.score import Colour, EffectColumns, score_test
from skinkit.lab import alt_noise as an
from skinkit.schemas.ar_filter import whiten_series

PHI, N_REST, T = 0.9, 500, 4000
#: null records: at the nominal α = 0.05 more than 5 rejections of 40 has binomial probability
#: 0.048, so a calibrated test passes
SEEDS, MAX_REJECT, ALPHA = 40, 5, 0.05


def test_ar_sampling_bias_and_spread_of_a_short_rest_segment() -> None:
    bias, cov = nm.ar_sampling(np.array([PHI]), N_REST + 1)
    # least squares after a line is removed: bias about −(2 + 4φ)/n, spread about √((1 − φ²)/n)
    assert -2.0 * (2 + 4 * PHI) / N_REST < bias[0] < -0.5 * (2 + 4 * PHI) / N_REST
    sd = float(np.sqrt(cov[0, 0]))
    assert 0.8 < sd / np.sqrt((1 - PHI ** 2) / N_REST) < 1.6
    assert np.allclose(nm.ar_covariance(np.array([PHI]), N_REST), (1 - PHI ** 2) / N_REST)
    assert nm.ar_sampling(np.zeros(0), N_REST)[1].shape == (0, 0)


def _slow_direction_p(seed: int) -> tuple[float, float]:
    """p of the score test along a prewhitened ramp (a slow drift) on a null AR(1) record whose
    coefficients were fitted to the rest segment in front of it: (with the coefficients'
    uncertainty, against χ² as if they were known)."""
    rng = np.random.default_rng([seed, 77])
    x = an.ar1(rng, N_REST + T, PHI, 1.0)
    phi, se, sigma = nm.fit_ar(x[:N_REST])
    valid = np.ones(T, bool)
    z = whiten_series(x[N_REST:] / sigma, valid, phi, sigma / se)
    ramp = whiten_series(np.linspace(0.0, 1.0, T) / sigma, valid, phi, sigma / se)
    cols = EffectColumns("drift", ["drift.rate"], ramp[:, None], {"drift.rate": "analytic"}, np.zeros(1),
                         {"drift.rate": 0.0}, {"drift.rate": 1.0})
    colour = Colour([(slice(0, T), valid[:, None], ((phi, *nm.ar_sampling(phi, N_REST)),), N_REST)])
    U = np.zeros((T, 0))
    return score_test(z, U, cols, colour).p_value, score_test(z, U, cols, None).p_value


def test_slow_direction_on_ar1_null_is_rejected_at_about_alpha() -> None:
    p = np.array([_slow_direction_p(s) for s in range(SEEDS)])
    calibrated = int(np.sum(p[:, 0] < ALPHA))
    assert calibrated <= MAX_REJECT, f"{calibrated}/{SEEDS} rejections with the coefficients' uncertainty"
    # the reference only widens (m ≥ 1, F's tail above χ²'s), most in the far tail
    assert np.all(p[:, 0] >= p[:, 1])
    low = np.argmin(p[:, 1])
    assert p[low, 0] > 2 * p[low, 1]


def test_white_noise_model_leaves_the_test_unchanged() -> None:
    rng = np.random.default_rng(5)
    z = rng.standard_normal(T)
    cols = EffectColumns("drift", ["drift.rate"], np.linspace(-1, 1, T)[:, None], {"drift.rate": "analytic"},
                         np.zeros(1), {"drift.rate": 0.0}, {"drift.rate": 1.0})
    t = score_test(z, np.zeros((T, 0)), cols, None)
    assert np.isclose(t.p_value, stats.chi2.sf(t.statistic, 1))
