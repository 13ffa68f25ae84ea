"""Splitting a session's records into segments: one protocol per loading cycle.

``split(observations, "cycles")`` turns every protocol into protocols
``<protocol>-cycle-1``, ``<protocol>-cycle-2``, ... so that a fit can use some cycles and
predict the others (``skinkit fit --segments cycles --holdout NAME-cycle-3,...``).

**The drive.** Cycles are read off the tip position component with the largest range over
its valid samples (the axis the device moved along). A cycle is: leaving rest, loading,
(holding), returning towards rest. With ``r`` the extreme of the drive nearer its first
sample (rest) and ``R`` its full range, the drive's excursion is ``a = |u − r| / R`` in
[0, 1]. A cycle begins where ``a`` rises above 0.6 and ends where it next falls below 0.4:
a hysteresis of 0.2 R, so noise well below a tenth of the range cannot start or end a cycle,
and the median over 5 samples (applied first) removes isolated spikes of up to two samples.
A return needs only to go below 0.4 R: the record of ``docs/guide/real-records.md`` returns to
0.05-1.8 mm of its 9.45 mm between cycles and reloads at once.

**The cuts.** Between two cycles the "rest" is the samples within max(2 % of R, 3 noise
levels) of the lowest excursion between them: a dwell at rest, or just the turning point
when the drive reloads at once. The cut is at the middle sample of that rest, so the first
cycle keeps everything before it, the last everything after it, and every sample of every
channel belongs to exactly one segment (windows are half-open in time, ``[t_k, t_k+1)``).

**Time is re-zeroed** to each segment's first drive sample (the first segment keeps the
protocol's time base): ``Channel.time_s`` counts from
the protocol's start, and the forward models rely on it — a finite-element model solves its
programme on (0, T] (:func:`skinkit.forward.drive.step_times`), and the lumped models start
their relaxation history *relaxed at the first sample* (:func:`skinkit.forward.lumped_elements.qlv`),
so they depend on time differences only. The consequence, which re-zeroing does not cause but
segmenting does: a segment's model does not remember the cycles before it (a QLV model of
cycle 2 starts relaxed at the turning point, where the real skin still carries the
unloading of cycle 1). A ``basis = "time"`` bias entry is a drift from each segment's start.
The segment's start and end in the original record are kept in the protocol's parameters
(``segment_start_s``, ``segment_end_s`` [s], ``segment_of``, ``cycle``).

Every channel is cut to the segment's time window; its noise level (estimated on the whole
record, the more precise) is kept, as is the reference of a point channel. A measured
reference frame stays the reference frame when it lies in the segment; in other segments
the reference is taken as exact (``reference_frame = None``): the correlation its noise
brings to a point's residuals is then not whitened (a track usually lives in one protocol).
A channel with fewer than two samples in a window is left out of that segment, as
:meth:`Observations.until` does.
"""

from __future__ import annotations

import numpy as np

from skinkit.errors import SchemaError
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

#: excursion (fraction of the drive's range) above which a cycle has begun, below which it has ended
_UP, _DOWN = 0.6, 0.4
#: samples of the median filter run before thresholding (removes spikes of up to 2 samples)
_MEDIAN = 5
#: a drive whose range is below this many noise levels does not move
_MIN_RANGE_NOISE = 10.0
#: "at rest" between cycles: within this fraction of the range (or 3 noise levels) of the lowest point
_REST_TOL = 0.02

HOW = ("cycles",)


def _median(x: np.ndarray, width: int) -> np.ndarray:
    """Running median over ``width`` samples (edges: the samples available)."""
    if x.size < width:
        return x.copy()
    from scipy.ndimage import median_filter

    return median_filter(x, size=width, mode="nearest")


def _drive(po: ProtocolObservations) -> tuple[np.ndarray, np.ndarray, float, str]:
    """``(t (n,), u (n,), noise, component letter)``: the valid samples of the tip position
    component with the largest range."""
    where = f"--segments cycles: protocol {po.name!r}"
    ch = po.channels.get("tip_position")
    if ch is None:
        raise SchemaError(where, "has no tip_position channel to find cycles in "
                          f"(it has {sorted(po.channels)})")
    ranges = []
    for j in range(ch.values.shape[1]):
        ok = ch.valid[:, j]
        ranges.append(float(np.ptp(ch.values[ok, j])) if ok.sum() >= 2 else -1.0)
    j = int(np.argmax(ranges))
    ok = ch.valid[:, j]
    if ok.sum() < 2 * _MEDIAN:
        raise SchemaError(where, f"tip_position has {int(ok.sum())} valid samples: too few to find cycles in")
    return ch.time_s[ok], ch.values[ok, j], float(ch.noise[j]), "xyz"[j]


def cycle_cuts(t: np.ndarray, u: np.ndarray, noise: float, where: str = "drive") -> list[float]:
    """Times [s] at which a drive ``u`` ``(n,)`` sampled at ``t`` ``(n,)`` is cut into cycles
    (module docstring): the middle of each rest between two cycles, ``n_cycles − 1`` times.

    ``noise``: the standard deviation of one drive sample [unit of u]. Raises
    :class:`SchemaError` naming ``where`` when the drive does not move, starts loaded, or a
    cycle does not return before the record ends.
    """
    s = _median(np.asarray(u, dtype=float), _MEDIAN)
    lo, hi = float(s.min()), float(s.max())
    R = hi - lo
    if not R > _MIN_RANGE_NOISE * noise or R <= 0:
        raise SchemaError(where, f"the drive does not move (range {R:.3g} against a noise of {noise:.3g}): "
                          "no loading cycle found")
    rest = lo if abs(s[0] - lo) <= abs(s[0] - hi) else hi
    a = np.abs(s - rest) / R
    if a[0] > _DOWN:
        raise SchemaError(where, f"the drive starts loaded ({a[0]:.0%} of its range from rest): "
                          "a cycle must begin by leaving rest")
    # hysteresis: up-crossings of _UP, each followed by a down-crossing of _DOWN
    spans: list[tuple[int, int]] = []
    i, n = 0, a.size
    while i < n:
        up = np.flatnonzero(a[i:] > _UP)
        if not up.size:
            break
        i_up = i + int(up[0])
        down = np.flatnonzero(a[i_up:] < _DOWN)
        if not down.size:
            raise SchemaError(where, f"cycle {len(spans) + 1}, loaded from t = {t[i_up]:.4g} s, does not "
                              f"return towards rest ({rest:.4g}, the extreme nearer the first sample) "
                              f"within {_DOWN:.0%} of the range before the record ends")
        i_down = i_up + int(down[0])
        spans.append((i_up, i_down))
        i = i_down
    # spans is not empty: a reaches 1 at the far extreme, so the first up-crossing exists
    tol = max(_REST_TOL, 3 * noise / R)
    cuts = []
    for (_, d0), (u1, _) in zip(spans[:-1], spans[1:], strict=True):
        gap = a[d0:u1]
        near = np.flatnonzero(gap <= gap.min() + tol)
        cuts.append(float(t[d0 + (int(near[0]) + int(near[-1])) // 2]))
    return cuts


def _cut_channel(c: Channel, t0: float, t1: float, shift: float) -> Channel | None:
    """The samples of ``c`` with ``t0 <= t < t1``, time shifted by ``-shift``; None below 2 samples."""
    a = int(np.searchsorted(c.time_s, t0, side="left"))
    b = int(np.searchsorted(c.time_s, t1, side="left"))
    if b - a < 2:
        return None
    sl = (slice(None), slice(a, b)) if c.is_points else (slice(a, b),)
    rf = c.reference_frame
    rf = rf - a if rf is not None and a <= rf < b else None
    return Channel(c.name, c.time_s[a:b] - shift, c.values[sl], c.valid[sl], c.noise, c.noise_source,
                   c.reference, rf, c.window_m, c.noise_ar, c.noise_innovation,
                   None if c.outliers is None else c.outliers[sl],
                   None if c.noise_scale is None else c.noise_scale[sl])


def _split_cycles(po: ProtocolObservations) -> list[ProtocolObservations]:
    where = f"--segments cycles: protocol {po.name!r}"
    t, u, noise, comp = _drive(po)
    cuts = cycle_cuts(t, u, noise, f"{where} (tip_position {comp})")
    edges = [-np.inf, *cuts, np.inf]
    out = []
    for k in range(1, len(edges)):
        t0, t1 = edges[k - 1], edges[k]
        start = 0.0 if k == 1 else t0     # the first segment keeps the protocol's time base
        chans = {}
        for c in po.channels.values():
            cc = _cut_channel(c, t0, t1, start)
            if cc is not None:
                chans[c.name] = cc
        end = max(po.duration_s, float(t[-1])) if k == len(edges) - 1 else t1
        pr = po.protocol
        params = {**pr.parameters, "segment_of": pr.name, "cycle": k, "segment_start_s": start,
                  "segment_end_s": end}
        units = {**pr.units, "segment_start_s": "s", "segment_end_s": "s"}
        proto = Protocol(f"{pr.name}-cycle-{k}", pr.kind, params, units, end - start,
                         f"loading cycle {k} of {pr.name!r} ({start:.4g} s to {end:.4g} s of it)"
                         + (f"; {pr.description}" if pr.description else ""))
        out.append(ProtocolObservations(proto, chans, po.held_out))
    return out


def split(observations: Observations, how: str) -> Observations:
    """``observations`` with every protocol split into segments ``how`` (module docstring).

    ``how``: ``"cycles"`` — one protocol per loading cycle, ``<protocol>-cycle-<k>`` (k from
    1), in session order; each keeps its parent's held-out mark. Raises :class:`SchemaError`
    for an unknown ``how`` or a record in which the cycles cannot be found.
    """
    if how not in HOW:
        raise SchemaError("--segments", f"unknown segmentation {how!r}; known: {', '.join(HOW)}")
    protocols: dict[str, ProtocolObservations] = {}
    for po in observations:
        for seg in _split_cycles(po):
            if seg.name in protocols or seg.name in observations.protocols:
                raise SchemaError("--segments cycles", f"segment name {seg.name!r} is already a protocol "
                                  "of the session")
            protocols[seg.name] = seg
    return Observations(protocols, observations.profile, observations.source)


__all__ = ["HOW", "cycle_cuts", "split"]
