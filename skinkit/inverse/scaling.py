"""Scaled coordinates for the free parameters of a fit (thesis Eq 7.13, and logarithmic).

* ``bounds``: θ = (p − L)/(U − L) in [0, 1] (Eq 7.13), for parameters with finite bounds;
* ``log``: θ = log10(p / p0) for positive parameters whose range spans more than two
  decades (a relaxation time between 0.05 and 200 s), so a step means a ratio;
* ``value``: θ = p / |p0| for the rest (unbounded parameters), p0 the start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from skinkit.schemas import ParameterSet


@dataclass(frozen=True)
class Scaling:
    """Map between free parameter values ``p`` [SI] and scaled coordinates θ."""

    names: tuple[str, ...]
    kinds: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    ref: np.ndarray

    @classmethod
    def for_parameters(cls, pset: ParameterSet, names: list[str] | None = None) -> Scaling:
        """The scaling of ``names`` (default: the free parameters of ``pset``)."""
        names = list(names if names is not None else pset.free_names)
        kinds, lo, hi, ref = [], [], [], []
        for n in names:
            p = pset.param(n)
            L, U = p.lower, p.upper
            if L > 0 and math.isfinite(U) and U / L > 100:
                kinds.append("log")
            elif math.isfinite(L) and math.isfinite(U) and U > L:
                kinds.append("bounds")
            else:
                kinds.append("value")
            lo.append(L)
            hi.append(U)
            ref.append(p.value if p.value != 0 else 1.0)
        return cls(tuple(names), tuple(kinds), np.array(lo, float), np.array(hi, float), np.array(ref, float))

    def to_scaled(self, p: np.ndarray) -> np.ndarray:
        """θ ``(n,)`` of values ``p`` ``(n,)`` [SI]."""
        p = np.asarray(p, dtype=float)
        out = np.empty_like(p)
        for i, k in enumerate(self.kinds):
            if k == "log":
                out[i] = math.log10(p[i] / abs(self.ref[i]))
            elif k == "bounds":
                out[i] = (p[i] - self.lower[i]) / (self.upper[i] - self.lower[i])
            else:
                out[i] = p[i] / abs(self.ref[i])
        return out

    def to_values(self, theta: np.ndarray) -> np.ndarray:
        """Values ``p`` [SI] of scaled coordinates θ (clipped into the bounds)."""
        th = np.asarray(theta, dtype=float)
        out = np.empty_like(th)
        for i, k in enumerate(self.kinds):
            if k == "log":
                out[i] = abs(self.ref[i]) * 10.0 ** th[i]
            elif k == "bounds":
                out[i] = self.lower[i] + (self.upper[i] - self.lower[i]) * th[i]
            else:
                out[i] = abs(self.ref[i]) * th[i]
        return np.clip(out, self.lower, self.upper)

    def dvalue_dscaled(self, theta: np.ndarray) -> np.ndarray:
        """``(n,)`` dp/dθ at θ (the Jacobian of the map is diagonal)."""
        p = self.to_values(theta)
        out = np.empty_like(p)
        for i, k in enumerate(self.kinds):
            if k == "log":
                out[i] = p[i] * math.log(10.0)
            elif k == "bounds":
                out[i] = self.upper[i] - self.lower[i]
            else:
                out[i] = abs(self.ref[i])
        return out

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of θ."""
        return self.to_scaled_bound(self.lower), self.to_scaled_bound(self.upper)

    def to_scaled_bound(self, b: np.ndarray) -> np.ndarray:
        """Bounds ``b`` (n,) [SI] in scaled coordinates (infinite ones stay infinite)."""
        out = np.empty(len(self.names))
        for i, k in enumerate(self.kinds):
            if not math.isfinite(b[i]):
                out[i] = b[i]
            elif k == "log":
                out[i] = math.log10(b[i] / abs(self.ref[i]))
            elif k == "bounds":
                out[i] = (b[i] - self.lower[i]) / (self.upper[i] - self.lower[i])
            else:
                out[i] = b[i] / abs(self.ref[i])
        return out


__all__ = ["Scaling"]
