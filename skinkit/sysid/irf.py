"""Non-parametric impulse response by correlation (thesis Eq. 4.1).

``h = Fs * pinv(R) phi_xy``: ``R`` is the Toeplitz matrix of the input's biased
autocorrelation and ``phi_xy`` the input-output biased cross-correlation. ``R`` is inverted
through its eigen-decomposition (the SVD of a symmetric matrix); the terms are ranked by
the output variance each one accounts for, and the number kept minimises the minimum
description length ``MDL(k) = V_k (1 + k ln N / N)`` (Westwick & Kearney's pseudo-inverse
IRF; ``V_k`` is the residual variance with ``k`` terms). Confidence bounds follow from the
estimate's covariance ``sigma_e^2 / N * pinv_k(R)`` (white-residual approximation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import toeplitz

from skinkit.sysid.checks import SysidError, check_irf_size


@dataclass
class IRF:
    """An impulse response function estimate.

    Attributes:
        lags_s: ``(L,)`` lags [s] (negative lags present when two-sided).
        h: ``(L,)`` IRF [m/(N s)] such that ``y(t) = sum_k h[k] x(t - lag_k) / rate_hz``.
        h_std: ``(L,)`` standard deviation of ``h`` [m/(N s)].
        rate_hz: sampling rate [Hz].
        rank: number of pseudo-inverse terms kept (of ``L``).
        mdl: ``(L,)`` MDL criterion against the number of terms.
        residual_var: estimated residual variance of the output with ``rank`` terms [m^2].
    """

    lags_s: np.ndarray
    h: np.ndarray
    h_std: np.ndarray
    rate_hz: float
    rank: int
    mdl: np.ndarray
    residual_var: float

    @property
    def memory_s(self) -> float:
        """Longest positive lag [s]."""
        return float(self.lags_s[-1])

    @property
    def n_neg(self) -> int:
        """Number of negative lags."""
        return int(np.sum(self.lags_s < 0))

    @property
    def two_sided(self) -> bool:
        """True when the IRF has negative lags."""
        return self.n_neg > 0

    def bounds(self, z: float = 1.96) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper confidence bounds [m/(N s)] (``z = 1.96``: 95 %)."""
        return self.h - z * self.h_std, self.h + z * self.h_std

    @property
    def dc_gain_m_per_N(self) -> float:
        """Integral of the IRF [m/N] (the DC compliance, truncated to the memory)."""
        return float(np.sum(self.h) / self.rate_hz)

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Convolve input ``x`` ``(N,)`` (mean removed by the caller) with the IRF: ``(N,)``.

        Samples within the memory of the start use zero input before the record.
        """
        g = self.h / self.rate_hz
        nn = self.n_neg
        full = np.convolve(x, g)
        return full[nn:nn + x.size]

    def to_dict(self) -> dict[str, object]:
        """The IRF as a plain dict (lags [s], h and its std [m/(N s)], rank, memory [s])."""
        return {"lags_s": self.lags_s.tolist(), "h_m_per_Ns": self.h.tolist(),
                "h_std_m_per_Ns": self.h_std.tolist(), "rank": self.rank,
                "memory_s": self.memory_s, "two_sided": self.two_sided}


def correlations(x: np.ndarray, y: np.ndarray, n_pos: int,
                 n_neg: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Biased auto-correlation of ``x`` at lags ``0 .. n_pos + n_neg - 1`` and biased
    cross-correlation ``phi[k] = 1/N sum_n x[n] y[n + k]`` at lags ``-n_neg .. n_pos - 1``."""
    n = x.size
    L = n_pos + n_neg
    nfft = 1 << int(np.ceil(np.log2(n + L)))
    X = np.fft.rfft(x, nfft)
    Y = np.fft.rfft(y, nfft)
    rxx = np.fft.irfft(X * np.conj(X), nfft)[:L] / n
    cxy = np.fft.irfft(np.conj(X) * Y, nfft) / n
    phi = np.concatenate([cxy[nfft - n_neg:], cxy[:n_pos]]) if n_neg else cxy[:n_pos]
    return rxx, phi


def estimate_irf(x: np.ndarray, y: np.ndarray, rate_hz: float, memory_s: float,
                 two_sided: bool = False, rank: int | None = None) -> IRF:
    """IRF from input ``x`` and output ``y`` (each ``(N,)``, means removed here).

    ``memory_s`` is the longest lag [s]; two-sided IRFs also span ``-memory_s``.
    ``rank`` fixes the number of pseudo-inverse terms (default: minimum MDL).
    """
    x = np.asarray(x, float) - np.mean(x)
    y = np.asarray(y, float) - np.mean(y)
    n = x.size
    n_pos = int(round(memory_s * rate_hz)) + 1
    n_neg = n_pos - 1 if two_sided else 0
    L = n_pos + n_neg
    if L >= n:
        raise SysidError(f"IRF of {L} lags needs more than {n} samples")
    check_irf_size(L, rate_hz, memory_s)
    rxx, phi = correlations(x, y, n_pos, n_neg)
    R = toeplitz(rxx)
    s, V = np.linalg.eigh(R)
    s = np.maximum(s, s.max() * 1e-15)
    proj = V.T @ phi
    contrib = proj * proj / s  # output variance accounted for by each term
    order = np.argsort(contrib)[::-1]
    var_y = float(np.mean(y * y))
    resid = np.maximum(var_y - np.cumsum(contrib[order]), var_y * 1e-12)
    k = np.arange(1, L + 1)
    mdl = resid * (1.0 + k * np.log(n) / n)
    if rank is None:
        rank = int(np.argmin(mdl)) + 1
    elif not 1 <= rank <= L:
        raise SysidError(f"rank must lie in 1..{L}, got {rank}")
    keep = order[:rank]
    g = V[:, keep] @ (proj[keep] / s[keep])
    resid_var = float(resid[rank - 1])
    var_g = resid_var / n * np.einsum("ij,j,ij->i", V[:, keep], 1.0 / s[keep], V[:, keep])
    lags = np.arange(-n_neg, n_pos) / rate_hz
    return IRF(lags_s=lags, h=g * rate_hz, h_std=np.sqrt(var_g) * rate_hz, rate_hz=rate_hz,
               rank=rank, mdl=mdl, residual_var=resid_var)


def estimate_irf_lstsq(x: np.ndarray, y: np.ndarray, rate_hz: float, memory_s: float) -> np.ndarray:
    """The same one-sided IRF [m/(N s)] by plain least squares on the full ``(N - L + 1) x L``
    Toeplitz data matrix of lagged inputs (the reference the benchmark compares against).

    Without rank reduction, the directions the input hardly excites (above its cut-off)
    amplify the output noise."""
    x = np.asarray(x, float) - np.mean(x)
    y = np.asarray(y, float) - np.mean(y)
    L = int(round(memory_s * rate_hz)) + 1
    check_irf_size(L, rate_hz, memory_s)
    if L >= x.size:
        raise SysidError(f"IRF of {L} lags needs more than {x.size} samples")
    # rows whose lags all fall inside the record: X[n, k] = x[n - k], n = L-1 .. N-1
    X = toeplitz(x[L - 1:], x[L - 1::-1])
    g, *_ = np.linalg.lstsq(X, y[L - 1:], rcond=None)
    return g * rate_hz
