"""The drive of a protocol, as the gap's location reads it: its level, rate, phase (loading,
unloading, hold), cycle and input band, from the channel that drives the protocol."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skinkit.schemas import Channel, ProtocolObservations


@dataclass
class Drive:
    """A protocol's drive reduced to one signal: the displacement (or force) of the drive
    channel from its first sample along its main direction (the principal axis of its excursion),
    signed so that its largest excursion is positive.

    ``level`` ``(T,)`` [channel unit], ``rate`` ``(T,)`` its smoothed derivative [unit/s], ``phase``
    ``(T,)`` index into :data:`PHASES`, ``cycle`` ``(T,)`` 0, 1, ...; ``band`` [Hz].
    """

    channel: str
    time_s: np.ndarray
    level: np.ndarray
    rate: np.ndarray
    phase: np.ndarray
    cycle: np.ndarray
    band: tuple[float, float]

    def index(self, t: np.ndarray) -> np.ndarray:
        """Nearest drive sample of each time ``t`` [s]."""
        i = np.interp(t, self.time_s, np.arange(self.time_s.size, dtype=float))
        return np.rint(i).astype(int)


def _drive_channel(po: ProtocolObservations, predicted: set[str], declared: str | None) -> str | None:
    """The channel that drove the model: the prediction's declared input, else the observed tip
    channel the model does not predict, else any observed tip channel."""
    if declared and declared in po.channels and not po.channels[declared].is_points:
        return declared
    tips = [c for c in ("tip_force", "tip_position") if c in po.channels]
    for c in tips:
        if c not in predicted:
            return c
    return tips[0] if tips else None


def make_drive(ch: Channel, rel_threshold: float = 0.25) -> Drive | None:
    """The :class:`Drive` of a tip channel ``ch``; None when it does not move.

    Band: the frequencies between 2.5 % and 97.5 % of the cumulative power of the demeaned
    level. Loading / unloading: the magnitude of the level, smoothed by a moving average over
    1/20 of the band's upper period (5 samples at least), grows / shrinks faster than both
    ``rel_threshold`` of its 99th-percentile rate and five standard deviations of the rate's
    noise (from the level's second differences); hold otherwise. Cycles: upward crossings of the
    smoothed level's mid-range (hysteresis 10 % of the range); each cycle after the first starts
    where the level leaves the trough before its crossing; a monotonic record is one cycle.
    """
    from scipy.ndimage import uniform_filter1d

    # components never recorded (a one-axis record's y and z) do not void every sample
    used = np.any(ch.valid, axis=0)
    if not used.any():
        return None
    ok = np.all(ch.valid[:, used], axis=1)
    if ok.sum() < 16:
        return None
    t = ch.time_s[ok]
    v = ch.values[ok][:, used]
    d = v - v[0]
    lam, vec = np.linalg.eigh(d.T @ d)
    s = d @ vec[:, -1]
    if s[np.argmax(np.abs(s))] < 0:
        s = -s
    rng = float(np.ptp(s))
    dts = np.diff(t)
    dt = float(np.median(dts[dts > 0])) if np.any(dts > 0) else 0.0
    if not (rng > 0 and dt > 0):
        return None
    T = s.size
    # the band holding 95 % of the drive's power
    P = np.abs(np.fft.rfft(s - s.mean())) ** 2
    f = np.fft.rfftfreq(T, dt)
    cum = np.cumsum(P[1:])
    cum = cum / cum[-1]
    hi = min(int(np.searchsorted(cum, 0.975)), cum.size - 1)
    band = (float(f[1 + np.searchsorted(cum, 0.025)]), float(f[1 + hi]))
    w = int(np.clip(round(0.05 / (band[1] * dt)), 5, max(5, T // 20)))
    S = uniform_filter1d(s, w, mode="nearest")
    tt = t if np.all(dts > 0) else t[0] + dt * np.arange(T)
    hw = max(w // 2, 1)
    i = np.arange(T)
    lo_, hi_ = np.maximum(i - hw, 0), np.minimum(i + hw, T - 1)
    span = tt[hi_] - tt[lo_]
    rate = (S[hi_] - S[lo_]) / span
    da = (np.abs(S[hi_]) - np.abs(S[lo_])) / span
    # noise of the rate: S over adjacent windows of w samples differs by σ√(2/w)
    sigma = 1.4826 * float(np.median(np.abs(np.diff(s, 2) - np.median(np.diff(s, 2))))) / np.sqrt(6.0)
    noise_rate = sigma * np.sqrt(2.0 / w) / (2 * hw * dt)
    thr = max(rel_threshold * float(np.percentile(np.abs(da), 99)), 5.0 * noise_rate)
    phase = np.where(da > thr, 0, np.where(da < -thr, 1, 2)).astype(np.int8)
    # cycles: a Schmitt trigger on the smoothed level
    mid, hyst = 0.5 * (S.max() + S.min()), 0.1 * rng
    event = (S > mid + hyst) | (S < mid - hyst)
    last = np.maximum.accumulate(np.where(event, i, -1))
    high = (last >= 0) & (S[np.maximum(last, 0)] > mid)
    ups = np.flatnonzero(high[1:] & ~high[:-1]) + 1
    # a cycle starts where its loading leaves the trough (the last sample within 2 % of the range
    # of the trough's bottom), so a rest at the bottom ends the cycle before
    starts = [int(a + np.flatnonzero(S[a:b] <= S[a:b].min() + 0.02 * rng)[-1])
              for a, b in zip(ups[:-1], ups[1:], strict=True)]
    cycle = np.searchsorted(np.asarray(starts, dtype=int), i, side="right")
    return Drive(ch.name, t, s, rate, phase, cycle, band)


__all__ = ["Drive", "make_drive"]
