"""Turning a recorded drive (tip force or tip position at the robot's rate) into a solver programme.

A finite-element model is solved at a few steps per second while the robot records at
hundreds or thousands of samples per second. The programme value at a step time is a local
quadratic regression of the recorded samples within half a step on either side
(Savitzky–Golay): it averages the noise down by the number of samples in the window and,
unlike a plain moving average, does not flatten the peaks of a sinusoid (its error is of
third order in the window, below 1e-5 of the amplitude for the thesis's 0.1 Hz protocols at
20 steps per period).
"""

from __future__ import annotations

import numpy as np


def step_times(duration_s: float, max_step_s: float, extra: np.ndarray | None = None) -> np.ndarray:
    """Solver output times ``(n,)`` [s] in (0, duration]: a uniform grid no coarser than
    ``max_step_s``, merged with ``extra`` times (frame times) so those are solved exactly."""
    if not duration_s > 0:
        raise ValueError(f"the protocol's duration must be positive, got {duration_s}")
    n = max(1, int(np.ceil(duration_s / max_step_s - 1e-9)))
    t = np.linspace(duration_s / n, duration_s, n)
    if extra is not None and np.size(extra):
        e = np.asarray(extra, dtype=float)
        e = e[(e > 0) & (e <= duration_s * (1 + 1e-12))]
        t = np.union1d(t, e)
        # merge times closer than a thousandth of a step (a frame on a grid point)
        keep = np.concatenate([[True], np.diff(t) > 1e-3 * max_step_s])
        t = t[keep]
    return t


def smooth_at(t_rec: np.ndarray, x_rec: np.ndarray, t_out: np.ndarray, window_s: float) -> np.ndarray:
    """Local quadratic regression of ``x_rec`` ``(T, k)`` sampled at ``t_rec`` ``(T,)``,
    evaluated at ``t_out`` ``(n,)`` with a window of ``window_s`` [s]; ``(n, k)``.

    Where fewer than 5 samples fall in the window, linear interpolation is used instead.
    Linear in ``x_rec``, so derivatives of the drive go through the same operator.
    """
    t_rec = np.asarray(t_rec, dtype=float)
    x = np.asarray(x_rec, dtype=float)
    squeeze = x.ndim == 1
    if squeeze:
        x = x[:, None]
    out = np.empty((len(t_out), x.shape[1]))
    half = 0.5 * window_s
    lo = np.searchsorted(t_rec, np.asarray(t_out) - half, side="left")
    hi = np.searchsorted(t_rec, np.asarray(t_out) + half, side="right")
    for i, tc in enumerate(t_out):
        a, b = lo[i], hi[i]
        if b - a < 5:
            out[i] = [np.interp(tc, t_rec, x[:, j]) for j in range(x.shape[1])]
            continue
        tt = (t_rec[a:b] - tc) / max(half, 1e-300)
        V = np.stack([np.ones_like(tt), tt, tt * tt], axis=1)
        # the fitted value at the centre: e0ᵀ (VᵀV)⁻¹ Vᵀ x, three unknowns
        w = np.linalg.solve(V.T @ V, np.array([1.0, 0.0, 0.0])) @ V.T
        out[i] = w @ x[a:b]
    return out[:, 0] if squeeze else out


def fill_invalid(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``(T, 3)`` drive with invalid samples interpolated in time and never-measured components 0."""
    v = np.array(values, dtype=float)
    for j in range(v.shape[1]):
        ok = valid[:, j] & np.isfinite(v[:, j])
        if not ok.any():
            v[:, j] = 0.0
        elif not ok.all():
            idx = np.arange(v.shape[0])
            v[~ok, j] = np.interp(idx[~ok], idx[ok], v[ok, j])
    return v


def running_level(drive_steps: np.ndarray, previous_max: float, reference: float) -> np.ndarray:
    """Softening level ``(n,)``: the largest drive magnitude so far (including earlier
    protocols' ``previous_max``) over the session's largest ``reference``."""
    mag = np.linalg.norm(drive_steps, axis=1)
    m = np.maximum.accumulate(np.maximum(mag, previous_max))
    return m / reference if reference > 0 else np.zeros_like(m)


def running_strokes(drive_steps: np.ndarray, previous: float, reference: float) -> np.ndarray:
    """Loading strokes so far ``(n,)`` [1]: ``previous`` (earlier protocols' strokes) plus the
    sum of the increases of the drive magnitude up to each step, from 0 at the protocol's start
    (the solver's programme starts unloaded), over the session's largest magnitude
    ``reference``: one ramp from 0 to it adds 1."""
    mag = np.linalg.norm(drive_steps, axis=1)
    if not reference > 0:
        return np.full(mag.shape, float(previous))
    up = np.maximum(np.diff(mag, prepend=0.0), 0.0)
    return previous + np.cumsum(up) / reference


__all__ = ["fill_invalid", "running_level", "running_strokes", "smooth_at", "step_times"]
