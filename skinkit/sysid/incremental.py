"""Incremental analysis (thesis 4.2.3): K, B, I per increment against mean position,
Young's modulus ``E = (1 - nu^2) K / (2 Rp)`` (semi-infinite body under a flat circular
probe of radius Rp), and ascending-versus-descending hysteresis."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.sysid.checks import SysidError, check_irf_size, check_signals
from skinkit.sysid.inputs import Segment
from skinkit.sysid.linear import LinearModel, identify_signals
from skinkit.sysid.robot import RobotDynamics

#: Poisson's ratio of skin (thesis 4.3, after Tilleman et al. 2004)
SKIN_POISSON = 0.45


def youngs_modulus(K_N_per_m: float | np.ndarray, probe_radius_m: float,
                   poisson: float = SKIN_POISSON) -> float | np.ndarray:
    """``E = (1 - nu^2) K / (2 Rp)`` [Pa] from stiffness [N/m] and probe radius [m]."""
    if probe_radius_m <= 0:
        raise SysidError(f"probe radius must be positive, got {probe_radius_m!r} m")
    if not -1 < poisson <= 0.5:
        raise SysidError(f"Poisson's ratio must lie in (-1, 0.5], got {poisson!r}")
    return (1 - poisson**2) * np.asarray(K_N_per_m) / (2 * probe_radius_m)


def detect_segments(force_N: Any, rate_hz: float, *, min_s: float = 1.0, cutoff_hz: float = 20.0,
                    window_s: float = 0.1, level: float = 0.3,
                    trim_s: float = 0.25) -> list[Segment]:
    """Find the stochastic segments of an incremental record without its programme.

    Stochastic steps carry force above ``cutoff_hz``; holds (protocol B) and triangles
    (protocol A) do not. Runs where the windowed RMS of the high-passed force exceeds
    ``level`` times its 90th percentile, shortened by ``trim_s`` at each end (the jumps
    between a hold or triangle and a step ring through the high-pass filter) and lasting
    at least ``min_s``, become ``"identify"`` segments; ``direction`` is ``"up"`` when a
    segment's mean force exceeds the previous one's, ``"down"`` when it is lower, and a
    level repeated at the turn of the staircase starts the other leg (the first is
    ``"up"``).
    """
    from scipy import signal

    f = np.asarray(force_N, float)
    if f.ndim != 1 or f.size < 10:
        raise SysidError(f"force_N must be a (N,) array with N >= 10, got shape {f.shape}")
    if not 0 < cutoff_hz < rate_hz / 2:
        raise SysidError(f"cutoff {cutoff_hz!r} Hz must lie between 0 and {rate_hz / 2} Hz")
    hp = signal.sosfiltfilt(signal.butter(4, cutoff_hz, "highpass", fs=rate_hz, output="sos"), f)
    w = max(int(round(window_s * rate_hz)), 1)
    rms = np.sqrt(np.convolve(hp * hp, np.ones(w) / w, mode="same"))
    active = rms > level * np.quantile(rms, 0.9)
    d = np.diff(np.concatenate([[0], active.astype(np.int8), [0]]))
    runs = [(int(a), int(b)) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1),
                                             strict=True)]
    h = w // 2 + 1 + int(round(trim_s * rate_hz))
    runs = [(a + h, b - h) for a, b in runs if (b - a - 2 * h) >= min_s * rate_hz]
    means = [float(np.mean(f[a:b])) for a, b in runs]
    steps = np.abs(np.diff(means))
    tol = 0.25 * float(np.median(steps)) if steps.size else 0.0
    segs: list[Segment] = []
    direction = "up"
    for k, ((a, b), m) in enumerate(zip(runs, means, strict=True)):
        if k > 0:
            if m > means[k - 1] + tol:
                direction = "up"
            elif m < means[k - 1] - tol:
                direction = "down"
            else:  # a level repeated at the turn of the staircase starts the other leg
                direction = "down" if direction == "up" else "up"
        segs.append(Segment(a, b, "identify", m, direction, k))
    return segs


@dataclass
class Increment:
    """One increment: its segment, the identified model (or the reason it failed)."""

    segment: Segment
    model: LinearModel | None
    error: str = ""
    issues: list[str] = field(default_factory=list)


@dataclass
class IncrementalResult:
    """Per-increment linear models of an incremental protocol."""

    increments: list[Increment]
    probe_radius_m: float | None = None
    poisson: float = SKIN_POISSON

    def table(self) -> list[dict[str, Any]]:
        """One row per increment (tidy): index, direction, mean force [N], mean position [m],
        K, B, I, VAF, E [Pa] (when the probe radius is known), error, warnings."""
        rows = []
        for inc in self.increments:
            s, m = inc.segment, inc.model
            row: dict[str, Any] = {"index": s.index, "direction": s.direction,
                                   "mean_force_N": s.mean_N, "start": s.start, "stop": s.stop}
            if m is not None:
                row.update({"position_mean_m": m.position_mean_m, "K_N_per_m": m.skin.K,
                            "B_Ns_per_m": m.skin.B, "I_kg": m.skin.I,
                            "vaf_linear_pct": m.vaf_linear_pct, "valid": m.valid})
                if self.probe_radius_m is not None:
                    row["E_Pa"] = float(youngs_modulus(m.skin.K, self.probe_radius_m,
                                                       self.poisson))
            else:
                row.update({k: float("nan") for k in ("position_mean_m", "K_N_per_m",
                                                      "B_Ns_per_m", "I_kg", "vaf_linear_pct")})
                row["valid"] = False
            row["error"] = inc.error
            row["warnings"] = list(inc.issues)
            rows.append(row)
        return rows

    def hysteresis(self) -> list[dict[str, Any]]:
        """Ascending vs descending at each mean force level reached both ways (the nearest
        ascending level within half the level spacing): position offset (down minus up)
        [m] and stiffness ratio (down / up)."""
        ups = [i for i in self.increments if i.segment.direction == "up" and i.model is not None]
        if not ups:
            return []
        levels = np.array([i.segment.mean_N for i in ups])
        spacing = np.diff(np.sort(levels))
        tol = 0.5 * float(spacing.min()) if spacing.size else np.inf
        out = []
        for inc in self.increments:
            if inc.segment.direction != "down" or inc.model is None:
                continue
            k = int(np.argmin(np.abs(levels - inc.segment.mean_N)))
            if abs(levels[k] - inc.segment.mean_N) > tol:
                continue
            up = ups[k]
            assert up.model is not None
            out.append({"mean_force_N": inc.segment.mean_N,
                        "position_offset_m": inc.model.position_mean_m - up.model.position_mean_m,
                        "K_ratio": inc.model.skin.K / up.model.skin.K})
        return out


#: stochastic segments whose mean forces all lie within this fraction of their force's
#: standard deviation are one level, not increments: the segment means of a plain stochastic
#: test differ by ~std / sqrt(effective samples), those of an incremental protocol by about
#: full scale / steps, several standard deviations (thesis 4.1.3: 20 % of full scale stochastic)
STEP_LEVEL = 0.25


def _require_steps(segments: Sequence[Segment], f: np.ndarray) -> None:
    """Refuse a record in which the detected stochastic segments do not step the mean force:
    fewer than two segments, or all at one level (a plain stochastic test)."""
    if len(segments) < 2:
        raise SysidError(f"not an incremental protocol: {len(segments)} stochastic segment(s) found "
                         "(an incremental record steps the mean force over several); identify it "
                         "as one stochastic record (skinkit sysid without --incremental)")
    means = np.array([s.mean_N for s in segments])
    sd = float(np.median([np.std(f[s.start:s.stop]) for s in segments]))
    if float(np.ptp(means)) <= STEP_LEVEL * sd:
        raise SysidError(f"not an incremental protocol: the {len(segments)} stochastic segments "
                         f"all have a mean force of {means.mean():.4g} N (spread {np.ptp(means):.3g} N, "
                         f"force std {sd:.3g} N); identify it as one stochastic record "
                         "(skinkit sysid without --incremental)")


def identify_incremental(force_N: Any, position_m: Any = None, rate_hz: float | None = None,
                         segments: Sequence[Segment | tuple[int, int]] | None = None, *,
                         axis: int | str = 2,
                         memory_s: float | None = None, robot: RobotDynamics | None = None,
                         probe_radius_m: float | None = None, poisson: float = SKIN_POISSON,
                         hold: str = "foh", refine: bool = True,
                         progress: bool | Callable[[int, int], None] = False) -> IncrementalResult:
    """Identify a linear model in every ``"identify"`` segment of an incremental record.

    ``segments`` come from :func:`skinkit.sysid.inputs.incremental` (``Programme.segments``)
    or are ``(start, stop)`` sample ranges; without them they are found by
    :func:`detect_segments`. ``force_N`` may be a uniformly sampled
    :class:`~skinkit.schemas.RobotRecord` (tip channels along ``axis``). An increment that
    cannot be identified keeps its error message instead of stopping the others.
    ``refine`` (default on) finishes each fit by output error: increments are short and
    start mid-response, which biases the correlation IRF (and so the damped-sinusoid
    K, B, I) by a few per cent, while the output-error fit leaves out the start-up.
    ``progress`` shows a progress bar (True) or is told ``(increments done, increments)``.
    """
    from skinkit.schemas import RobotRecord
    from skinkit.sysid.record import axis_index

    if isinstance(force_N, RobotRecord):
        rec = force_N
        if position_m is not None or rate_hz is not None:
            raise SysidError("with a RobotRecord, do not also give position or rate")
        if rec.tip_force is None or rec.tip_position is None:
            raise SysidError(f"record {rec.protocol.name!r} needs tip_force and tip_position")
        if not rec.is_uniform():
            raise SysidError(f"record {rec.protocol.name!r} is not uniformly sampled; resample "
                             "it or pass arrays with segments")
        a = axis_index(axis)
        force_N, position_m, rate_hz = rec.tip_force[:, a], rec.tip_position[:, a], rec.rate_hz
    if rate_hz is None or position_m is None:
        raise SysidError("identify_incremental needs position_m and rate_hz with force arrays")
    f = np.asarray(force_N, float)
    y = np.asarray(position_m, float)
    if segments is None:
        segments = detect_segments(f, rate_hz)
        _require_steps(segments, f)
    if f.shape != y.shape or f.ndim != 1:
        raise SysidError(f"force_N {f.shape} and position_m {y.shape} must be equal (N,) arrays")
    segs = [s if isinstance(s, Segment) else Segment(int(s[0]), int(s[1]), "identify",
                                                     float(np.mean(f[s[0]:s[1]])), "", k)
            for k, s in enumerate(segments)]
    segs = [s for s in segs if s.kind == "identify"]
    if not segs:
        raise SysidError("no segments of kind 'identify' to analyse")
    if memory_s is not None and np.isfinite(memory_s) and memory_s > 0:
        # refused once for the record, not once per increment
        check_irf_size(int(round(memory_s * rate_hz)) + 1, float(rate_hz), memory_s)
    out = []
    it: Iterable[Segment] = segs
    if progress is True:
        from rich.progress import track

        it = track(segs, description="identifying increments")
    for k, s in enumerate(it):
        if callable(progress):
            progress(k, len(segs))
        if not 0 <= s.start < s.stop <= f.size:
            raise SysidError(f"segment {s.start}:{s.stop} lies outside the record of {f.size}")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                sig = check_signals(f[s.start:s.stop], y[s.start:s.stop], rate_hz=rate_hz,
                                    memory_s=memory_s)
                m = identify_signals(sig, memory_s, hold=hold, robot=robot, refine=refine)
                out.append(Increment(s, m, issues=list(m.issues)))
            except SysidError as exc:
                out.append(Increment(s, None, str(exc),
                                     [f"{w.category.__name__}: {w.message}" for w in caught]))
    return IncrementalResult(out, probe_radius_m, poisson)
