"""Dynamic lumped elements: the K-B-I and Wiener models of :mod:`skinkit.sysid`, complex-safe.

K-B-I (thesis Eq 4.2): I y'' + B y' + K y = f, force f [N] in, position y [m] out.
Wiener (thesis 4.1.2): the unit-DC-gain dynamics Is x'' + Bs x' + x = f give x [N], then
y = C1 (1 − exp(−C2 x)) (Eq 4.9).

The force varies linearly between samples (first-order hold, ``"foh"``, right for a measured
force) or is held (``"zoh"``), and the system starts at rest under the first sample, as
:func:`skinkit.sysid.lti.simulate` does. The discretisation is exact and goes through the
matrix exponential of an augmented state matrix, which is analytic in K, B and I, so the
complex step differentiates it (the closed forms of :mod:`skinkit.sysid.lti` test the
real part, or the pole ordering, and are not).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import linalg, signal


def discretise(K: Any, B: Any, I: Any, dt: float, hold: str = "foh") -> tuple[np.ndarray, np.ndarray]:
    """``(b, a)`` in powers of z⁻¹ of the sampled 1/(I s² + B s + K) [m/N] for step ``dt`` [s]."""
    dtype = np.result_type(K, B, I, float)
    A = np.array([[0, 1], [-K / I, -B / I]], dtype=dtype)
    Bv = np.array([0, 1 / I], dtype=dtype)
    if hold == "zoh":
        M = np.zeros((3, 3), dtype=dtype)
        M[:2, :2], M[:2, 2] = A * dt, Bv * dt
        E = linalg.expm(M)
        Phi, G, D = E[:2, :2], E[:2, 2], 0 * K
    else:
        # u linear over a step: s⁺ = Φ s + Γ0 u + Γ1 (u⁺ − u), with Φ, Γ0, Γ1 blocks of
        # exp([[A, B, 0], [0, 0, 1/T], [0, 0, 0]] T)
        M = np.zeros((4, 4), dtype=dtype)
        M[:2, :2], M[:2, 2], M[2, 3] = A * dt, Bv * dt, 1.0
        E = linalg.expm(M)
        Phi, G0, G1 = E[:2, :2], E[:2, 2], E[:2, 3]
        # z = s − Γ1 u:  z⁺ = Φ z + (Φ Γ1 + Γ0 − Γ1) u,  y = z₀ + (Γ1)₀ u
        G, D = Phi @ G1 + G0 - G1, G1[0]
    tr, det = Phi[0, 0] + Phi[1, 1], Phi[0, 0] * Phi[1, 1] - Phi[0, 1] * Phi[1, 0]
    # y = C (zI − Φ)⁻¹ G u + D u with C = [1, 0] and adj(zI − Φ) = [[z − Φ₁₁, Φ₀₁], [Φ₁₀, z − Φ₀₀]]
    b = np.array([D, G[0] - D * tr, Phi[0, 1] * G[1] - Phi[1, 1] * G[0] + D * det])
    a = np.array([1 + 0 * tr, -tr, det])
    return b, a


def second_order(f: np.ndarray, K: Any, B: Any, I: Any, dt: float, hold: str = "foh") -> np.ndarray:
    """Position ``(T,)`` [m] of I y'' + B y' + K y = f under force ``f`` ``(T,)`` [N] sampled every
    ``dt`` [s], at rest under ``f[0]`` at the start (y = f[0]/K)."""
    b, a = discretise(K, B, I, dt, hold)
    # the sampled system's DC gain is exactly 1/K: the record starts in its steady state
    return f[0] / K + signal.lfilter(b, a, f - f[0])


def wiener(f: np.ndarray, Is: Any, Bs: Any, C1: Any, C2: Any, dt: float, hold: str = "foh") -> np.ndarray:
    """Position ``(T,)`` [m] of the Wiener model: x [N] from the unit-DC-gain dynamics under
    ``f`` ``(T,)`` [N], then C1 (1 − exp(−C2 x))."""
    x = second_order(f, 1.0, Bs, Is, dt, hold)
    if not any(np.iscomplexobj(v) for v in (x, C1, C2)):
        return C1 * -np.expm1(-C2 * x)
    return C1 * (1 - np.exp(-C2 * x))


__all__ = ["discretise", "second_order", "wiener"]
