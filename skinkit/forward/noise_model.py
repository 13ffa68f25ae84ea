"""A sensor's noise as it is: isolated spikes, and an autoregressive model of its colour.

Real sensors are not white: an anti-aliasing filter, a drifting amplifier or the skin's own
slow wander while nothing is imposed make neighbouring samples correlated, and a loose contact
or a digitiser glitch adds isolated spikes. Treating such noise as white makes every
χ², interval and AIC difference wrong by large factors (the residual looks like a gap).

Per channel component of a robot record:

* **spikes** (:func:`spikes`): a jump away and a jump back of opposite sign within
  :data:`SPIKE_RUN` samples, both beyond :data:`SPIKE_LEVEL` robust standard deviations of the
  first differences (a longer excursion is a signal, not a spike; ramps and steps have no jump
  back, so the test is model-free). Flagged samples are left out of every
  sum (weight 0: a "skipped" or hard-redescending M-estimator, the limit of Tukey's biweight;
  Huber, 1981, Robust Statistics, ch. 4) and reported (count and times).
* **colour** (:func:`fit_ar`): an autoregressive model AR(p),
  e_t = x_t − Σᵢ φᵢ x_{t−i} white with standard deviation σ_e, fitted by least squares
  (conditional likelihood) to the **rest segment** — the samples before the record's drive
  first moves, detrended by a line — with the order chosen by BIC among 0..:data:`MAX_ORDER`
  (Box, Jenkins & Reinsel, Time Series Analysis, ch. 6–7; Ljung, System Identification, ch. 16).
  It needs at least :data:`MIN_AR_SAMPLES` rest samples (:func:`samples_needed`).
* **level over time** (:func:`local_scale`): a sensor is often noisier under load (a subject's
  tremor, stick-slip at the pad) than at rest; the innovation's standard deviation around each
  sample, relative to the rest segment's, from the record's high-passed AR innovations over
  :data:`LOCAL_WINDOW` samples (a variance function estimated from the record, as weighted
  least squares uses).

Prewhitening (:func:`skinkit.schemas.ar_filter.whiten_series`): a residual or a sensitivity
already divided by the marginal standard deviation σ is filtered by A(q) = 1 − Σ φᵢ q⁻ⁱ and
scaled by σ/σ_e, so that under the model its samples are independent standard normals (the
first p samples are kept as they are: unit variance, as the exact likelihood's first terms for
AR(1)). The filter is linear, so residuals and Jacobians go through the same map and every
least-squares quantity becomes the generalised least-squares one (Aitken's estimator).
"""

from __future__ import annotations

import functools
import re

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import lfilter

#: samples over which the innovation's level is measured around each sample (2 s at 100 Hz)
LOCAL_WINDOW = 201
#: samples of the running mean that separates the innovations from the signal's slow leakage
HIGH_PASS = 21
#: the smallest local scale of the innovation (relative to the rest segment's)
MIN_SCALE = 0.2
#: the largest autoregressive order tried
MAX_ORDER = 6
#: rest samples an AR noise model needs (a lag-p regression with tens of samples per coefficient)
MIN_AR_SAMPLES = 200
#: a spike lies this many robust standard deviations from its neighbours' median
SPIKE_LEVEL = 5.0
#: a record shorter than this many samples is not searched for spikes
SPIKE_WINDOW = 7
#: the longest run of flagged samples still called spikes
SPIKE_RUN = 2
_MAD = 1.4826


def samples_needed(order: int = 1) -> int:
    """Rest samples an AR(``order``) noise model needs (at least :data:`MIN_AR_SAMPLES`)."""
    return max(MIN_AR_SAMPLES, 30 * (order + 1))


def spikes(x: np.ndarray) -> np.ndarray:
    """Indices of isolated spikes in ``x`` ``(T,)`` (module docstring); NaNs are never flagged.

    A spike of r ≤ :data:`SPIKE_RUN` samples is a jump away from the signal and a jump back of
    opposite sign r samples later, each beyond :data:`SPIKE_LEVEL` robust standard deviations
    of the first differences, with the samples either side of it within that level of each
    other. Coloured noise moves in correlated steps, not in such pairs: on AR(1) noise with
    φ = 0.9 no sample of 400,000 was flagged, nor on white noise."""
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x)
    if ok.sum() < 4 * SPIKE_WINDOW:
        return np.zeros(0, int)
    idx = np.flatnonzero(ok)
    xs = x[ok]
    d = np.diff(xs)
    scale = _MAD * float(np.median(np.abs(d - np.median(d))))
    if not scale > 0:
        return np.zeros(0, int)
    lim = SPIKE_LEVEL * scale
    flag = np.zeros(xs.size, bool)
    for r in range(1, SPIKE_RUN + 1):
        # jump up into sample t (d[t-1]) and back out of sample t+r-1 (d[t+r-1])
        t = np.arange(1, xs.size - r)
        up, down = d[t - 1], d[t + r - 1]
        back = np.abs(xs[t + r] - xs[t - 1])
        hit = (np.abs(up) > lim) & (np.abs(down) > lim) & (np.sign(up) != np.sign(down)) & (back < lim)
        for k in range(r):
            flag[t[hit] + k] = True
    return idx[flag]


def _ar_design(x: np.ndarray, p: int, n_used: int) -> tuple[np.ndarray, np.ndarray]:
    """Lagged regressors ``(n_used, p)`` and targets ``(n_used,)``: the last ``n_used`` samples."""
    y = x[x.size - n_used:]
    X = np.column_stack([x[x.size - n_used - i - 1: x.size - i - 1] for i in range(p)]) if p else \
        np.zeros((n_used, 0))
    return X, y


def fit_ar(x: np.ndarray, max_order: int = MAX_ORDER, order: int | None = None
           ) -> tuple[np.ndarray, float, float]:
    """An AR model of ``x`` ``(n,)`` (finite samples, detrended by a line here): ``(φ (p,),
    σ_e, σ)`` with p chosen by BIC among 0..``max_order`` (or ``order`` when given); σ is the
    detrended segment's standard deviation. Every order is fitted on the same samples, so the
    criteria compare."""
    x = np.asarray(x, dtype=float)
    n = x.size
    t = np.arange(n, dtype=float)
    x = x - np.polyval(np.polyfit(t, x, 1), t)
    sigma = float(np.std(x, ddof=2))
    orders = [order] if order is not None else list(range(max_order + 1))
    n_used = n - max(orders)
    best: tuple[float, np.ndarray, float] | None = None
    for p in orders:
        X, y = _ar_design(x, p, n_used)
        phi = np.linalg.lstsq(X, y, rcond=None)[0] if p else np.zeros(0)
        e = y - X @ phi
        s2 = float(np.mean(e ** 2))
        if not s2 > 0:
            continue
        bic = n_used * np.log(s2) + p * np.log(n_used)
        if best is None or bic < best[0]:
            best = (bic, phi, float(np.sqrt(s2)))
    if best is None:
        return np.zeros(0), sigma, sigma
    _, phi, se = best
    if phi.size and not _stationary(phi):
        # a unit root (a random walk) has no marginal variance: keep the largest stationary AR(1)
        phi = np.array([min(float(np.sum(phi)), 0.999)])
        X, y = _ar_design(x, 1, n_used)
        se = float(np.sqrt(np.mean((y - X @ phi) ** 2)))
    if not phi.size:
        se = sigma
    return phi, se, sigma


def _stationary(phi: np.ndarray) -> bool:
    """True when every root of z^p − φ₁ z^(p−1) − … − φ_p lies inside the unit circle."""
    roots = np.roots(np.concatenate([[1.0], -phi]))
    return bool(np.all(np.abs(roots) < 1.0))


def ar_covariance(phi: np.ndarray, n: int) -> np.ndarray:
    """``(p, p)`` covariance of the least-squares AR(p) coefficients ``phi`` ``(p,)`` fitted to
    ``n`` samples: Γ_p⁻¹ σ_e²/n, Γ_p the process's autocovariance matrix at lags 0..p−1
    (Brockwell & Davis, Time Series: Theory and Methods, Thm 8.1.1), evaluated at ``phi``
    itself (the true coefficients are unknown). For AR(1) it is (1 − φ²)/n: on 500 rest
    samples of φ = 0.9 a standard deviation of 0.02, which moves the prewhitened spectrum near
    frequency 0, ((1 − φ̂)/(1 − φ))², by ±40 %."""
    phi = np.asarray(phi, dtype=float).ravel()
    p = phi.size
    if not p or n <= p:
        return np.zeros((p, p))
    # autocovariances at unit innovation variance from the impulse response ψ of 1/A(q):
    # γ_k = Σ_j ψ_j ψ_{j+k}; the response is truncated where it has decayed below 1e-12
    length = 64
    while True:
        psi = lfilter([1.0], np.concatenate([[1.0], -phi]), np.r_[1.0, np.zeros(length - 1)])
        if abs(psi[-1]) < 1e-12 * max(1.0, float(np.max(np.abs(psi)))) or length >= 2 ** 20:
            break
        length *= 4
    gam = np.array([float(psi[: psi.size - k] @ psi[k:]) for k in range(p)])
    G = gam[np.abs(np.subtract.outer(np.arange(p), np.arange(p)))]
    return np.linalg.inv(G) / n


#: simulated records behind :func:`ar_sampling`'s bias and covariance
SAMPLING_REPS = 200


@functools.lru_cache(maxsize=64)
def _ar_sampling(phi: tuple[float, ...], n: int, reps: int) -> tuple[np.ndarray, np.ndarray]:
    p = len(phi)
    a = np.asarray(phi, float)
    rng = np.random.default_rng([n, p, 20])          # fixed: the same record gets the same answer
    burn = 10 * n
    est = np.empty((reps, p))
    for r in range(reps):
        x = lfilter([1.0], np.concatenate([[1.0], -a]), rng.standard_normal(n + burn))[burn:]
        est[r] = fit_ar(x, order=p)[0] if p else np.zeros(0)
    return est.mean(axis=0) - a, np.atleast_2d(np.cov(est, rowvar=False))


def ar_sampling(phi: np.ndarray, n: int, reps: int = SAMPLING_REPS) -> tuple[np.ndarray, np.ndarray]:
    """``(bias (p,), cov (p, p))`` of :func:`fit_ar`'s coefficients at a fixed order when the
    rest segment of ``n`` samples is AR(p) with coefficients ``phi`` ``(p,)``, from ``reps``
    simulated segments fitted the same way (detrended by a line, least squares): a parametric
    bootstrap at the estimate (Efron & Tibshirani, An Introduction to the Bootstrap, ch. 10).
    The least-squares coefficients of a short segment are biased towards 0 — about
    −(2 + 4φ)/n for AR(1) with a line removed, −0.012 on 500 samples of φ 0.9, half a standard
    deviation — which under-whitens the slow part of the noise; their covariance is about
    :func:`ar_covariance`'s. Cached per (``phi``, ``n``)."""
    phi = np.asarray(phi, dtype=float).ravel()
    if not phi.size or n <= 3 * phi.size + 2 or not _stationary(phi):
        return np.zeros(phi.size), np.zeros((phi.size, phi.size))
    bias, cov = _ar_sampling(tuple(float(x) for x in phi), int(n), int(reps))
    return bias.copy(), cov.copy()


def log_gain_gradient(phi: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """``(F, p)``: ∂ log|A(e^{iω})|² / ∂φ_k at the frequencies ``omega`` ``(F,)`` [rad/sample],
    A(z) = 1 − Σ φ_k z^{−k}. A coloured noise prewhitened by coefficients off by δ keeps the
    spectrum |A_φ̂|²/|A_φ|² ≈ 1 + δ · this gradient (relative, first order)."""
    phi = np.asarray(phi, dtype=float).ravel()
    omega = np.asarray(omega, dtype=float).ravel()
    k = np.arange(1, phi.size + 1)
    ek = np.exp(-1j * np.outer(omega, k))                          # (F, p)
    A = 1.0 - ek @ phi                                             # (F,)
    return -2.0 * np.real(ek * np.conj(A)[:, None]) / (np.abs(A) ** 2)[:, None]


def rest_samples(source: str) -> int | None:
    """The rest samples an AR noise model was fitted to, read from its source text
    (:func:`describe`); None when the text names none."""
    got = re.search(r"rest segment \((\d+) samples\), AR\(\d+\)", source or "")
    return int(got.group(1)) if got else None


def rest_length(position: np.ndarray, noise: np.ndarray, resolution: np.ndarray) -> int:
    """Samples before the drive first moves: every component of ``position`` ``(T, k)`` within
    five noise levels (or 1.5 resolution steps) of its starting median."""
    pos = np.asarray(position, dtype=float)
    cols = [j for j in range(pos.shape[1]) if np.isfinite(pos[:, j]).any()]
    if not cols:
        return 0
    pos = pos[:, cols]
    start = np.nanmedian(pos[:min(20, len(pos))], axis=0)
    tol = np.maximum(5 * np.asarray(noise, float)[cols], 1.5 * np.asarray(resolution, float)[cols])
    with np.errstate(invalid="ignore"):
        away = np.any(np.abs(pos - start) > tol, axis=1)
    hit = np.flatnonzero(away)
    return int(hit[0]) if hit.size else len(pos)


def local_scale(x: np.ndarray, valid: np.ndarray, n_rest: int, ar: np.ndarray,
                window: int = LOCAL_WINDOW) -> np.ndarray:
    """``(T,)`` the innovation's standard deviation around each sample of ``x`` ``(T,)`` over the
    rest segment's (its first ``n_rest`` samples).

    The record is filtered by its AR model's A(q) (``ar`` ``(p,)``), which leaves the innovations
    plus a slowly varying part of the signal; a running mean over :data:`HIGH_PASS` samples
    removes the latter, and the RMS over ``window`` samples, over the rest segment's, is the
    scale (bounded below by :data:`MIN_SCALE`, so that no stretch of record weighs without
    limit). Flagged samples are bridged by interpolation."""
    x = np.asarray(x, dtype=float)
    ok = np.asarray(valid, bool) & np.isfinite(x)
    if ok.sum() < 2 or not 0 < n_rest <= x.size:
        return np.ones(x.size)
    idx = np.flatnonzero(ok)
    xs = np.interp(np.arange(x.size), idx, x[idx])
    # relative to the record's start, so that the filter's first samples carry no level step
    xs = xs - float(np.median(xs[: min(20, xs.size)]))
    p = len(ar) + 1
    e = lfilter(np.concatenate([[1.0], -np.asarray(ar, float)]), [1.0], xs)
    e[:p] = e[p]
    e = e - uniform_filter1d(e, HIGH_PASS, mode="nearest")
    rest = ok[p:n_rest]
    if rest.sum() < 10:
        return np.ones(x.size)
    ref = float(np.sqrt(np.mean(e[p:n_rest][rest] ** 2)))
    if not ref > 0:
        return np.ones(x.size)
    num = uniform_filter1d(np.where(ok, e ** 2, 0.0), window, mode="nearest")
    den = uniform_filter1d(ok.astype(float), window, mode="nearest")
    loc = np.sqrt(num / np.maximum(den, 1e-12)) / ref
    return np.maximum(np.where(den > 0, loc, 1.0), MIN_SCALE)


def describe(order: int, n_rest: int) -> str:
    """The source text of an AR noise model (kept parseable: ``rest segment (<n> samples``)."""
    return f"rest segment ({n_rest} samples), AR({order})"


__all__ = ["HIGH_PASS", "LOCAL_WINDOW", "MAX_ORDER", "MIN_AR_SAMPLES", "MIN_SCALE", "SAMPLING_REPS",
           "SPIKE_LEVEL", "SPIKE_RUN", "SPIKE_WINDOW", "ar_covariance", "ar_sampling", "describe", "fit_ar",
           "local_scale", "log_gain_gradient", "rest_length", "rest_samples", "samples_needed", "spikes"]
