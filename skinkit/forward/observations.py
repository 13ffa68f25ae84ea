"""Reading what a session measured into :class:`~skinkit.schemas.Observations`.

Sources: an experiment file (``.h5``: every robot record, the track named after each
protocol, the undeformed profile) or a CSV robot record (``.csv``, one protocol).

Frames: robot records are stored in the robot frame (z into the skin); observations are in
the skin frame (z out of the skin), so the z components of ``tip_position`` and ``tip_force``
change sign here, and nowhere else.

Noise, per channel and component (:func:`sample_noise`), in this order of preference:

1. **second differences** over the whole record — RMS(Δ²x)/√6, spikes beyond five robust
   standard deviations trimmed: for white noise Var(Δ²x) = 6σ², and a signal smooth at the
   sampling rate adds almost nothing; with every sample used it is precise (0.6 % at 30,000
   samples), also on quantised signals, where a median-based estimate is biased;
2. checked against the **rest segment** — the samples before the signal first leaves its
   starting level, detrended by a quadratic (unbiased, but short: its standard deviation is
   uncertain by 1/√(2n)). When the differences exceed it by more than three of those
   uncertainties, a broadband input has leaked into them and the rest segment's value is
   used (a "rest" segment larger than the differences holds a slow signal, and is not);
3. a floor at the **sensor resolution** (the smallest step between distinct values, /√12).

Tracks: the track's ``noise_m`` attribute when its producer knows its uncertainty
("tracker"); otherwise **neighbour differences** — each point's displacement against the
mean of its six nearest neighbours', 1.4826 MAD / √(1 + 1/6) per component, over all
frames (smooth fields contribute little; the MAD ignores the high-gradient minority).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.errors import SchemaError, StoreError
from skinkit.schemas import Channel, Observations, ProtocolObservations, RobotRecord, SurfaceTrack

#: robot frame -> skin frame (z flips)
_FLIP = np.array([1.0, 1.0, -1.0])
_MIN_REST = 50
_MAD = 1.4826
#: how a robot record's noise is modelled (:func:`channels_from_record`)
NOISE_MODELS = ("auto", "white", "ar")


#: the noise source of a level estimated from second differences alone (white noise assumed)
SECOND_DIFFERENCES = "second differences"


def _mad(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan")
    return float(_MAD * np.median(np.abs(x - np.median(x))))


def _resolution(x: np.ndarray) -> float:
    u = np.unique(x[np.isfinite(x)])
    if u.size < 2:
        return 0.0
    d = np.diff(u)
    d = d[d > 1e-15 * max(np.abs(u).max(), 1e-300)]
    return float(d.min()) if d.size else 0.0


def sample_noise(x: np.ndarray) -> tuple[float, str]:
    """Standard deviation of one sample of ``x`` ``(T,)`` and how it was estimated (see module)."""
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x)
    if ok.sum() < 8:
        return float("nan"), "too few samples"
    xs = x[ok]
    d2 = np.diff(xs, 2)
    robust = _mad(d2) / np.sqrt(6.0)
    keep = np.abs(d2 - np.median(d2)) <= 5 * np.sqrt(6.0) * max(robust, 1e-300) if robust > 0 else \
        np.ones(d2.size, bool)
    sd2 = float(np.sqrt(np.mean(d2[keep] ** 2) / 6.0)) if keep.any() else float("nan")
    res = _resolution(xs)
    floor = res / np.sqrt(12.0)
    est, src = sd2, SECOND_DIFFERENCES
    if np.isfinite(sd2) and sd2 > 0:
        start = np.median(xs[:min(20, xs.size)])
        away = np.flatnonzero(np.abs(xs - start) > 5 * sd2 + res)
        n_rest = int(away[0]) if away.size else xs.size
        if n_rest >= _MIN_REST:
            t = np.arange(n_rest, dtype=float)
            seg = xs[:n_rest]
            fit = np.polyval(np.polyfit(t, seg, 2), t)
            rest = float(np.std(seg - fit, ddof=3))
            # a broadband signal inflates the differences; a slow one the "rest" segment
            if rest > 0 and sd2 - rest > 3 * rest / np.sqrt(2 * n_rest):
                est, src = rest, f"rest segment ({n_rest} samples; second differences larger)"
            elif rest > 0:
                src = f"{SECOND_DIFFERENCES} (rest segment of {n_rest} samples agrees)"
    if not (np.isfinite(est) and est > floor):
        if floor > 0:
            est, src = floor, "sensor resolution"
        elif not (np.isfinite(est) and est > 0):
            est, src = float("nan"), "constant signal"
    return float(est), src


def _channel_noise(values: np.ndarray, name: str, where: str,
                   components: str | None = None) -> tuple[np.ndarray, str, set[int]]:
    """Per-component noise of a ``(T, k)`` channel, its source, and the components given a nominal
    1: NaN components (they are invalid), and those outside ``components`` (e.g. ``"x"``; None:
    all) whose noise cannot be estimated -- an unmeasured axis stored as zeros, which no model
    reading ``components`` compares with anything. A used component that is constant is refused."""
    out, srcs, nominal = [], set(), set()
    for j in range(values.shape[1]):
        col = values[:, j]
        if not np.isfinite(col).any():
            out.append(1.0)
            nominal.add(j)
            continue
        s, src = sample_noise(col)
        if not (np.isfinite(s) and s > 0):
            if components is not None and "xyz"[j] not in components:
                out.append(1.0)
                nominal.add(j)
                continue
            raise SchemaError(where, f"cannot estimate the noise of {name} component {'xyz'[j]} ({src}); "
                              "give the record more samples or a rest segment")
        out.append(s)
        srcs.add(src.split(" (")[0])
    return np.array(out), ", ".join(sorted(srcs)) or "none", nominal


def channels_from_record(record: RobotRecord, where: str = "record",
                         noise: str = "auto", components: str | None = None) -> dict[str, Channel]:
    """``tip_force`` and ``tip_position`` channels (skin frame) of a robot record.

    ``components``: the tip components a model reads (e.g. ``"x"``; None: all): the noise of
    another component is estimated when it can be, else nominal (an unmeasured axis stored as
    zeros, say); a constant component that is read is refused.

    ``noise``: ``"auto"`` (spikes flagged; an autoregressive model of each component's colour
    from the rest segment where it has one and BIC prefers it: :mod:`skinkit.forward.noise_model`),
    ``"white"`` (the levels of :func:`sample_noise` only, spikes still flagged) or ``"ar"``
    (an AR model required: an error when the rest segment is too short)."""
    if noise not in NOISE_MODELS:
        raise SchemaError("--noise", f"must be one of {list(NOISE_MODELS)}, got {noise!r}")
    raw = {}
    for name in ("tip_force", "tip_position"):
        v = getattr(record, name)
        if v is not None and np.isfinite(v).any():
            raw[name] = np.asarray(v, dtype=float) * _FLIP
    n_rest = _record_rest(raw.get("tip_position"), f"{where}.tip_position", components)
    t = record.time_s - record.time_s[0]
    return {name: _noise_channel(name, t, v, n_rest, noise, f"{where}.{name}", components)
            for name, v in raw.items()}


def _record_rest(position: np.ndarray | None, where: str, components: str | None = None) -> int:
    """Samples before the recorded position first moves (0 without a position channel)."""
    from skinkit.forward.noise_model import rest_length

    if position is None:
        return 0
    lev, _, nominal = _channel_noise(position, "tip_position", where, components)
    res = np.array([_resolution(position[:, j]) for j in range(position.shape[1])])
    # a component with a nominal level (unmeasured, or constant and unread) does not move
    moving = np.where([j in nominal for j in range(position.shape[1])], np.nan, position)
    return rest_length(moving, lev, res)


def _component_ar(seg: np.ndarray, mode: str, axis: str, where: str) -> tuple[np.ndarray, float, float]:
    """``(φ, σ_e, σ)`` of one component's rest segment ``seg`` (φ empty: white)."""
    from skinkit.forward import noise_model as nm

    need = nm.samples_needed(1)
    if seg.size < need:
        if mode == "ar":
            raise SchemaError(where, f"cannot estimate an AR noise model of component {axis}: its rest "
                              f"segment (before the position first moves) has {seg.size} samples, "
                              f"at least {need} are needed (record more rest, or use --noise white)")
        return np.zeros(0), 0.0, 0.0
    if mode == "ar":
        orders = [nm.fit_ar(seg, order=p) for p in range(1, nm.MAX_ORDER + 1)]
        n = seg.size - nm.MAX_ORDER
        return min(orders, key=lambda o: n * np.log(o[1] ** 2) + o[0].size * np.log(n))
    return nm.fit_ar(seg)


def _noise_channel(name: str, t: np.ndarray, v: np.ndarray, n_rest: int, mode: str, where: str,
                   components: str | None = None) -> Channel:
    """A tip channel with its spikes flagged and its noise model (see :func:`channels_from_record`)."""
    from skinkit.forward import noise_model as nm

    outliers = np.zeros(v.shape, bool)
    for j in range(v.shape[1]):
        outliers[nm.spikes(v[:, j]), j] = True
    clean = np.where(outliers, np.nan, v)
    level, src, nominal = _channel_noise(clean, name, where, components)
    ars, innov, srcs = [], level.copy(), set()
    rested = 0
    scale = np.ones(v.shape)
    for j in range(v.shape[1]):
        ars.append(np.zeros(0))
        if mode == "white" or j in nominal:
            continue
        seg = clean[:n_rest, j]
        phi, se, sigma = _component_ar(seg[np.isfinite(seg)], mode, "xyz"[j], where)
        # a rest segment within the sensor's resolution says nothing of its colour
        floor = _resolution(clean[:, j]) / np.sqrt(12.0)
        if phi.size and sigma > floor and 0 < se < sigma:
            ars[j], level[j], innov[j] = phi, sigma, se
            scale[:, j] = nm.local_scale(v[:, j], ~outliers[:, j], n_rest, phi)
            srcs.add(nm.describe(phi.size, int(np.isfinite(seg).sum())))
        elif not phi.size and np.isfinite(seg).sum() >= nm.samples_needed(1):
            rested = int(np.isfinite(seg).sum())
    if srcs:
        white = sum(1 for j, a in enumerate(ars) if not a.size and j not in nominal)
        src = ", ".join(sorted(srcs) + ([src] if white else []))
    elif rested:
        # the colour was looked for and BIC chose white: the level is sound, say so
        src = f"{src}; white by the rest segment ({rested} samples)"
    n_out = int(outliers.sum())
    if n_out:
        src += f"; {n_out} spike(s) left out"
    coloured = bool(srcs)
    return Channel(name, t, v, np.isfinite(v) & ~outliers, level, src,
                   noise_ar=tuple(ars) if coloured else None, noise_innovation=innov if coloured else None,
                   outliers=outliers if n_out else None, noise_scale=scale if coloured else None)


def track_noise(track: SurfaceTrack) -> tuple[np.ndarray, str]:
    """Per-component noise [m] of a track by neighbour differences (module docstring)."""
    from scipy.spatial import cKDTree

    d = track.displacements()
    ref = np.nanmean(np.where(track.valid[..., None], track.points, np.nan), axis=1)
    ok = np.all(np.isfinite(ref), axis=1)
    if ok.sum() < 8:
        return np.full(3, np.nan), "too few points"
    idx = np.flatnonzero(ok)
    k = min(6, idx.size - 1)
    _, nb = cKDTree(ref[idx]).query(ref[idx], k + 1)
    nbmean = np.nanmean(d[idx][nb[:, 1:]], axis=1)
    diff = d[idx] - nbmean
    out = np.array([_mad(diff[..., j].ravel()) for j in range(3)]) / np.sqrt(1 + 1 / k)
    return out, "neighbour differences"


def channel_from_track(track: SurfaceTrack, attrs: dict[str, Any], where: str) -> Channel:
    """A ``points`` channel, or ``points_2d`` when the track's attribute ``dimensions`` is 2."""
    two_d = int(attrs.get("dimensions", 3)) == 2
    k = 2 if two_d else 3
    if "noise_m" in attrs:
        noise = np.broadcast_to(np.asarray(attrs["noise_m"], dtype=float), (3,))[:k]
        src = "tracker"
    else:
        noise, src = track_noise(track)
        noise = noise[:k]
        if two_d:
            noise = np.full(2, float(np.nanmean(noise)))
    if not np.all(np.isfinite(noise) & (noise > 0)):
        raise SchemaError(where, f"cannot estimate the tracking noise ({src})")
    pts = track.points[..., :k]
    valid = np.repeat(track.valid[..., None], k, axis=2)
    scale = None
    if track.uncertainty_m is not None:
        # each position's own standard error over the channel's level: the still-frame floor
        # rises where the views disagree under deformation
        u = track.uncertainty_m[..., :k] / noise
        scale = np.where(valid & np.isfinite(u), np.maximum(u, 1.0), 1.0)
        src = f"{src} (still floor; each position's standard error from the views' disagreement)"
    ref = np.where(track.valid[:, :1, None], track.points[:, :1, :], np.nan)[:, 0, :]
    ref = np.where(np.isfinite(ref), ref, 0.0)
    t = track.time_s
    window = attrs.get("window_m")
    return Channel("points_2d" if two_d else "points", t, np.where(valid, pts, np.nan), valid, noise, src,
                   reference=ref, reference_frame=0, window_m=None if window is None else float(window),
                   noise_scale=scale)


def _read_experiment(path: Path, held_out: Sequence[str], only: Sequence[str] | None = None,
                     noise: str = "auto", components: str | None = None) -> Observations:
    from skinkit.store import open_experiment

    protocols: dict[str, ProtocolObservations] = {}
    with open_experiment(path) as exp:
        tracks = set(exp.track_names())
        names = exp.record_names()
        if only is not None:
            missing = sorted(set(only) - set(names))
            if missing:
                raise SchemaError("protocols", f"no record(s) {missing} in {path} (it has {names})")
            names = [n for n in names if n in set(only)]
        # session order: by the time each record was written (its protocol order), else name
        order = []
        for n in names:
            info = exp.record_info(n)
            order.append((info.get("extra", {}).get("session_index", len(order)), n, info))
        for _, name, info in sorted(order):
            rec = exp.read_record(name)
            chans = channels_from_record(rec, f"{path}:{name}", noise, components)
            if name in tracks:
                tr = exp.read_track(name)
                attrs = exp.track_attrs(name) if hasattr(exp, "track_attrs") else {}
                ch = channel_from_track(tr, attrs, f"{path}:tracks/{name}")
                chans[ch.name] = ch
            ho = bool(info.get("extra", {}).get("held_out", False)) or name in held_out
            protocols[name] = ProtocolObservations(rec.protocol, chans, ho)
        profiles = exp.profile_names()
        profile = None
        if profiles:
            profile = exp.read_profile("undeformed" if "undeformed" in profiles else profiles[0])
    if not protocols:
        raise StoreError(str(path), "records", "the session holds no robot record")
    return Observations(protocols, profile, str(path))


def read_observations(path: str | os.PathLike[str], held_out: Sequence[str] = (), axis: str = "z",
                      segments: str | None = None, protocols: Sequence[str] | None = None,
                      noise: str = "auto", components: str | None = None) -> Observations:
    """The observations of a session file: an experiment file or a CSV record.

    ``held_out``: protocol names to mark held out (in addition to those the file marks).
    ``axis``: the tip axis of one-axis CSV columns (``displacement_mm``, ``force_N``); for a
    model, :func:`skinkit.forward.session.read_session` takes it from the model (as
    :func:`skinkit.fit` and the command line do).
    ``segments``: split every record into protocols first (:func:`skinkit.forward.segments.split`;
    ``"cycles"``: one protocol per loading cycle, named ``<protocol>-cycle-<k>``), so that
    ``held_out`` can name a segment (fit cycles 1-2, predict 3-4). ``noise``: how each robot
    record's noise is modelled (:func:`channels_from_record`); ``components``: the tip components
    a model reads (e.g. ``"x"``; None: all), the only ones whose noise must be estimable.
    Raises :class:`StoreError` / :class:`SchemaError` naming the file and what is wrong.
    """
    p = Path(path)
    if not p.is_file():
        raise StoreError(str(p), "", "no such session file")
    if p.suffix.lower() == ".csv":
        from skinkit.store import read_robot_csv

        rec = read_robot_csv(p, axis=axis)
        if protocols is not None and rec.protocol.name not in protocols:
            raise SchemaError("protocols", f"no record(s) {sorted(set(protocols))} in {p} (it has "
                                           f"{[rec.protocol.name]})")
        obs = Observations({rec.protocol.name: ProtocolObservations(
            rec.protocol, channels_from_record(rec, str(p), noise, components), False)}, None, str(p))
    else:
        obs = _read_experiment(p, (), protocols, noise, components)
    if segments is not None:
        from skinkit.forward.segments import split

        obs = split(obs, segments)
    unknown = sorted(set(held_out) - set(obs.names))
    if unknown:
        raise SchemaError("--holdout", f"no protocol(s) {unknown} in {p} (it has {obs.names})")
    if not held_out:
        return obs
    return obs.with_held_out(sorted(set(held_out) | set(obs.held_out().names)))


__all__ = ["channel_from_track", "channels_from_record", "read_observations", "sample_noise", "track_noise"]
