"""Damped-sinusoid fit of an IRF (thesis Eq. 4.4) by Levenberg-Marquardt."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from skinkit.sysid.irf import IRF
from skinkit.sysid.lti import SecondOrder, kernel
from skinkit.sysid.metrics import vaf


@dataclass(frozen=True)
class DampedFit:
    """``h(t) = A1 sin(A2 t) exp(A3 t)`` fitted to an IRF.

    Attributes:
        A1: [m/(N s)], A2: damped natural frequency [rad/s], A3: decay rate [1/s] (< 0).
        vaf_pct: VAF of the fit against the IRF samples [%].
        underdamped: False when the IRF did not look like a decaying oscillation.
    """

    A1: float
    A2: float
    A3: float
    vaf_pct: float
    underdamped: bool = True

    @property
    def system(self) -> SecondOrder:
        """The second-order system (K, B, I) of the fitted damped sinusoid."""
        return SecondOrder.from_damped_sinusoid(self.A1, self.A2, self.A3)


def _initial(h: np.ndarray, rate_hz: float) -> tuple[float, float, float, bool]:
    """Poles of an AR(2) model of the IRF samples (a sampled damped sinusoid obeys
    ``h[k] = 2 r cos(wT) h[k-1] - r^2 h[k-2]`` exactly)."""
    T = 1.0 / rate_hz
    k0 = 2
    A = np.column_stack([h[k0 - 1:-1], h[k0 - 2:-2]])
    c, *_ = np.linalg.lstsq(A, h[k0:], rcond=None)
    disc = c[0] ** 2 + 4 * c[1]
    r2 = -c[1]
    ok = disc < 0 and 0 < r2 < 1
    if ok:
        r = np.sqrt(r2)
        w = np.arccos(np.clip(c[0] / (2 * r), -1, 1)) / T
        a3 = np.log(r) / T
    else:  # fall back on the first peak as a quarter period and a few periods of decay
        kp = max(int(np.argmax(np.abs(h))), 1)
        w = np.pi / (2 * kp * T)
        a3 = -w / 3
    t = np.arange(h.size) * T
    basis = np.sin(w * t) * np.exp(a3 * t)
    a1 = float(basis @ h / max(basis @ basis, 1e-300))
    return a1, float(w), float(a3), bool(ok)


def fit_damped_sinusoid(irf: IRF, hold: str = "foh") -> DampedFit:
    """Fit A1, A2, A3 to the causal part of ``irf`` by Levenberg-Marquardt.

    The model is sampled as the correlation estimate sees it for input ``hold`` (see
    :func:`skinkit.sysid.lti.kernel`), so the sampling does not bias K, B and I.
    """
    nn = irf.n_neg
    h = irf.h[nn:]
    a1, a2, a3, _ = _initial(h, irf.rate_hz)

    def resid(p: np.ndarray) -> np.ndarray:
        return kernel(p[0], p[1], p[2], h.size, irf.rate_hz, hold) - h

    scale = np.array([abs(a1) or 1.0, abs(a2) or 1.0, abs(a3) or 1.0])
    sol = least_squares(resid, np.array([a1, a2, a3]), method="lm", x_scale=scale)
    A1, A2, A3 = (float(v) for v in sol.x)
    if A2 < 0:  # sin is odd: (A1, A2) and (-A1, -A2) are the same curve
        A1, A2 = -A1, -A2
    fit = kernel(A1, A2, A3, h.size, irf.rate_hz, hold)
    # judged on the fit itself: the AR(2) start only seeds the search
    under = A3 < 0 and A1 > 0 and A2 > 0
    return DampedFit(A1, A2, A3, vaf(h, fit), under)
