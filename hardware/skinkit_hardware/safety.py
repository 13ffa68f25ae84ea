"""Programme checks against the safety limits, run before any motion.

The same checks run on the host (driver) and in the device model (firmware), so a
programme that slips past a host still cannot move the robot.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from skinkit_hardware import faults as F
from skinkit_hardware.params import Limits, RobotParameters


def thermal_rms(force_N: np.ndarray, rate_hz: float, tau_s: float) -> np.ndarray:
    """``(N, 3)`` running RMS force [N] through the first-order coil-heating filter.

    ``force_N`` ``(N, 3)`` sampled at ``rate_hz``; the filter is the one the device runs every
    tick (``th += (F^2 - th) dt / tau``), evaluated exactly for piecewise-constant input.
    """
    a = np.exp(-1.0 / (rate_hz * tau_s))
    th = lfilter([1.0 - a], [1.0, -a], np.asarray(force_N, float) ** 2, axis=0)
    return np.sqrt(th)


def check_programme(mode: str, setpoints: np.ndarray, rate_hz: float, limits: Limits,
                    params: RobotParameters) -> tuple[F.Fault, int] | None:
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
        force = (params.mass_kg * (a + params.gravity_m_s2) + params.damping_Ns_per_m * v
                 + params.stiffness_N_per_m * (sp - params.spring_rest_m))
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
        return (F.Fault(F.CONTINUOUS_FORCE, int(j) + 1, float(rms[i, j]), limits.continuous_force_N,
                        float(t[i])), int(i))
    return None
