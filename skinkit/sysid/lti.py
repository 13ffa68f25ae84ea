"""Second-order mechanical dynamics and their simulation with :mod:`scipy.signal`.

The force-to-position transfer function of a mass-spring-damper (thesis Eq. 4.2) is
``H(s) = 1 / (I s^2 + B s + K)``. Its impulse response is the damped sinusoid of Eq. 4.4,
``h(t) = A1 sin(A2 t) exp(A3 t)``, with (derived here; the extracted Eqs 4.5-4.7 lose the
sign of B)::

    A2 = sqrt(K/I - (B/2I)^2)    (damped natural frequency, rad/s)
    A3 = -B / (2 I)              (decay rate, 1/s, negative)
    A1 = 1 / (I A2)              (m / (N s))

and inversely ``I = 1/(A1 A2)``, ``B = -2 A3/(A1 A2)``, ``K = (A2^2 + A3^2)/(A1 A2)``.
The same system as gain, natural frequency and damping ratio (Eq. 4.3, gain = 1/K = DC
compliance): ``H(s) = gain wn^2 / (s^2 + 2 zeta wn s + wn^2)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

#: how the sampled force is assumed to vary between samples
HOLDS = ("foh", "zoh", "impulse")


@dataclass(frozen=True)
class SecondOrder:
    """Stiffness ``K`` [N/m], damping ``B`` [N s/m] and inertia ``I`` [kg]."""

    K: float
    B: float
    I: float

    @property
    def wn_rad_s(self) -> float:
        """Undamped natural frequency [rad/s]."""
        return float(np.sqrt(self.K / self.I))

    @property
    def zeta(self) -> float:
        """Damping ratio [1]."""
        return float(self.B / (2.0 * np.sqrt(self.K * self.I)))

    @property
    def gain_m_per_N(self) -> float:
        """DC compliance 1/K [m/N]."""
        return 1.0 / self.K

    @property
    def Is_s2(self) -> float:
        """Scaled inertia I/K [s^2] (dynamics with unit DC gain, thesis Table 8)."""
        return self.I / self.K

    @property
    def Bs_s(self) -> float:
        """Scaled damping B/K [s]."""
        return self.B / self.K

    def damped_sinusoid(self) -> tuple[float, float, float]:
        """``(A1 [m/(N s)], A2 [rad/s], A3 [1/s])`` of the impulse response (under-damped only)."""
        a3 = -self.B / (2.0 * self.I)
        w2 = self.K / self.I - a3 * a3
        if w2 <= 0:
            raise ValueError("system is not under-damped: no damped sinusoid form")
        a2 = float(np.sqrt(w2))
        return 1.0 / (self.I * a2), a2, a3

    @classmethod
    def from_damped_sinusoid(cls, a1: float, a2: float, a3: float) -> SecondOrder:
        """Inverse of :meth:`damped_sinusoid`."""
        d = a1 * a2
        return cls(K=(a2 * a2 + a3 * a3) / d, B=-2.0 * a3 / d, I=1.0 / d)

    @classmethod
    def from_scaled(cls, Is_s2: float, Bs_s: float, K: float = 1.0) -> SecondOrder:
        """A system with DC gain 1/K from scaled inertia and damping."""
        return cls(K=K, B=Bs_s * K, I=Is_s2 * K)

    def tf(self) -> tuple[list[float], list[float]]:
        """``(num, den)`` of H(s) = 1/(I s^2 + B s + K) [m/N]."""
        return [1.0], [self.I, self.B, self.K]

    def to_dict(self) -> dict[str, float]:
        """K [N/m], B [N s/m], I [kg], gain [m/N], natural frequency [rad/s] and damping ratio as a dict."""
        return {"K_N_per_m": self.K, "B_Ns_per_m": self.B, "I_kg": self.I,
                "gain_m_per_N": self.gain_m_per_N, "wn_rad_s": self.wn_rad_s, "zeta": self.zeta}


def discretise(num: list[float], den: list[float], rate_hz: float,
               hold: str = "foh") -> tuple[np.ndarray, np.ndarray]:
    """Discrete ``(b, a)`` of a continuous transfer function for input held by ``hold``.

    ``"foh"`` (force varying linearly between samples, right for a measured smooth force)
    or ``"zoh"`` (force held constant, right for a digitally commanded force).
    """
    if hold not in ("foh", "zoh"):
        raise ValueError(f"hold must be 'foh' or 'zoh' for simulation, got {hold!r}")
    if len(num) == 1 and len(den) == 3 and den[0] != 0:
        # an under-damped second-order system in closed form (no matrix exponential: this
        # runs inside every least-squares iteration)
        p = np.roots(den)
        if abs(p[0].imag) > 0:
            a3, a2 = float(p[0].real), abs(float(p[0].imag))
            a1 = num[0] / (den[0] * a2)
            T = 1.0 / rate_hz
            a = np.array([1.0, -2 * np.exp(a3 * T) * np.cos(a2 * T), np.exp(2 * a3 * T)])
            g = kernel(a1, a2, a3, 3, rate_hz, hold) * T  # first pulse-response samples
            return np.convolve(a, g)[:3], a
    b, a, _ = signal.cont2discrete((num, den), 1.0 / rate_hz, method=hold)
    b = np.atleast_2d(b)[0]
    return b / a[0], np.asarray(a, float) / a[0]


def simulate_tf(num: list[float], den: list[float], u: np.ndarray, rate_hz: float,
                hold: str = "foh", at_rest: bool = True) -> np.ndarray:
    """Response of ``num/den`` to input samples ``u`` ``(N,)`` at ``rate_hz``.

    With ``at_rest`` the system starts in equilibrium under the first input sample (no
    start-up transient); otherwise it starts from zero state.
    """
    b, a = discretise(num, den, rate_hz, hold)
    u = np.asarray(u, float)
    if at_rest:
        zi = signal.lfilter_zi(b, a) * u[0]
        return signal.lfilter(b, a, u, zi=zi)[0]
    return signal.lfilter(b, a, u)


def simulate(system: SecondOrder, force_N: np.ndarray, rate_hz: float, hold: str = "foh",
             at_rest: bool = True) -> np.ndarray:
    """Position [m] ``(N,)`` of ``system`` under ``force_N`` ``(N,)`` [N]."""
    num, den = system.tf()
    return simulate_tf(num, den, force_N, rate_hz, hold, at_rest)


def kernel(a1: float, a2: float, a3: float, n_lags: int, rate_hz: float,
           hold: str = "foh", first_lag: int = 0) -> np.ndarray:
    """Sampled IRF [m/(N s)] of the damped sinusoid as a correlation estimate sees it.

    A discrete IRF estimated from sampled data is the pulse response of the sampled system
    times the rate; it equals ``h(k T)`` only for ``hold="impulse"``. For ``"zoh"`` it is
    ``(s(kT) - s((k-1)T)) / T`` and for ``"foh"`` ``(r((k+1)T) - 2 r(kT) + r((k-1)T)) / T^2``,
    with ``s`` and ``r`` the step and ramp responses (closed forms below). Lags are
    ``first_lag ... first_lag + n_lags - 1`` samples.
    """
    T = 1.0 / rate_hz
    k = np.arange(first_lag, first_lag + n_lags, dtype=float)
    if hold == "impulse":
        t = k * T
        return np.where(t >= 0, a1 * np.sin(a2 * t) * np.exp(a3 * t), 0.0)
    d = a3 * a3 + a2 * a2

    def step(t: np.ndarray) -> np.ndarray:
        tt = np.maximum(t, 0.0)
        e = np.exp(a3 * tt)
        v = a1 * (e * (a3 * np.sin(a2 * tt) - a2 * np.cos(a2 * tt)) + a2) / d
        return np.where(t > 0, v, 0.0)

    def ramp(t: np.ndarray) -> np.ndarray:
        tt = np.maximum(t, 0.0)
        e = np.exp(a3 * tt)
        inner = (e * ((a3 * a3 - a2 * a2) * np.sin(a2 * tt) - 2 * a3 * a2 * np.cos(a2 * tt))
                 + 2 * a3 * a2) / d
        return np.where(t > 0, a1 / d * (a2 * tt + inner), 0.0)

    if hold == "zoh":
        return (step(k * T) - step((k - 1) * T)) / T
    if hold == "foh":
        return (ramp((k + 1) * T) - 2 * ramp(k * T) + ramp((k - 1) * T)) / (T * T)
    raise ValueError(f"hold must be one of {HOLDS}, got {hold!r}")
