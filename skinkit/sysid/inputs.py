"""Input design: stochastic force programmes, preconditioning and incremental protocols.

Thesis 4.1.3: a Gaussian force low-pass filtered at 200 Hz, scalable to the robot's force
limit; overall preconditioning by a 0.5 Hz sinusoidal ramp to full force for three periods,
a hold at full force, then the stochastic signal for 100 s; incremental protocols scale the
stochastic input to 20 % of full scale and step its mean over the range, 15 increments up
and 15 down, preconditioning each increment with a zero-max-zero triangle (protocol A) or
by holding the next increment's mean (protocol B).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from skinkit.sysid.checks import SysidError


@dataclass(frozen=True)
class Segment:
    """Samples ``start:stop`` of a programme: ``kind`` is ``"identify"`` (stochastic, to be
    identified) or ``"precondition"``; ``mean_N`` the segment's mean force [N];
    ``direction`` ``"up"``/``"down"`` for incremental steps (else ``""``)."""

    start: int
    stop: int
    kind: str
    mean_N: float
    direction: str = ""
    index: int = 0


@dataclass
class Programme:
    """A force programme: ``force_N`` ``(N,)`` [N] at ``rate_hz`` and its labelled segments."""

    force_N: np.ndarray
    rate_hz: float
    segments: list[Segment] = field(default_factory=list)

    @property
    def time_s(self) -> np.ndarray:
        """Sample times (N,) [s] from 0."""
        return np.arange(self.force_N.size) / self.rate_hz

    def identify_segments(self) -> list[Segment]:
        """The segments used for identification."""
        return [s for s in self.segments if s.kind == "identify"]


def _rng(seed: int | np.random.Generator) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def gaussian_force(duration_s: float, rate_hz: float, *, cutoff_hz: float = 200.0,
                   rms_N: float | None = None, peak_N: float | None = None, mean_N: float = 0.0,
                   seed: int | np.random.Generator = 0, order: int = 4) -> np.ndarray:
    """Gaussian white noise low-pass filtered at ``cutoff_hz`` (Butterworth of ``order``, zero
    phase), scaled to ``rms_N`` or so that its largest excursion is ``peak_N``, plus ``mean_N``.

    Returns ``(round(duration_s * rate_hz),)`` [N].
    """
    n = int(round(duration_s * rate_hz))
    if n < 2:
        raise SysidError(f"duration {duration_s!r} s at {rate_hz!r} Hz gives fewer than 2 samples")
    if not 0 < cutoff_hz < rate_hz / 2:
        raise SysidError(f"cutoff {cutoff_hz!r} Hz must lie between 0 and Nyquist {rate_hz / 2} Hz")
    if (rms_N is None) == (peak_N is None):
        raise SysidError("give exactly one of rms_N or peak_N")
    sos = signal.butter(order, cutoff_hz, fs=rate_hz, output="sos")
    f = signal.sosfiltfilt(sos, _rng(seed).standard_normal(n))
    f -= f.mean()
    f *= (rms_N / np.std(f)) if rms_N is not None else (peak_N / np.max(np.abs(f)))
    return f + mean_N


def scale_to_limit(force_N: np.ndarray, limit_N: float) -> np.ndarray:
    """Scale a programme about zero so that its largest magnitude equals ``limit_N`` [N]
    (e.g. 3 motors x 3.5 N under normal indentation)."""
    peak = float(np.max(np.abs(force_N)))
    if peak == 0:
        raise SysidError("cannot scale an all-zero force programme")
    return np.asarray(force_N, float) * (limit_N / peak)


def preconditioning(full_N: float, rate_hz: float, *, sine_hz: float = 0.5, periods: int = 3,
                    hold_s: float = 10.0, stochastic_s: float = 100.0, cutoff_hz: float = 200.0,
                    seed: int | np.random.Generator = 0) -> Programme:
    """Overall preconditioning: ``periods`` of a ``sine_hz`` sinusoidal ramp from zero to
    ``full_N``, ``hold_s`` at ``full_N``, then ``stochastic_s`` of stochastic force spanning
    ``0 ... full_N`` (thesis 4.1.3)."""
    ns = int(round(periods * rate_hz / sine_hz))
    t = np.arange(ns) / rate_hz
    ramp = 0.5 * full_N * (1 - np.cos(2 * np.pi * sine_hz * t))
    nh = int(round(hold_s * rate_hz))
    # after the last period the sinusoid is back at zero; ramp up in a half period to hold
    nu = int(round(rate_hz / (2 * sine_hz)))
    up = 0.5 * full_N * (1 - np.cos(np.pi * np.arange(nu) / nu))
    hold = np.full(nh, full_N)
    stoch = gaussian_force(stochastic_s, rate_hz, cutoff_hz=cutoff_hz, peak_N=full_N / 2,
                           mean_N=full_N / 2, seed=seed)
    parts = [ramp, up, hold, stoch]
    f = np.concatenate(parts)
    i0 = ns + nu + nh
    segs = [Segment(0, i0, "precondition", float(np.mean(f[:i0]))),
            Segment(i0, f.size, "identify", full_N / 2)]
    return Programme(f, rate_hz, segs)


def incremental(protocol: str, full_N: float, rate_hz: float, *, n_steps: int = 15,
                fraction: float = 0.2, step_s: float = 5.0, precondition_s: float = 2.0,
                cutoff_hz: float = 200.0, seed: int | np.random.Generator = 0) -> Programme:
    """Incremental protocol ``"A"`` or ``"B"``: a stochastic force spanning ``fraction`` of
    ``full_N`` whose mean steps over ``n_steps`` levels up then the same levels down.

    Before each step, protocol A applies a zero-``full_N``-zero triangle and protocol B
    holds the step's mean, each for ``precondition_s``. Every stochastic step is a segment
    of kind ``"identify"`` with its mean and direction.
    """
    if protocol not in ("A", "B"):
        raise SysidError(f"incremental protocol must be 'A' or 'B', got {protocol!r}")
    if not 0 < fraction < 1:
        raise SysidError(f"fraction must lie in (0, 1), got {fraction!r}")
    if n_steps < 2:
        raise SysidError(f"n_steps must be at least 2, got {n_steps!r}")
    rng = _rng(seed)
    half = fraction * full_N / 2
    means = np.linspace(half, full_N - half, n_steps)
    levels = [(m, "up", i) for i, m in enumerate(means)]
    levels += [(m, "down", i) for i, m in enumerate(means[::-1])]
    npre = int(round(precondition_s * rate_hz))
    parts: list[np.ndarray] = []
    segs: list[Segment] = []
    pos = 0
    for mean, direction, i in levels:
        if protocol == "A":
            pre = full_N * (1 - np.abs(np.linspace(-1, 1, npre)))
        else:
            pre = np.full(npre, mean)
        stoch = gaussian_force(step_s, rate_hz, cutoff_hz=cutoff_hz, peak_N=half,
                               mean_N=mean, seed=rng)
        segs.append(Segment(pos, pos + npre, "precondition", float(pre.mean()), direction, i))
        segs.append(Segment(pos + npre, pos + npre + stoch.size, "identify", float(mean),
                            direction, i))
        parts += [pre, stoch]
        pos += npre + stoch.size
    return Programme(np.concatenate(parts), rate_hz, segs)
