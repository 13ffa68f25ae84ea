"""Truth forms of the alternative gap benchmark, written apart from the effect plugins.

Every function here is plain NumPy on arrays: the drive programme, the exponential elastic
element and, for each effect a lumped model can lack, forms of it that the candidate effects
do not share (the plugins' forms are Prony terms by their exact recurrence, a softening that
develops along the loading strokes or follows the largest load, a force drift linear in time,
a one-exponential warm-up, a constant channel delay, a linear series compliance solved with
the element and a regularised Coulomb friction that follows the velocity;
``docs/guide/gap-benchmark.md`` sets each truth against them). Nothing is imported from the
plugins or from the forward model's relaxation, preconditioning or instrument code: a truth
made here checks the diagnosis against forms it did not make
(``tests/gap/test_benchmark_alternative.py`` parses the imports).

Units are SI throughout: time [s], displacement [m], force [N].
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.signal import fftconvolve


# -- the drive programme --------------------------------------------------------------------------
@dataclass(frozen=True)
class Programme:
    """A displacement programme sampled uniformly.

    ``t`` ``(T,)`` [s] from 0; ``u`` ``(T,)`` [m] the pads' separation beyond rest; ``cycle``
    ``(T,)`` the cycle each sample belongs to (0 for the rest before the first ramp and the
    first cycle, k from the start of ramp k + 1 on); ``rate_hz`` the sampling rate."""

    t: np.ndarray
    u: np.ndarray
    cycle: np.ndarray
    rate_hz: float

    @property
    def dt(self) -> float:
        """Sampling interval [s]."""
        return 1.0 / self.rate_hz

    @property
    def velocity(self) -> np.ndarray:
        """``(T,)`` du/dt [m/s], central differences (exact on the ramps' interiors)."""
        return np.gradient(self.u, self.t)


def ramp_hold_return(*, peak_m: float = 9e-3, speed_m_s: float = 1e-3, hold_s: float = 40.0,
                     cycles: int = 4, rest_s: float = 5.0, between_s: float = 2.0,
                     rate_hz: float = 100.0) -> Programme:
    """``cycles`` cycles of: ramp from 0 to ``peak_m`` at ``speed_m_s``, hold ``hold_s``, return at
    the same speed; ``rest_s`` at 0 before the first cycle and ``between_s`` between cycles (the
    extension-relaxation record's programme: four cycles to about 9 mm at 1 mm/s, long holds)."""
    ramp = peak_m / speed_m_s
    # breakpoints (time, displacement) of the piecewise-linear programme
    knots_t, knots_u = [0.0, rest_s], [0.0, 0.0]
    starts = []
    for k in range(cycles):
        t0 = knots_t[-1] + (between_s if k else 0.0)
        if k:
            knots_t.append(t0)
            knots_u.append(0.0)
        starts.append(t0)
        knots_t += [t0 + ramp, t0 + ramp + hold_s, t0 + 2 * ramp + hold_s]
        knots_u += [peak_m, peak_m, 0.0]
    n = int(round(knots_t[-1] * rate_hz)) + 1
    t = np.arange(n) / rate_hz
    u = np.interp(t, knots_t, knots_u)
    cycle = np.searchsorted(np.asarray(starts[1:]) - 0.5 / rate_hz, t)
    return Programme(t, u, cycle.astype(int), float(rate_hz))


# -- the base model ---------------------------------------------------------------------------------
def exponential_force(u: np.ndarray, a: float, b: float) -> np.ndarray:
    """F = a (exp(b u) − 1) [N]: ``a`` [N], ``b`` [1/m], ``u`` [m], any shape."""
    return a * np.expm1(b * np.asarray(u, float))


# -- hereditary integrals (viscoelastic forms) ------------------------------------------------------
def hereditary(dt: float, fe: np.ndarray, antiderivative: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """F(t) = ∫ G(t − s) dFe(s) for ``fe`` ``(T,)`` sampled every ``dt`` [s], exact for ``fe``
    linear between samples: the increment over [t_{m−1}, t_m] weighs G averaged over its
    elapsed times, K[j] = (I((j+1)dt) − I(j dt)) / dt, with ``antiderivative`` I(s) = ∫₀ˢ G
    (vectorised, I(0) = 0). The first sample's value counts as an increment at t₀ (zero when the
    record starts at rest). A direct convolution (FFT), no recurrence: any kernel works."""
    fe = np.asarray(fe, float)
    d = np.diff(fe, prepend=0.0)
    s = dt * np.arange(fe.size + 1, dtype=float)
    kernel = np.diff(antiderivative(s)) / dt
    return fftconvolve(d, kernel)[:fe.size]


def prony_antiderivative(g: tuple[float, ...], tau: tuple[float, ...]) -> Callable[[np.ndarray], np.ndarray]:
    """I(s) of G(s) = g∞ + Σ gᵢ exp(−s/τᵢ), g∞ = 1 − Σ gᵢ (G(0) = 1): g∞ s + Σ gᵢ τᵢ (1 − e^(−s/τᵢ))."""
    ginf = 1.0 - sum(g)

    def integral(s: np.ndarray) -> np.ndarray:
        return ginf * s + sum(gi * ti * -np.expm1(-s / ti) for gi, ti in zip(g, tau, strict=True))

    return integral


def power_law_antiderivative(g_inf: float, t0: float, alpha: float) -> Callable[[np.ndarray], np.ndarray]:
    """I(s) of G(s) = g∞ + (1 − g∞)(1 + s/t0)^(−α) (``t0`` [s], 0 < α ≠ 1): a fractional
    relaxation, no single time scale: g∞ s + (1 − g∞) t0 ((1 + s/t0)^(1−α) − 1) / (1 − α)."""

    def integral(s: np.ndarray) -> np.ndarray:
        return g_inf * s + (1 - g_inf) * t0 * np.expm1((1 - alpha) * np.log1p(s / t0)) / (1 - alpha)

    return integral


def stretch_dependent_relaxation(prog: Programme, fe: np.ndarray, gamma_max: float, tau: float,
                                 power: float = 2.0) -> np.ndarray:
    """A relaxing fraction that grows with stretch (not quasi-linear): the force increment laid
    down at stretch u relaxes by γ(u) = γ_max (u/u_max)^power with time constant ``tau`` [s],
    F(t) = ∫ [1 − γ(u(s)) (1 − e^(−(t−s)/τ))] dFe(s). ``fe`` ``(T,)`` [N]; u_max the programme's
    largest stretch. Small stretches do not relax, the peak relaxes by γ_max."""
    u = prog.u
    u_mid = 0.5 * (u + np.concatenate([[u[0]], u[:-1]]))      # the increment's stretch
    gamma = gamma_max * (np.abs(u_mid) / np.max(np.abs(u))) ** power
    d = np.diff(np.asarray(fe, float), prepend=0.0)
    relaxing = gamma * d
    s = prog.dt * np.arange(fe.size + 1, dtype=float)
    decay = np.diff(tau * -np.expm1(-s / tau)) / prog.dt      # e^(−s/τ) averaged per step
    return np.cumsum(d) - np.cumsum(relaxing) + fftconvolve(relaxing, decay)[:fe.size]


# -- preconditioning forms ---------------------------------------------------------------------------
def cycle_count_softening(prog: Programme, fe: np.ndarray, s: float, n: float) -> np.ndarray:
    """Cycle k's force (k = 0 the first) scaled by 1 − s (1 − e^(−k/n)): a softening that goes on
    with every cycle towards 1 − s, at a pace ``n`` [cycles] — not set by the largest stretch."""
    return np.asarray(fe, float) * (1 - s * -np.expm1(-prog.cycle / n))


def step_softening(prog: Programme, fe: np.ndarray, s: float) -> np.ndarray:
    """The whole first cycle at full stiffness, every later cycle scaled by 1 − ``s``."""
    return np.asarray(fe, float) * np.where(prog.cycle == 0, 1.0, 1.0 - s)


# -- force-drift forms ---------------------------------------------------------------------------------
def warmup_drift(t: np.ndarray, amplitudes: tuple[float, ...], taus: tuple[float, ...]) -> np.ndarray:
    """A sensor's warm-up with several time constants (the bridge and the amplifier settle
    apart): Σ Aᵢ (1 − e^(−t/τᵢ)) [N], ``amplitudes`` Aᵢ [N], ``taus`` τᵢ [s]."""
    t = np.asarray(t, float)
    return sum((a * -np.expm1(-t / tau) for a, tau in zip(amplitudes, taus, strict=True)), np.zeros_like(t))


def thermal_drift(t: np.ndarray, amplitude: float, period: float, phase: float = 0.0) -> np.ndarray:
    """A slow thermal swing: B sin(2π t/P + ϕ) [N], ``period`` P [s], ``phase`` ϕ [rad]."""
    return amplitude * np.sin(2 * np.pi * np.asarray(t, float) / period + phase)


# -- channel timing forms ------------------------------------------------------------------------------
def clock_skew(t: np.ndarray, f: np.ndarray, lag_end: float) -> np.ndarray:
    """The force channel's clock running slow against the position's: the sample recorded at t
    holds the force of t − λ(t), λ growing linearly from 0 to ``lag_end`` [s] at the record's
    end (linear interpolation between samples; held at the first sample before it)."""
    t = np.asarray(t, float)
    lag = lag_end * (t - t[0]) / (t[-1] - t[0])
    return np.interp(t - lag, t, np.asarray(f, float))


# -- robot-compliance form -------------------------------------------------------------------------------
def series_nonlinear_spring(u_motor: np.ndarray, a: float, b: float, c: float, kappa: float,
                            iterations: int = 80) -> np.ndarray:
    """The force through a slightly nonlinear spring in series with the exponential element:
    the motor's position ``u_motor`` [m] = tip + δ(F), δ(F) = c F (1 + κ |F|) (``c`` [m/N],
    ``kappa`` [1/N]), and F = a (exp(b · tip) − 1). Solved by bisection per sample (F lies
    between 0 and the element's force at the motor's position; the residual is monotone)."""
    u = np.asarray(u_motor, float)
    f_rigid = exponential_force(u, a, b)
    lo, hi = np.minimum(0.0, f_rigid), np.maximum(0.0, f_rigid)
    for _ in range(iterations):
        f = 0.5 * (lo + hi)
        excess = exponential_force(u - c * f * (1 + kappa * np.abs(f)), a, b) - f
        lo = np.where(excess > 0, f, lo)
        hi = np.where(excess > 0, hi, f)
    return 0.5 * (lo + hi)


# -- artefacts no effect describes ----------------------------------------------------------------------
def clipped(f: np.ndarray, upper: float) -> np.ndarray:
    """A force sensor saturating at ``upper`` [N]: recorded values above it read ``upper``."""
    return np.minimum(np.asarray(f, float), upper)


def mains_interference(t: np.ndarray, amplitude: float, mains_hz: float = 49.8,
                       third: float = 0.3) -> np.ndarray:
    """Mains pick-up sampled at the record's rate [N]: a tone at ``mains_hz`` and its third
    harmonic (relative size ``third``). At 100 Hz the fundamental lies just below Nyquist (an
    alternating sequence under a slow beat) and the harmonic folds to 100 − 3 f (about 49 Hz)."""
    t = np.asarray(t, float)
    return amplitude * (np.sin(2 * np.pi * mains_hz * t) + third * np.sin(2 * np.pi * 3 * mains_hz * t + 1.0))


def cable_tugs(t: np.ndarray, rng: np.random.Generator, amplitude: float, count: int,
               duration: float, margin: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """The sensor's cable tugged now and then (brushed by an arm, caught on the table's edge): ``count``
    raised-cosine bumps of height ±``amplitude`` [N] (sign drawn) lasting ``duration`` [s], at times
    drawn uniformly over the record but ``margin`` [s] at each end. Returns the force ``(T,)`` [N]
    and the bumps' centres [s] (sorted)."""
    t = np.asarray(t, float)
    centres = np.sort(rng.uniform(t[0] + margin, t[-1] - margin, count))
    signs = rng.choice((-1.0, 1.0), count)
    out = np.zeros_like(t)
    for c, s in zip(centres, signs, strict=True):
        x = (t - c) / duration
        inside = np.abs(x) < 0.5
        out[inside] += s * amplitude * 0.5 * (1 + np.cos(2 * np.pi * x[inside]))
    return out, centres


# -- guide-friction forms ------------------------------------------------------------------------------
def dahl_friction(u: np.ndarray, level: float, presliding: float) -> np.ndarray:
    """Dahl's friction along a stroke ``u`` ``(T,)`` [m] [N]: dF/du = (level − F sign(du)) / x₀ with
    x₀ = ``presliding`` [m], a rate-independent friction with a presliding stiffness level/x₀ that
    holds its last value when the motion stops. Per step, exactly for a constant direction:
    z ← s + (z − s) e^(−|Δu|/x₀), F = level · z, z = 0 at the start."""
    u = np.asarray(u, float)
    du = np.diff(u, prepend=u[0])
    z = np.zeros_like(u)
    zi = 0.0
    for i, d in enumerate(du):
        if d != 0.0:
            s = 1.0 if d > 0 else -1.0
            zi = s + (zi - s) * math.exp(-abs(d) / presliding)
        z[i] = zi
    return level * z


__all__ = ["Programme", "cable_tugs", "clipped", "clock_skew", "cycle_count_softening", "dahl_friction",
           "exponential_force", "hereditary", "mains_interference", "power_law_antiderivative",
           "prony_antiderivative", "ramp_hold_return", "series_nonlinear_spring", "step_softening",
           "stretch_dependent_relaxation", "thermal_drift", "warmup_drift"]
