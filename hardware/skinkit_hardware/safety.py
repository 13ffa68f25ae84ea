"""Programme checks against the safety limits, run before any motion.

The same checks run on the host (driver) and in the device model (firmware), so a
programme that slips past a host still cannot move the robot.
"""

from __future__ import annotations

import numpy as np

from skinkit_hardware import faults as F
from skinkit_hardware.params import Limits, RobotParameters


def thermal_rms(force_N: np.ndarray, rate_hz: float, tau_s: float) -> np.ndarray:
    """``(N, 3)`` running RMS force [N] through the first-order coil-heating filter.

    ``force_N`` ``(N, 3)`` sampled at ``rate_hz``; the filter is the one the device runs every
    tick, ``th_k = a th_(k-1) + (1 - a) F_k^2`` with ``a = exp(-1 / (rate tau))``, evaluated in
    closed form per chunk (``th_k = a^(k+1) th_0 + (1-a) a^k sum_j a^-j F_j^2``); chunks keep
    ``a^-j`` below e^50. Plain numpy: the emulator must not pay scipy.signal's import time.
    """
    x = np.asarray(force_N, dtype=float) ** 2
    a = np.exp(-1.0 / (rate_hz * tau_s))
    chunk = max(1, int(50 * rate_hz * tau_s))
    out = np.empty_like(x)
    th0 = np.zeros(x.shape[1:])
    for s in range(0, x.shape[0], chunk):
        xs = x[s: s + chunk]
        k = np.arange(xs.shape[0], dtype=float)[:, None]
        w = a ** -k
        out[s: s + chunk] = a ** (k + 1) * th0 + (1.0 - a) * np.cumsum(xs * w, axis=0) / w
        th0 = out[s + xs.shape[0] - 1]
    return np.sqrt(out)


def check_programme(
    mode: str, setpoints: np.ndarray, rate_hz: float, limits: Limits, params: RobotParameters
) -> tuple[F.Fault, int] | None:
    """First limit a programme would exceed, as ``(fault, setpoint index)``, or None.

    ``mode`` ``"position"``: ``setpoints`` ``(N, 3)`` arm positions [m]; the forces checked are
    those the robot alone needs (mass, damping, spring, gravity): a lower bound, the skin
    only adds to it and is checked every tick during motion.
    ``mode`` ``"force"``: ``setpoints`` ``(N, 3)`` motor forces [N].
    """
    sp = np.asarray(setpoints, dtype=float)
    if sp.ndim != 2 or sp.shape[1] != 3 or sp.shape[0] < 2:
        return F.Fault(F.BAD_COMMAND, value=float(sp.shape[0]) if sp.ndim else float("nan")), 0
    if not np.all(np.isfinite(sp)):
        i = int(np.argmax(~np.all(np.isfinite(sp), axis=1)))
        return F.Fault(F.BAD_COMMAND), i
    t = np.arange(sp.shape[0]) / rate_hz
    if mode == "position":
        lo, hi = limits.travel_m
        bad = (sp < lo) | (sp > hi)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            lim = lo if sp[i, j] < lo else hi
            return F.Fault(F.TRAVEL, int(j) + 1, float(sp[i, j]), lim, float(t[i])), int(i)
        v = np.gradient(sp, 1.0 / rate_hz, axis=0)
        a = np.gradient(v, 1.0 / rate_hz, axis=0)
        force = (
            params.mass_kg * (a + params.gravity_m_s2)
            + params.damping_Ns_per_m * v
            + params.stiffness_N_per_m * (sp - params.spring_rest_m)
        )
    elif mode == "force":
        force = sp
    else:
        return F.Fault(F.BAD_COMMAND), 0
    over = np.abs(force) > limits.peak_force_N
    if over.any():
        i, j = np.argwhere(over)[0]
        return F.Fault(F.PEAK_FORCE, int(j) + 1, float(force[i, j]), limits.peak_force_N, float(t[i])), int(i)
    rms = thermal_rms(force, rate_hz, params.thermal_time_constant_s)
    over = rms > limits.continuous_force_N
    if over.any():
        i, j = np.argwhere(over)[0]
        return (
            F.Fault(F.CONTINUOUS_FORCE, int(j) + 1, float(rms[i, j]), limits.continuous_force_N, float(t[i])),
            int(i),
        )
    return None
