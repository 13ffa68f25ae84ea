"""Noise of the alternative gap benchmark's null sessions: white, coloured (AR(1)) and spiky.

All draws come from a :class:`numpy.random.Generator` the caller seeds; sizes in the unit of
``sigma`` (here newtons)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter


def white(rng: np.random.Generator, n: int, sigma: float) -> np.ndarray:
    """``(n,)`` independent N(0, σ²) samples."""
    return sigma * rng.standard_normal(n)


def ar1(rng: np.random.Generator, n: int, phi: float, sigma: float) -> np.ndarray:
    """``(n,)`` a stationary AR(1) series x_k = φ x_{k−1} + e_k with marginal standard deviation
    ``sigma`` (e_k ~ N(0, σ²(1 − φ²)), x_0 drawn from the stationary law, so there is no
    start-up transient); lag-k autocorrelation φ^k, |φ| < 1."""
    if not abs(phi) < 1:
        raise ValueError(f"AR(1) needs |phi| < 1, got {phi!r}")
    e = sigma * np.sqrt(1 - phi**2) * rng.standard_normal(n)
    e[0] = sigma * rng.standard_normal()
    return lfilter([1.0], [1.0, -phi], e)


@dataclass(frozen=True)
class Spikes:
    """Isolated spikes: ``index`` ``(k,)`` distinct sample indices, ``size`` ``(k,)`` signed
    heights [unit of σ times σ, i.e. the signal's unit]."""

    index: np.ndarray
    size: np.ndarray

    def series(self, n: int) -> np.ndarray:
        """``(n,)`` zeros with the spikes added."""
        out = np.zeros(n)
        out[self.index] = self.size
        return out


def spikes(rng: np.random.Generator, n: int, sigma: float, count: tuple[int, int] = (5, 20),
           height: tuple[float, float] = (10.0, 30.0), apart: int = 10) -> Spikes:
    """Between ``count[0]`` and ``count[1]`` spikes (inclusive) at random samples at least
    ``apart`` samples from each other (isolated: one sample each), heights uniform in
    ``height`` × σ with a random sign."""
    k = int(rng.integers(count[0], count[1] + 1))
    idx: list[int] = []
    while len(idx) < k:
        i = int(rng.integers(0, n))
        if all(abs(i - j) >= apart for j in idx):
            idx.append(i)
    size = sigma * rng.uniform(*height, size=k) * rng.choice([-1.0, 1.0], size=k)
    order = np.argsort(idx)
    return Spikes(np.asarray(idx, int)[order], size[order])


__all__ = ["Spikes", "ar1", "spikes", "white"]
