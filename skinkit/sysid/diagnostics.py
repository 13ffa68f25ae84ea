"""Residual diagnostics of an identified model (the first half of the sim-to-real gap).

A model that captures the dynamics leaves a residual that is white (no autocorrelation
outside the confidence band) and uncorrelated with the input at every lag; where it does
not, the lags, frequency bands and output amplitudes at which the VAF drops say what is
missing (e.g. a nonlinearity shows as a VAF that falls with output amplitude).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from skinkit.sysid.checks import SysidError
from skinkit.sysid.irf import correlations
from skinkit.sysid.metrics import vaf


class _Predictor(Protocol):
    def predict(self, force_N: np.ndarray) -> np.ndarray: ...


@dataclass
class ResidualDiagnostics:
    """Residual statistics of one model on one record.

    Attributes:
        lags_s: ``(L,)`` lags [s] of the correlations (``-max_lag .. max_lag``).
        autocorr: ``(L,)`` normalised residual autocorrelation (1 at lag 0).
        crosscorr: ``(L,)`` normalised input-residual cross-correlation (positive lag:
            residual after input).
        bound: 95 % band of a white residual, ``1.96 / sqrt(N)``.
        band_edges_hz: ``(B + 1,)`` frequency band edges [Hz]; vaf_by_band_pct ``(B,)`` [%].
        amplitude_edges_m: ``(A + 1,)`` measured-output quantile edges [m];
        vaf_by_amplitude_pct: ``(A,)`` VAF in each amplitude band about the overall mean [%];
        rms_by_amplitude_m: ``(A,)`` residual RMS in each amplitude band [m].
        vaf_pct: overall VAF [%]; n: samples used.
    """

    lags_s: np.ndarray
    autocorr: np.ndarray
    crosscorr: np.ndarray
    bound: float
    band_edges_hz: np.ndarray
    vaf_by_band_pct: np.ndarray
    amplitude_edges_m: np.ndarray
    vaf_by_amplitude_pct: np.ndarray
    rms_by_amplitude_m: np.ndarray
    vaf_pct: float
    n: int

    @property
    def whiteness_outside(self) -> float:
        """Fraction of non-zero lags whose residual autocorrelation leaves the 95 % band
        (about 0.05 for a white residual)."""
        nz = self.lags_s != 0
        return float(np.mean(np.abs(self.autocorr[nz]) > self.bound))

    @property
    def crosscorr_outside(self) -> float:
        """Fraction of lags whose input-residual correlation leaves the 95 % band."""
        return float(np.mean(np.abs(self.crosscorr) > self.bound))

    def to_dict(self) -> dict[str, Any]:
        """The diagnostics as a plain dict of floats and lists (JSON-ready)."""
        return {"vaf_pct": self.vaf_pct, "n": self.n, "bound": self.bound,
                "whiteness_outside": self.whiteness_outside,
                "crosscorr_outside": self.crosscorr_outside,
                "lags_s": self.lags_s.tolist(), "autocorr": self.autocorr.tolist(),
                "crosscorr": self.crosscorr.tolist(),
                "band_edges_hz": self.band_edges_hz.tolist(),
                "vaf_by_band_pct": self.vaf_by_band_pct.tolist(),
                "amplitude_edges_m": self.amplitude_edges_m.tolist(),
                "vaf_by_amplitude_pct": self.vaf_by_amplitude_pct.tolist(),
                "rms_by_amplitude_m": self.rms_by_amplitude_m.tolist()}


def default_bands(rate_hz: float) -> np.ndarray:
    """Band edges [Hz]: 0, 5, 20, 50, 100, 200 and Nyquist, cut at Nyquist."""
    ny = rate_hz / 2
    edges = [e for e in (0.0, 5.0, 20.0, 50.0, 100.0, 200.0) if e < ny]
    return np.array([*edges, ny])


def residual_diagnostics(force_N: np.ndarray, position_m: np.ndarray, predicted_m: np.ndarray,
                         rate_hz: float, *, burn_in: int = 0, max_lag_s: float = 0.1,
                         band_edges_hz: np.ndarray | None = None,
                         n_amplitude: int = 5) -> ResidualDiagnostics:
    """Diagnostics of ``predicted_m`` against ``position_m`` (all ``(N,)``), input ``force_N``.

    The first ``burn_in`` samples (the model's start-up) are left out.
    """
    f = np.asarray(force_N, float)[burn_in:]
    y = np.asarray(position_m, float)[burn_in:]
    p = np.asarray(predicted_m, float)[burn_in:]
    if not (f.size == y.size == p.size):
        raise SysidError(f"force, position and prediction differ in length: {f.size}, {y.size}, "
                         f"{p.size}")
    n = y.size
    e = y - p
    e = e - e.mean()
    L = int(round(max_lag_s * rate_hz))
    if L < 1 or 2 * L >= n:
        raise SysidError(f"max_lag_s {max_lag_s!r} does not fit a record of {n} samples")
    fc = f - f.mean()
    ree, _ = correlations(e, e, L + 1)
    _, rfe = correlations(fc, e, L + 1, L)
    if ree[0] > 0:
        auto = np.concatenate([ree[:0:-1], ree]) / ree[0]
        cross = rfe / np.sqrt(np.mean(fc * fc) * ree[0])
    else:  # a perfect prediction: nothing left to correlate
        auto = np.zeros(2 * L + 1)
        auto[L] = 1.0
        cross = np.zeros(2 * L + 1)
    lags = np.arange(-L, L + 1) / rate_hz

    edges = default_bands(rate_hz) if band_edges_hz is None else np.asarray(band_edges_hz, float)
    Y = np.abs(np.fft.rfft(y - y.mean())) ** 2
    E = np.abs(np.fft.rfft(e)) ** 2
    fr = np.fft.rfftfreq(n, 1.0 / rate_hz)
    vb = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (fr >= lo) & (fr < hi) if hi < edges[-1] else (fr >= lo) & (fr <= hi)
        sy = float(Y[m].sum())
        vb.append(100.0 * (1.0 - float(E[m].sum()) / sy) if sy > 0 else float("nan"))

    q = np.quantile(y, np.linspace(0, 1, n_amplitude + 1))
    idx = np.clip(np.searchsorted(q, y, side="right") - 1, 0, n_amplitude - 1)
    dev = (y - y.mean()) ** 2
    va, ra = [], []
    for k in range(n_amplitude):
        m = idx == k
        if not m.any():
            va.append(float("nan"))
            ra.append(float("nan"))
            continue
        va.append(100.0 * (1.0 - float(np.sum(e[m] ** 2)) / max(float(np.sum(dev[m])), 1e-300)))
        ra.append(float(np.sqrt(np.mean(e[m] ** 2))))
    return ResidualDiagnostics(lags, auto, cross, 1.96 / np.sqrt(n), edges, np.array(vb), q,
                               np.array(va), np.array(ra), vaf(y, p), n)


def diagnose(model: _Predictor, force_N: np.ndarray, position_m: np.ndarray, rate_hz: float,
             burn_in: int = 0, **kw: Any) -> ResidualDiagnostics:
    """:func:`residual_diagnostics` of ``model.predict(force_N)``."""
    return residual_diagnostics(force_N, position_m, model.predict(force_N), rate_hz,
                                burn_in=burn_in, **kw)


def compare(models: dict[str, _Predictor], force_N: np.ndarray, position_m: np.ndarray,
            rate_hz: float, burn_in: int = 0) -> list[dict[str, Any]]:
    """Linear-vs-Wiener-vs-Hammerstein (or any) comparison: one row per model with its VAF,
    residual whiteness and input-residual correlation."""
    rows = []
    for name, m in models.items():
        d = diagnose(m, force_N, position_m, rate_hz, burn_in)
        rows.append({"model": name, "vaf_pct": d.vaf_pct, "whiteness_outside": d.whiteness_outside,
                     "crosscorr_outside": d.crosscorr_outside,
                     "vaf_by_band_pct": d.vaf_by_band_pct.tolist(),
                     "vaf_by_amplitude_pct": d.vaf_by_amplitude_pct.tolist()})
    return rows
