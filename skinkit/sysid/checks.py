"""Input validation for system identification: errors and named warnings.

A stochastic identification silently goes wrong on gaps, jittered clocks, NaNs, a constant
or clipped input, or a record too short for the requested memory. :func:`check_signals`
turns each of these into a :class:`SysidError` (one line naming what is wrong) or a named
:class:`SysidWarning` subclass, and returns signals that are safe to identify from.
"""

from __future__ import annotations

import os
import sys
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError


class SysidError(SkinkitError, ValueError):
    """The record cannot be identified (bad shapes, constant input, too short, ...)."""


class SysidWarning(UserWarning):
    """Base of every warning that a system identification result may be compromised."""


class GapWarning(SysidWarning):
    """The time column has gaps; only the longest uninterrupted segment was used."""


class NonUniformSamplingWarning(SysidWarning):
    """Sample intervals vary; the record was resampled onto a uniform grid."""


class NaNWarning(SysidWarning):
    """NaN samples were interpolated (short runs) or cut out (long runs)."""


class ClippedForceWarning(SysidWarning):
    """The force input sits at its extreme value for many samples (saturation)."""


class ClippedPositionWarning(SysidWarning):
    """The position output sits at its extreme value for many samples (travel limit)."""


class ShortRecordWarning(SysidWarning):
    """The record holds few memory lengths; the IRF estimate will be noisy."""


class NarrowbandInputWarning(SysidWarning):
    """The input is not broadband (e.g. a ramp-and-hold test, not a stochastic force)."""


class NonCausalWarning(SysidWarning):
    """The position leads the force: the force is probably not the input of this test."""


class MemoryWarning(SysidWarning):
    """The IRF has not decayed by the end of its memory (memory too short, or drift/creep)."""


class PoorFitWarning(SysidWarning):
    """A parametric fit is poor or outside its model class (e.g. not under-damped)."""


#: a sample interval longer than this many median intervals is a gap
GAP_FACTOR = 1.5
#: relative jitter of the sample interval tolerated without resampling
JITTER_RTOL = 1e-3
#: NaN runs up to this length [samples] are linearly interpolated, longer runs split the record
MAX_NAN_FILL = 2
#: the record must hold at least this many memory lengths (error) ...
MIN_MEMORIES = 5
#: ... and should hold this many (warning below)
WARN_MEMORIES = 10
#: fewest samples for any identification
MIN_SAMPLES = 64
#: a Gaussian-like input has ~1 sample at its extreme; more than this fraction is a plateau
CLIP_FRACTION = 2e-3
#: most IRF lags identified unless ``SKINKIT_MAX_IRF_LAGS`` allows more: the correlation IRF
#: eigen-decomposes an L x L matrix (about 32 L^2 bytes with LAPACK's workspace, L^3 time):
#: 4,096 lags take about 0.5 GB and tens of seconds, while a skin IRF lasts < 0.25 s, 500
#: lags at the robot's 2 kHz (thesis 4.2.1)
MAX_IRF_LAGS = 4096


@dataclass
class Signals:
    """Force and position ready for identification.

    Attributes:
        force_N: ``(N,)`` input force [N], uniform sampling, finite.
        position_m: ``(N,)`` output position [m].
        rate_hz: sampling rate [Hz].
        t0_s: time of the first sample [s].
        issues: ``"WarningName: message"`` for every warning raised while checking.
    """

    force_N: np.ndarray
    position_m: np.ndarray
    rate_hz: float
    t0_s: float = 0.0
    issues: list[str] = field(default_factory=list)

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.force_N.size)


def _user_stacklevel() -> int:
    """Stack level of the first caller outside skinkit.sysid (warnings point at user code)."""
    here = os.path.dirname(os.path.abspath(__file__))
    frame = sys._getframe(2)
    level = 2
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(here):
        frame = frame.f_back
        level += 1
    return level


def warn(category: type[SysidWarning], message: str, issues: list[str] | None = None) -> None:
    """Emit a named warning and remember it in ``issues`` (so results can carry it)."""
    warnings.warn(message, category, stacklevel=_user_stacklevel())
    if issues is not None:
        issues.append(f"{category.__name__}: {message}")


def _vector(a: Any, name: str) -> np.ndarray:
    try:
        # a copy: later steps interpolate NaN runs in place, and the caller's array is theirs
        arr = np.array(a, dtype=float, copy=True)
    except (TypeError, ValueError):
        raise SysidError(f"{name}: must be numbers, got {type(a).__name__}") from None
    if arr.ndim != 1:
        raise SysidError(f"{name}: must be one-dimensional (N,), got shape {arr.shape}")
    if np.isinf(arr).any():
        i = int(np.flatnonzero(np.isinf(arr))[0])
        raise SysidError(f"{name}: infinite value at sample {i}")
    return arr


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of the runs of True in ``mask``."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def _longest_segment(breaks: np.ndarray, n: int) -> tuple[int, int]:
    """Longest ``[start, stop)`` between break points (a break at i splits i-1 | i)."""
    edges = np.concatenate([[0], np.sort(breaks), [n]])
    k = int(np.argmax(np.diff(edges)))
    return int(edges[k]), int(edges[k + 1])


def _plateau_fraction(x: np.ndarray) -> tuple[float, float, float]:
    """Fraction of samples at the maximum and at the minimum (within 1e-6 of the range)."""
    lo, hi = float(x.min()), float(x.max())
    tol = 1e-6 * (hi - lo)
    return float(np.mean(x >= hi - tol)), float(np.mean(x <= lo + tol)), tol


def check_signals(force_N: Any, position_m: Any, *, rate_hz: float | None = None,
                  time_s: Any = None, memory_s: float | None = None, flags: Any = None,
                  force_limit_N: float | None = None) -> Signals:
    """Validate a force-to-position record and return uniform, finite signals.

    The caller's arrays are never modified (the signals returned are copies). The steps, in
    order: :func:`_inputs` (shapes, counts), :func:`_uniform_from_times` (gaps, jitter; only
    with ``time_s``), :func:`_fill_or_cut_nans`, :func:`_refuse_constant`,
    :func:`_check_memory`, then the clipping and bandwidth warnings.

    Args:
        force_N: ``(N,)`` input force [N].
        position_m: ``(N,)`` output position [m].
        rate_hz: sampling rate [Hz] when the record is uniform; or give ``time_s``.
        time_s: ``(N,)`` sample times [s], strictly increasing (gaps and jitter are handled).
        memory_s: the IRF memory to be identified [s]; checks the record is long enough.
        flags: ``(N,)`` :class:`~skinkit.schemas.RobotRecord` flag bits (saturation is read).
        force_limit_N: the actuator's force limit [N]; samples at it count as clipped.

    Raises:
        SysidError: bad shapes, a constant input or output, too few samples for ``memory_s``.

    Warns:
        GapWarning, NonUniformSamplingWarning, NaNWarning, ClippedForceWarning,
        ClippedPositionWarning, ShortRecordWarning, NarrowbandInputWarning.
    """
    w = _inputs(force_N, position_m, flags, rate_hz, time_s)
    if time_s is not None:
        rate_hz = _uniform_from_times(w, time_s)
    rate = float(rate_hz)  # type: ignore[arg-type]
    if not np.isfinite(rate) or rate <= 0:
        raise SysidError(f"rate_hz must be a positive number, got {rate_hz!r}")
    _fill_or_cut_nans(w, rate)
    _refuse_constant(w)
    _check_memory(w.n, rate, memory_s, w.issues)
    _check_clipping(w.f, "force", ClippedForceWarning, w.issues, force_limit_N, w.flags)
    _check_clipping(w.y, "position", ClippedPositionWarning, w.issues)
    _check_bandwidth(w.f, rate, w.issues)
    return Signals(force_N=w.f, position_m=w.y, rate_hz=rate, t0_s=w.t0, issues=w.issues)


@dataclass
class _Work:
    """The record while :func:`check_signals` works on it: force ``f``, position ``y`` and
    ``flags`` (or None) of ``n`` samples, the first at ``t0`` [s]; warnings so far."""

    f: np.ndarray
    y: np.ndarray
    flags: np.ndarray | None
    t0: float = 0.0
    issues: list[str] = field(default_factory=list)

    @property
    def n(self) -> int:
        return int(self.f.size)

    def keep(self, a: int, b: int) -> None:
        """Keep samples ``[a, b)`` only."""
        self.f, self.y = self.f[a:b], self.y[a:b]
        self.flags = None if self.flags is None else self.flags[a:b]


def _inputs(force_N: Any, position_m: Any, flags: Any, rate_hz: float | None, time_s: Any) -> _Work:
    """Copies of the inputs as float vectors of one length (>= MIN_SAMPLES), the flags as
    uint64; exactly one of ``rate_hz`` and ``time_s`` given."""
    f = _vector(force_N, "force_N")
    y = _vector(position_m, "position_m")
    if f.size != y.size:
        raise SysidError(f"force_N has {f.size} samples but position_m has {y.size}")
    n = f.size
    if n < MIN_SAMPLES:
        raise SysidError(f"record has {n} samples; system identification needs at least {MIN_SAMPLES}")
    if (rate_hz is None) == (time_s is None):
        raise SysidError("give exactly one of rate_hz (uniform sampling) or time_s (sample times)")
    fl = None if flags is None else np.asarray(flags).astype(np.uint64)
    if fl is not None and fl.shape != (n,):
        raise SysidError(f"flags: expected shape ({n},), got {fl.shape}")
    return _Work(f, y, fl)


def _uniform_from_times(w: _Work, time_s: Any) -> float:
    """Cut ``w`` to its longest segment between gaps of ``time_s`` and resample it onto a
    uniform grid when the intervals jitter; sets ``w.t0``, returns the rate [Hz]."""
    n = w.n
    t = _vector(time_s, "time_s")
    if t.size != n:
        raise SysidError(f"time_s has {t.size} samples but force_N has {n}")
    if np.isnan(t).any():
        raise SysidError(f"time_s: NaN at sample {int(np.flatnonzero(np.isnan(t))[0])}")
    dt = np.diff(t)
    if (dt <= 0).any():
        i = int(np.flatnonzero(dt <= 0)[0])
        raise SysidError(f"time_s must increase; sample {i + 1} ({t[i + 1]:.6g} s) does not")
    med = float(np.median(dt))
    gaps = np.flatnonzero(dt > GAP_FACTOR * med) + 1
    if gaps.size:
        a, b = _longest_segment(gaps, n)
        warn(GapWarning, f"{gaps.size} gap(s) in time_s (largest {dt.max():.4g} s, median "
             f"interval {med:.4g} s); using the longest uninterrupted segment "
             f"{t[a]:.6g}-{t[b - 1]:.6g} s ({b - a} of {n} samples)", w.issues)
        t = t[a:b]
        w.keep(a, b)
        if w.n < MIN_SAMPLES:
            raise SysidError(f"longest segment between gaps has {w.n} samples; need {MIN_SAMPLES}")
        dt = np.diff(t)
        med = float(np.median(dt))
    w.t0 = float(t[0])
    jitter = float(np.max(np.abs(dt - med)) / med)
    if jitter > JITTER_RTOL:
        grid = t[0] + med * np.arange(int(np.floor((t[-1] - t[0]) / med)) + 1)
        warn(NonUniformSamplingWarning, f"sample intervals vary by up to {100 * jitter:.2g} % "
             f"of the median {med:.4g} s; resampled linearly onto a uniform {1.0 / med:.6g} Hz "
             "grid", w.issues)
        w.f = _interp_keep_nan(grid, t, w.f)
        w.y = _interp_keep_nan(grid, t, w.y)
        if w.flags is not None:
            w.flags = w.flags[np.clip(np.searchsorted(t, grid), 0, t.size - 1)]
    return 1.0 / med


def _fill_or_cut_nans(w: _Work, rate: float) -> None:
    """Interpolate NaN runs of at most MAX_NAN_FILL samples inside the record; cut longer
    runs (and runs at an end) out, keeping the longest NaN-free segment."""
    n = w.n
    bad = np.isnan(w.f) | np.isnan(w.y)
    if not bad.any():
        return
    runs = _runs(bad)
    short = [(a, b) for a, b in runs if b - a <= MAX_NAN_FILL and a > 0 and b < n]
    long_ = [(a, b) for a, b in runs if (a, b) not in short]
    idx = np.arange(n)
    for a, b in short:
        for arr in (w.f, w.y):  # in place: w holds copies (see _vector), never the caller's
            arr[a:b] = np.interp(idx[a:b], [a - 1, b], [arr[a - 1], arr[b]])
    msg = f"{int(bad.sum())} NaN sample(s) in {len(runs)} run(s) (first at sample " \
          f"{runs[0][0]}); {len(short)} short run(s) interpolated"
    if long_:
        keep = np.ones(n, bool)
        for a, b in long_:
            keep[a:b] = False
        a, b = max(((a, b) for a, b in _runs(keep)), key=lambda r: r[1] - r[0], default=(0, 0))
        msg += f"; longer runs cut out, using samples {a}-{b - 1} ({b - a} of {n})"
        w.keep(a, b)
        w.t0 += a / rate
        if w.n < MIN_SAMPLES:
            raise SysidError(f"longest NaN-free segment has {w.n} samples; need {MIN_SAMPLES}")
    warn(NaNWarning, msg, w.issues)


def _refuse_constant(w: _Work) -> None:
    """A constant (or two-valued) force or position carries no dynamics to identify."""
    for name, arr in (("force_N", w.f), ("position_m", w.y)):
        sd = float(np.std(arr))
        if sd <= 1e-12 * max(1.0, float(np.max(np.abs(arr)))) or np.unique(arr).size < 3:
            raise SysidError(f"{name} is constant (std {sd:.3g}); a stochastic input with an "
                             "output response is needed")


def max_irf_lags() -> int:
    """The most IRF lags identified: ``SKINKIT_MAX_IRF_LAGS`` if set, else :data:`MAX_IRF_LAGS`."""
    raw = os.environ.get("SKINKIT_MAX_IRF_LAGS", "").strip()
    if not raw:
        return MAX_IRF_LAGS
    try:
        value = int(raw)
    except ValueError:
        value = 0
    if value < 1:
        raise SysidError(f"SKINKIT_MAX_IRF_LAGS={raw!r}: must be a whole number of lags >= 1")
    return value


def check_irf_size(lags: int, rate_hz: float, memory_s: float) -> None:
    """Refuse, before allocating, an IRF of ``lags`` lags (``memory_s`` [s] at ``rate_hz``
    [Hz]; both sides counted when two-sided) above :func:`max_irf_lags`, with the memory it
    would take and the longest memory allowed at this rate."""
    limit = max_irf_lags()
    if lags <= limit:
        return
    gb = 32.0 * float(lags) ** 2 / 1e9
    longest = (limit - 1) / rate_hz / (2 if lags > int(round(memory_s * rate_hz)) + 1 else 1)
    raise SysidError(f"an IRF memory of {memory_s:.4g} s at {rate_hz:.6g} Hz is {lags:,} lags: a "
                     f"{lags:,} x {lags:,} correlation matrix, about {gb:.3g} GB and L^3 time to "
                     f"decompose, over the limit of {limit:,} lags; use a memory of at most "
                     f"{longest:.4g} s (skinkit sysid --memory), or raise SKINKIT_MAX_IRF_LAGS")


def _check_memory(n: int, rate: float, memory_s: float | None, issues: list[str]) -> None:
    """Refuse a record shorter than MIN_MEMORIES IRF memories; warn below WARN_MEMORIES.
    (The IRF's size is checked where it is identified, after a record that is not a
    stochastic test has been refused as such: :func:`check_irf_size`.)"""
    if memory_s is None:
        return
    if not np.isfinite(memory_s) or memory_s <= 0:
        raise SysidError(f"memory must be a positive time in seconds, got {memory_s!r}")
    m = int(round(memory_s * rate)) + 1
    if n < MIN_MEMORIES * m:
        raise SysidError(f"record of {n / rate:.4g} s ({n} samples) is too short for an IRF "
                         f"memory of {memory_s:.4g} s: need at least {MIN_MEMORIES} memory "
                         f"lengths ({MIN_MEMORIES * m} samples)")
    if n < WARN_MEMORIES * m:
        warn(ShortRecordWarning, f"record holds only {n / m:.1f} memory lengths of "
             f"{memory_s:.4g} s; the IRF will be noisy (>= {WARN_MEMORIES} recommended)", issues)


def _interp_keep_nan(grid: np.ndarray, t: np.ndarray, v: np.ndarray) -> np.ndarray:
    out = np.interp(grid, t, np.nan_to_num(v))
    if np.isnan(v).any():  # a grid point next to a NaN sample stays NaN
        near = np.isnan(v)[np.clip(np.searchsorted(t, grid), 0, t.size - 1)]
        out[near] = np.nan
    return out


def _check_clipping(x: np.ndarray, what: str, category: type[SysidWarning], issues: list[str],
                    limit: float | None = None, flags: np.ndarray | None = None) -> None:
    hi, lo, tol = _plateau_fraction(x)
    parts = []
    if hi > CLIP_FRACTION:
        parts.append(f"{100 * hi:.2g} % of samples at the maximum {x.max():.6g}")
    if lo > CLIP_FRACTION:
        parts.append(f"{100 * lo:.2g} % at the minimum {x.min():.6g}")
    if limit is not None:
        at = float(np.mean(np.abs(x) >= abs(limit) - tol))
        if at > 0:
            parts.append(f"{100 * at:.2g} % at the force limit {abs(limit):.6g} N")
    if flags is not None:
        from skinkit.schemas.robot import FLAG_SATURATED

        sat = float(np.mean((flags & FLAG_SATURATED) != 0))
        if sat > 0:
            parts.append(f"{100 * sat:.2g} % of samples flagged saturated by the device")
    if parts:
        unit = "N" if what == "force" else "m"
        warn(category, f"{what} looks clipped ({'; '.join(parts)} [{unit}]); the identified "
             "model will underestimate the response there", issues)


def _check_bandwidth(f: np.ndarray, rate: float, issues: list[str]) -> None:
    """Warn when little input power lies above 1 % of the Nyquist frequency."""
    fc = 0.01 * rate / 2
    spec = np.abs(np.fft.rfft(f - f.mean())) ** 2
    freqs = np.fft.rfftfreq(f.size, 1.0 / rate)
    total = float(spec.sum())
    frac = float(spec[freqs > fc].sum() / total) if total > 0 else 0.0
    if frac < 0.5:
        warn(NarrowbandInputWarning, f"only {100 * frac:.3g} % of the force variance lies above "
             f"{fc:.3g} Hz: the input is not a broadband stochastic force (a ramp or hold "
             "test?), so the IRF is poorly determined", issues)


class NotStochasticError(SysidError):
    """The record is not a broadband stochastic force test, so an IRF and K, B, I from it
    would be meaningless (raised by ``skinkit sysid``; the library only warns)."""


class NonPhysicalError(SysidError):
    """An identified stiffness, damping or mass is negative, zero or not finite."""


#: warnings that say the record is not a stochastic force-input test at all
NOT_STOCHASTIC = (NarrowbandInputWarning, NonCausalWarning)

#: what to do instead, for the test these warnings point at
ALTERNATIVE = ("fit a quasi-static or viscoelastic model to it instead, e.g. "
               "`skinkit fit docs/models/extension_relaxation_qlv.toml {record}` for an "
               "extension-relaxation record")


def not_stochastic_reason(warnings_seen: list[str]) -> str | None:
    """Why a record is not a broadband stochastic force test, or ``None`` if nothing says so.

    ``warnings_seen`` are the ``"WarningName: message"`` strings of :class:`Signals` (or of a
    result). A :class:`NarrowbandInputWarning` (the force holds little power above 1 % of
    Nyquist, as in a ramp-and-hold, relaxation or slow cyclic test) or a
    :class:`NonCausalWarning` (position leads force: the force is not the input) means the
    IRF, and so K, B, I, describe nothing of the skin.
    """
    for category in NOT_STOCHASTIC:
        prefix = f"{category.__name__}: "
        for msg in warnings_seen:
            if msg.startswith(prefix):
                text = msg[len(prefix):]
                # the measured fact, without the warning's own advice
                return text.split(":")[0] if category is NarrowbandInputWarning else \
                    text.split(", so")[0]
    return None


def refuse_if_not_stochastic(warnings_seen: list[str], record: str) -> None:
    """Raise :class:`NotStochasticError` (one line: why, and which analysis fits instead)
    when :func:`not_stochastic_reason` finds a reason in ``warnings_seen``."""
    why = not_stochastic_reason(warnings_seen)
    if why is not None:
        raise NotStochasticError(f"{record} is not a broadband stochastic force test ({why}); "
                                 "K, B, I would be meaningless, so none are given: "
                                 + ALTERNATIVE.format(record=record))


def nonphysical(K: float, B: float, I: float) -> dict[str, str]:  # noqa: N803 (thesis symbols)
    """The identified parameters that no passive skin can have, each with the reason.

    Args:
        K: stiffness [N/m]; B: damping [N s/m]; I: mass (inertia) [kg], of the skin after
            any robot removal.

    Returns:
        ``{"K"|"B"|"I": "negative stiffness"...}``, empty when all three are finite and
        positive. (A mass-spring-damper with a zero or negative coefficient is unstable or not
        second order; a negative skin mass usually means more robot mass was removed than the
        fit found in total.)
    """
    out: dict[str, str] = {}
    for key, value, what in (("K", K, "stiffness"), ("B", B, "damping"), ("I", I, "mass")):
        if not np.isfinite(value):
            out[key] = f"{what} is not finite"
        elif value < 0:
            out[key] = f"negative {what}"
        elif value == 0:
            out[key] = f"zero {what}"
    return out
