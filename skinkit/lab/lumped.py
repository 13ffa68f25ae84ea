"""A lumped (mass-spring-damper) skin driven by a stochastic force: a synthetic robot record.

The truth is the second-order system ``I x'' + B x' + K x = f`` (thesis Eq. 4.2 family),
with the forearm values of thesis Table 7 by default, plus the robot's own moving mass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from skinkit.schemas import Protocol, RobotRecord


@dataclass(frozen=True)
class LumpedSkin:
    """Truth of a lumped skin test: stiffness ``K`` [N/m], damping ``B`` [N s/m], inertia ``I``
    [kg] (skin plus probe), and the output noise as a signal-to-noise ratio [dB]."""

    K: float = 1450.0
    B: float = 4.76
    I: float = 0.0155 + 0.025
    snr_db: float = 30.0


def stochastic_force(duration_s: float, rate_hz: float, cutoff_hz: float, rms_N: float,
                     rng: np.random.Generator) -> np.ndarray:
    """Gaussian white noise low-pass filtered at ``cutoff_hz`` (4th-order Butterworth, zero
    phase), scaled to ``rms_N`` [N]; returns ``(round(duration_s * rate_hz),)`` [N]."""
    n = int(round(duration_s * rate_hz))
    sos = signal.butter(4, cutoff_hz, fs=rate_hz, output="sos")
    f = signal.sosfiltfilt(sos, rng.standard_normal(n))
    return f * (rms_N / np.std(f))


def simulate(truth: LumpedSkin, duration_s: float = 5.0, rate_hz: float = 2000.0,
             cutoff_hz: float = 200.0, rms_N: float = 0.5, seed: int | np.random.Generator = 0,
             ) -> RobotRecord:
    """Simulate the probe position under a stochastic normal force.

    Returns a :class:`RobotRecord` with ``tip_force`` and ``tip_position`` along z (x and y
    zero), position noise added at ``truth.snr_db``.
    """
    rng = np.random.default_rng(seed)
    f = stochastic_force(duration_s, rate_hz, cutoff_hz, rms_N, rng)
    t = np.arange(f.size) / rate_hz
    # Zero-order hold matches how a digital controller applies force between samples.
    a = np.array([[0.0, 1.0], [-truth.K / truth.I, -truth.B / truth.I]])
    b = np.array([[0.0], [1.0 / truth.I]])
    ad, bd, cd, dd, _ = signal.cont2discrete((a, b, np.array([[1.0, 0.0]]), np.zeros((1, 1))),
                                             1.0 / rate_hz, method="zoh")
    x = signal.dlsim((ad, bd, cd, dd, 1.0 / rate_hz), f)[1][:, 0]
    noise_rms = np.std(x) * 10 ** (-truth.snr_db / 20)
    x_meas = x + noise_rms * rng.standard_normal(x.size)
    zeros = np.zeros_like(f)
    protocol = Protocol("stochastic_normal", kind="force",
                        parameters={"rms_force": rms_N, "cutoff": cutoff_hz, "rate": rate_hz,
                                    "duration": duration_s},
                        units={"rms_force": "N", "cutoff": "Hz", "rate": "Hz", "duration": "s"},
                        duration_s=duration_s,
                        description="virtual lab: Gaussian force, low-pass filtered, normal axis")
    return RobotRecord(time_s=t, tip_force=np.column_stack([zeros, zeros, f]),
                       tip_position=np.column_stack([zeros, zeros, x_meas]), protocol=protocol)
