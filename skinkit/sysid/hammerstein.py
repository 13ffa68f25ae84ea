"""Hammerstein model (static polynomial of the force, then unit-DC-gain second-order
dynamics), for comparison with the Wiener model (thesis 4.1.2: it describes skin worse).

Given the dynamics, the output is linear in the polynomial coefficients
(``y = sum_j c_j H(f^j)``), so they are solved exactly inside a least-squares search over
the scaled inertia and damping (variable projection), started from the linear model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from skinkit.sysid.checks import Signals, SysidError
from skinkit.sysid.linear import LinearModel, identify_signals
from skinkit.sysid.lti import SecondOrder, simulate
from skinkit.sysid.metrics import vaf
from skinkit.sysid.nonlinearity import StaticNonlinearity
from skinkit.sysid.record import as_signals


@dataclass
class HammersteinModel:
    """``y = H(g(f))``: ``g`` a polynomial of force [N] -> [m], ``H`` unit DC gain with
    scaled inertia ``Is_s2`` [s^2] and damping ``Bs_s`` [s]."""

    Is_s2: float
    Bs_s: float
    nonlinearity: StaticNonlinearity
    linear: LinearModel
    vaf_hammerstein_pct: float
    rate_hz: float
    hold: str
    issues: list[str] = field(default_factory=list)

    @property
    def dynamics(self) -> SecondOrder:
        """The identified second-order dynamics (from the scaled Is and Bs)."""
        return SecondOrder.from_scaled(self.Is_s2, self.Bs_s)

    def predict(self, force_N: np.ndarray) -> np.ndarray:
        """Position [m] ``(N,)`` for force ``(N,)`` [N], simulated from equilibrium."""
        u = self.nonlinearity(np.asarray(force_N, float))
        return simulate(self.dynamics, u, self.rate_hz, self.hold)

    def to_dict(self) -> dict[str, Any]:
        """The linear model's dict with the Hammerstein fields and the nonlinearity added."""
        d = self.linear.to_dict()
        d.update({"model": "hammerstein", "Is_s2": self.Is_s2, "Bs_s": self.Bs_s,
                  "vaf_hammerstein_pct": self.vaf_hammerstein_pct,
                  "nonlinearity": self.nonlinearity.to_dict(), "warnings": list(self.issues)})
        return d


def identify_hammerstein_signals(sig: Signals, memory_s: float | None = None, *,
                                 degree: int = 3, hold: str = "foh",
                                 linear: LinearModel | None = None,
                                 **linear_kw: Any) -> HammersteinModel:
    """:func:`identify_hammerstein` on already checked :class:`Signals`."""
    if degree < 1:
        raise SysidError(f"polynomial degree must be at least 1, got {degree}")
    lin = linear if linear is not None else identify_signals(sig, memory_s, hold=hold, **linear_kw)
    f, y, rate = sig.force_N, sig.position_m, sig.rate_hz
    hold = lin.hold if lin.hold != "impulse" else "foh"
    burn = lin.burn_in
    yy = y[burn:]
    fs = (f - f.mean()) / np.std(f)  # powers of a standardised force keep the basis conditioned
    powers = np.vander(fs, degree + 1)  # highest power first, constant last

    def basis(q: np.ndarray) -> np.ndarray:
        dyn = SecondOrder.from_scaled(*np.exp(q))
        cols = [simulate(dyn, powers[:, j], rate, hold) for j in range(degree)]
        return np.column_stack([*cols, np.ones(f.size)])[burn:]

    def resid(q: np.ndarray) -> np.ndarray:
        X = basis(q)
        c, *_ = np.linalg.lstsq(X, yy, rcond=None)
        return X @ c - yy

    if not lin.valid:
        raise SysidError("the linear model is not a stable under-damped system, so no "
                         "Hammerstein model can start from it (see its warnings)")
    q0 = np.log([lin.total.Is_s2, lin.total.Bs_s])
    sol = least_squares(resid, q0, method="lm")
    X = basis(sol.x)
    c, *_ = np.linalg.lstsq(X, yy, rcond=None)
    # express g in the raw force: g(f) = sum_j c_j ((f - m)/s)^j
    m, s = float(f.mean()), float(np.std(f))
    poly = np.poly1d(c)
    g_raw = poly(np.poly1d([1.0 / s, -m / s]))
    g = StaticNonlinearity("polynomial", tuple(float(v) for v in g_raw.coeffs))
    v = vaf(yy, X @ c)
    Is, Bs = (float(x) for x in np.exp(sol.x))
    return HammersteinModel(Is, Bs, g, lin, v, rate, hold, sig.issues)


def identify_hammerstein(force_N: Any, position_m: Any = None, rate_hz: float | None = None,
                         memory_s: float | None = None, *, time_s: Any = None, degree: int = 3,
                         hold: str = "foh", flags: Any = None,
                         force_limit_N: float | None = None,
                    axis: int | str = 2,
                         **linear_kw: Any) -> HammersteinModel:
    """Identify a Hammerstein model; arguments as :func:`identify_wiener`."""
    sig = as_signals(force_N, position_m, rate_hz, time_s, memory_s, flags, force_limit_N, axis)
    return identify_hammerstein_signals(sig, memory_s, degree=degree, hold=hold, **linear_kw)
