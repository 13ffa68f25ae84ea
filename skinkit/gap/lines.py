"""Periodic components in a residual: lines that neither the noise model nor the drive explain.

Mains pick-up, a fan's or a pump's vibration, a switching supply: a sensor often carries a
steady tone. An autoregressive noise model estimated on a short rest segment cannot tell such a
tone from coloured noise (a tone near the Nyquist frequency looks like an alternating sequence
under a slow beat, which a low-order AR model takes up as a resonance), so the tone ends up in
the noise level and the gap it makes is not seen. Over the whole record the tone is a spectral
line a few frequency bins wide, which no AR spectrum of low order has.

The test is Thomson's harmonic F test (Thomson 1982, Proc IEEE 70 1055; Percival & Walden 1993,
Spectral Analysis for Physical Applications, §10.11), applied to each tip channel component's
prewhitened residual. With K = 2NW − 1 discrete prolate spheroidal tapers hₖ (time-bandwidth
NW = :data:`NW`), yₖ(f) = Σₜ hₖ(t) z(t) e^{−2πift} and Uₖ = Σₜ hₖ(t), the line's complex
amplitude is μ(f) = Σ Uₖ yₖ / Σ Uₖ² and

    F(f) = (K − 1) |μ|² Σ Uₖ² / Σ |yₖ − μ Uₖ|²

is F(2, 2K − 2) distributed when the spectrum is smooth over ±W = NW/N around f, whatever its
colour — so it stays calibrated on coloured noise, an estimated noise model and a broadband
misfit. Only frequencies above ten times the drive's band are searched (the drive's own
harmonics and the model's misfit lie below it; the same bands as the gap's ``frequency`` axis)
and away from 0 and the Nyquist frequency by 2W; the smallest p-value is Bonferroni-corrected
over the frequencies searched in every series, at level :data:`ALPHA_SHARE` × α, so that the
diagnosis's family-wise false-alarm rate on a session of pure noise grows by at most that share.

A detected line is reported with its frequency [Hz], its amplitude in the channel's unit (a
least-squares sinusoid fitted to the raw residual at that frequency) and its p-value.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats
from scipy.signal.windows import dpss

#: time-bandwidth product of the tapers (K = 2 NW − 1 = 7 tapers)
NW = 4.0
#: zero padding of the taper transforms (frequency grid 1/(PAD·N))
PAD = 2
#: the line family's share of the diagnosis's level α
ALPHA_SHARE = 0.1
#: at most this many lines reported per series (strongest first)
MAX_LINES = 5
#: a series shorter than this is not searched (too few bins above the drive's band)
MIN_SAMPLES = 256


@dataclass
class Line:
    """A periodic component of one series: ``frequency_hz``, ``amplitude`` [``unit``, the
    channel's SI unit], ``f_statistic`` and ``p_value`` (Bonferroni-corrected over the
    frequencies searched)."""

    series: str
    frequency_hz: float
    amplitude: float
    f_statistic: float
    p_value: float
    unit: str = "N"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"series": self.series, "frequency_hz": self.frequency_hz, "amplitude": self.amplitude,
                "f_statistic": self.f_statistic, "p_value": self.p_value, "unit": self.unit}


def harmonic_f(z: np.ndarray, nw: float = NW, pad: int = PAD) -> tuple[np.ndarray, np.ndarray, int]:
    """Thomson's harmonic F statistic of ``z`` ``(n,)`` on the grid ``k/(pad n)`` cycles per
    sample, k = 0..pad n/2: ``(frequency (F,) [cycles/sample], F (F,), K tapers)``."""
    z = np.asarray(z, float)
    n = z.size
    k = int(round(2 * nw)) - 1
    h = dpss(n, nw, k)                                 # (K, n), unit energy
    y = np.fft.rfft(h * z, pad * n)                    # (K, F)
    u0 = h.sum(axis=1)                                 # (K,): zero for odd tapers
    su = float(np.sum(u0 ** 2))
    mu = (u0 @ y) / su
    rest = np.sum(np.abs(y - np.outer(u0, mu)) ** 2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        F = np.where(rest > 0, (k - 1) * np.abs(mu) ** 2 * su / rest, 0.0)
    return np.arange(F.size) / (pad * n), F, k


def _amplitude(raw: np.ndarray, valid: np.ndarray, t: np.ndarray, f_hz: float) -> float:
    """Amplitude [unit] of the least-squares sinusoid at ``f_hz`` through the valid raw samples."""
    w = 2 * np.pi * f_hz * t[valid]
    X = np.column_stack([np.cos(w), np.sin(w), np.ones(w.size)])
    c = np.linalg.lstsq(X, raw[valid], rcond=None)[0]
    return float(np.hypot(c[0], c[1]))


def search(series: list[tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, float, str]],
           alpha: float) -> tuple[list[Line], float]:
    """Lines in ``series``: each ``(name, z (n,) prewhitened, raw (n,) [unit], valid (n,) bool,
    t (n,) [s], dt [s] the median sample interval, f_min [Hz], unit)`` (z is 0 off ``valid``);
    frequencies above ``f_min`` are searched.
    Returns the lines whose corrected p-value is below ``ALPHA_SHARE · alpha``, strongest first,
    and the smallest corrected p-value of any frequency searched (1 when none was)."""
    tested: list[tuple[Any, ...]] = []
    m = 0
    for name, z, raw, valid, t, dt, f_min, unit in series:
        n = z.size
        if n < MIN_SAMPLES or dt <= 0 or valid.sum() < MIN_SAMPLES:
            continue
        f, F, k = harmonic_f(z)
        w = NW / n
        band = (f > max(f_min * dt, 2 * w)) & (f < 0.5 - 2 * w)
        if not band.any():
            continue
        m += int(band.sum())
        tested.append((name, f, F, k, w, band, raw, valid, t, dt, unit))
    if not m:
        return [], 1.0
    level = ALPHA_SHARE * alpha
    out: list[Line] = []
    p_min = 1.0
    for name, f, F, k, w, band, raw, valid, t, dt, unit in tested:
        p = np.minimum(1.0, m * stats.f.sf(F, 2, 2 * k - 2))
        p_min = min(p_min, float(p[band].min()))
        hit = band & (p < level)
        # local maxima only, and none within 2W of a stronger one (the tapers' leakage)
        peaks = [i for i in np.flatnonzero(hit)
                 if F[i] >= F[max(i - 1, 0)] and F[i] >= F[min(i + 1, F.size - 1)]]
        peaks.sort(key=lambda i: -F[i])
        kept: list[int] = []
        for i in peaks:
            if all(abs(f[i] - f[j]) > 2 * w for j in kept):
                kept.append(i)
            if len(kept) == MAX_LINES:
                break
        for i in kept:
            f_hz = float(f[i] / dt)
            out.append(Line(name, f_hz, _amplitude(raw, valid, t, f_hz), float(F[i]), float(p[i]), unit))
    return sorted(out, key=lambda ln: ln.p_value), p_min


def describe(lines: list[Line]) -> str:
    """One phrase: ``"49.8 Hz (3.5 mN) and 49.4 Hz (1.1 mN) in tip_force x"`` (N and m in milli-)."""
    by: dict[str, list[str]] = {}
    for ln in lines:
        scale, u = (1e3, "m" + ln.unit) if ln.unit in ("N", "m") else (1.0, ln.unit)
        by.setdefault(ln.series, []).append(f"{ln.frequency_hz:.4g} Hz ({scale * ln.amplitude:.3g} {u})")
    return "; ".join(f"{' and '.join(v)} in {k}" for k, v in by.items())


__all__ = ["ALPHA_SHARE", "Line", "NW", "describe", "harmonic_f", "search"]
