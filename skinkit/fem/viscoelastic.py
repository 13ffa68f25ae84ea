"""Time integration of a quasi-linear viscoelastic (Prony series) stress at quadrature points.

With Sₑ(t) the elastic PK2 stress and g_R(t) = g∞ + Σᵢ gᵢ exp(-t/τᵢ), g∞ = 1 - Σᵢ gᵢ:

S = g∞ Sₑ + Σᵢ gᵢ hᵢ,  hᵢ(t) = ∫ exp(-(t - s)/τᵢ) dSₑ/ds ds.

Over a step Δt with Sₑ linear in time, hᵢ is exact (Taylor & Pister's recurrence):
hᵢⁿ⁺¹ = eᵢ hᵢⁿ + βᵢ (Sₑⁿ⁺¹ - Sₑⁿ), eᵢ = exp(-Δt/τᵢ), βᵢ = (1 - eᵢ) τᵢ/Δt,
and the algorithmic tangent is (g∞ + Σᵢ gᵢ βᵢ) CCₑ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def step_factors(g: np.ndarray, tau: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, float]:
    """``(e, β, tangent factor)`` for a step ``dt`` [s] (``dt = 0``: instantaneous response)."""
    g = np.asarray(g)
    tau = np.asarray(tau)
    if dt <= 0:
        e = np.ones_like(tau)
        beta = np.ones_like(tau)
    else:
        x = dt / tau
        e = np.exp(-x)
        beta = -np.expm1(-x) / x
    ginf = 1 - g.sum()
    return e, beta, ginf + (g * beta).sum()


@dataclass
class PronyState:
    """History at quadrature points: ``h`` ``(n_terms, ..., 3, 3)`` and last ``Se`` ``(..., 3, 3)``."""

    h: np.ndarray
    Se: np.ndarray

    @classmethod
    def zeros(cls, n_terms: int, shape: tuple[int, ...]) -> PronyState:
        """A zero history for ``n_terms`` Prony terms at integration points of ``shape``."""
        return cls(np.zeros((n_terms, *shape, 3, 3)), np.zeros((*shape, 3, 3)))

    def copy(self) -> PronyState:
        """An independent copy."""
        return PronyState(self.h.copy(), self.Se.copy())


def trial(state: PronyState, g: np.ndarray, tau: np.ndarray, dt: float, Se: np.ndarray):
    """``(S, factor, h_new)``: total stress, tangent factor, and the trial history."""
    e, beta, fac = step_factors(g, tau, dt)
    dSe = Se - state.Se
    h_new = np.empty(state.h.shape, dtype=np.result_type(state.h, Se))
    S = (1 - np.sum(g)) * Se
    # a loop over the (few) terms: tensordot would copy the strided history slices
    for i in range(h_new.shape[0]):
        h_new[i] = e[i] * state.h[i] + beta[i] * dSe
        S = S + g[i] * h_new[i]
    return S, fac, h_new
