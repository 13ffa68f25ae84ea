"""The virtual lab's instruments: the robot's tip sensors, the 3D tracker and the profiler.

Every number has a source (see ``docs/guide/virtual-lab.md``); ``scale`` (``--noise-scale``) multiplies
every imperfection at once — noise, quantisation step and offset — so every declared level
scales with it.

Robot (``hardware/skinkit_hardware``, ``params.py`` and ``device.py``), logged at
:data:`LOG_RATE_HZ`:

* **tip position**: each arm's potentiometer reads its position with Gaussian noise
  (:data:`POT_SIGMA_M`, 10 µm peak to peak / 6, thesis 3.3.2) through a 16-bit ADC over
  12 mm (:data:`ADC_LSB_M`); the tip position is the arms' readings mapped through the
  kinematics' Jacobian at the home pose (:data:`JACOBIAN_HOME`, linear about home). The
  declared standard deviation per tip axis is ``sqrt(sum_j J_ij² (σ_q² + lsb²/12))``.
* **tip force**: the Nano17 force/torque sensor at the tip, Gaussian noise
  :data:`FT_NOISE_N` then quantised to its resolution :data:`FT_RESOLUTION_N` (thesis
  Table 5); declared ``sqrt(σ² + res²/12)`` (the noise is 0.6 of a step, enough to make the
  quantisation error uniform and independent of the signal: variance within 0.3 %).
* **offset**: each channel is zeroed (tared) on the mean of :data:`TARE_SAMPLES` samples
  at rest before the protocol, so its constant offset is drawn from N(0, σ²/N) per
  component, σ the channel's declared noise.

Tracker: independent Gaussian noise per axis and frame, :data:`TRACK_SIGMA_M` = the 7.0 µm
RMS 3D error of the rendered calibrate → profile → track chain
split evenly over three axes. Profiler: Gaussian noise on the height, :data:`PROFILE_SIGMA_M`
= the 6.5 µm RMS of the same chain's automatic profile against the truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

#: robot logging rate [Hz]: the device's 10 kHz control loop streamed with decimation 10
LOG_RATE_HZ = 1000.0
#: potentiometer noise, one standard deviation [m]: 10 µm peak to peak / 6 (thesis 3.3.2)
POT_SIGMA_M = 10e-6 / 6.0
#: position ADC step [m]: 16 bits over the 12 mm span -1..11 mm (params.py, thesis 3.3.2)
ADC_LSB_M = 12e-3 / ((1 << 16) - 1)
#: arm position at the home pose [m] (mid-stroke) and the ADC span's lower end [m]
HOME_Q_M = 5e-3
ADC_LO_M = -1e-3
#: d(tip)/d(arm positions) at home, robot frame (rows x, y, z): arms at 90, 210, 330 deg on
#: a 25 mm radius, tip 30 mm above the platform; raising arm i swings the tip h/(1.5 r) = 0.8
#: times as far away from it and lifts it by a third (skinkit_hardware.kinematics.jacobian)
JACOBIAN_HOME = np.array([[0.0, 0.8 * math.sqrt(3) / 2, -0.8 * math.sqrt(3) / 2],
                          [-0.8, 0.4, 0.4],
                          [1 / 3, 1 / 3, 1 / 3]])
#: Nano17 force resolution [N] (thesis Table 5) and single-sample noise [N] (assumed: 0.6 of
#: a step, the least at which the quantisation error is uniform and independent of the signal:
#: the variance is then sigma^2 + res^2/12 within 0.3 % wherever the signal falls on the grid,
#: against 2.4 % at half a step; the device model in hardware/ quantises without noise)
FT_RESOLUTION_N = 5.8e-3
FT_NOISE_N = 0.6 * FT_RESOLUTION_N
#: samples averaged by the tare (zero) of each channel before a protocol: 0.1 s at 1 kHz
TARE_SAMPLES = 100
#: 3D tracks against the truth, RMS of the error vector [m]
TRACK_RMS_3D_M = 7.0e-6
TRACK_SIGMA_M = TRACK_RMS_3D_M / math.sqrt(3.0)
#: automatic profile against the truth, RMS of the height error [m] (same note: 6.5 um)
PROFILE_SIGMA_M = 6.5e-6


@dataclass(frozen=True)
class SensorModel:
    """The instruments of a virtual session, every imperfection multiplied by ``scale``.

    Attributes:
        scale: the ``--noise-scale`` factor (> 0).
    """

    scale: float = 1.0
    #: dimensions of the tracked points as the session file stores them (3: x, y, z tracked)
    track_dimensions: ClassVar[int] = 3

    def __post_init__(self) -> None:
        if not (isinstance(self.scale, (int, float)) and math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"the noise scale must be a positive finite number, got {self.scale!r}")

    # -- declared levels -------------------------------------------------------------------
    def position_sigma(self) -> np.ndarray:
        """``(3,)`` standard deviation of one tip-position sample per robot axis [m]."""
        var_q = POT_SIGMA_M**2 + ADC_LSB_M**2 / 12.0
        return self.scale * np.sqrt((JACOBIAN_HOME**2).sum(axis=1) * var_q)

    def force_sigma(self) -> np.ndarray:
        """``(3,)`` standard deviation of one tip-force sample per axis [N]."""
        return self.scale * np.full(3, math.sqrt(FT_NOISE_N**2 + FT_RESOLUTION_N**2 / 12.0))

    def sigma(self, channel: str) -> np.ndarray:
        """``(3,)`` declared noise of ``"tip_position"`` [m], ``"tip_force"`` [N], ``"points"`` [m]."""
        if channel == "tip_position":
            return self.position_sigma()
        if channel == "tip_force":
            return self.force_sigma()
        if channel == "points":
            return np.full(3, self.scale * TRACK_SIGMA_M)
        raise KeyError(channel)

    def track_noise_m(self) -> list[float]:
        """The track's ``noise_m`` attribute [m] per axis (x, y, z), as the session file holds it."""
        return [float(v) for v in self.sigma("points")]

    @property
    def profile_sigma(self) -> float:
        """Standard deviation of a profile point's height [m]."""
        return self.scale * PROFILE_SIGMA_M

    # -- measurement -----------------------------------------------------------------------
    def offset(self, channel: str, rng: np.random.Generator) -> np.ndarray:
        """``(3,)`` constant offset of a tip channel (the tare's error), robot frame."""
        return self.sigma(channel) / math.sqrt(TARE_SAMPLES) * rng.standard_normal(3)

    def measure_position(self, x: np.ndarray, offset: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Recorded tip position ``(T, 3)`` [m] of the true one ``x`` ``(T, 3)`` (robot frame)."""
        Jinv = np.linalg.inv(JACOBIAN_HOME)
        q = HOME_Q_M + np.asarray(x, dtype=float) @ Jinv.T
        lsb = self.scale * ADC_LSB_M
        raw = np.round((q + self.scale * POT_SIGMA_M * rng.standard_normal(q.shape) - ADC_LO_M) / lsb)
        q_meas = ADC_LO_M + raw * lsb
        # the zero (tare) is modelled by ``offset`` alone: no bias from the home reading's rounding
        return (q_meas - HOME_Q_M) @ JACOBIAN_HOME.T + offset

    def measure_force(self, f: np.ndarray, offset: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Recorded tip force ``(T, 3)`` [N] of the true one ``f`` ``(T, 3)`` (robot frame)."""
        res = self.scale * FT_RESOLUTION_N
        f = np.asarray(f, dtype=float)
        return np.round((f + self.scale * FT_NOISE_N * rng.standard_normal(f.shape)) / res) * res + offset

    def measure_points(self, p: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Tracked positions ``(P, F, 3)`` [m] of the true ones ``p`` ``(P, F, 3)`` (skin frame)."""
        p = np.asarray(p, dtype=float)
        return p + self.scale * TRACK_SIGMA_M * rng.standard_normal(p.shape)

    def measure_profile(self, p: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Profiled points ``(N, 3)`` [m] of true surface points ``p`` (noise on the height)."""
        out = np.array(p, dtype=float)
        out[:, 2] += self.profile_sigma * rng.standard_normal(len(out))
        return out

    def to_dict(self) -> dict[str, Any]:
        """The model's numbers (SI), JSON-ready, for the truth file."""
        return {
            "noise_scale": self.scale,
            "log_rate_hz": LOG_RATE_HZ,
            "tip_position": {"pot_sigma_m": self.scale * POT_SIGMA_M, "adc_lsb_m": self.scale * ADC_LSB_M,
                             "jacobian_home": JACOBIAN_HOME.tolist(),
                             "sigma_m": self.position_sigma().tolist()},
            "tip_force": {"noise_n": self.scale * FT_NOISE_N, "resolution_n": self.scale * FT_RESOLUTION_N,
                          "sigma_n": self.force_sigma().tolist()},
            "tare_samples": TARE_SAMPLES,
            "points": {"sigma_m": self.scale * TRACK_SIGMA_M, "rms_3d_m": self.scale * TRACK_RMS_3D_M},
            "profile": {"sigma_m": self.profile_sigma},
        }


__all__ = ["ADC_LSB_M", "FT_NOISE_N", "FT_RESOLUTION_N", "JACOBIAN_HOME", "LOG_RATE_HZ", "POT_SIGMA_M",
           "PROFILE_SIGMA_M", "SensorModel", "TARE_SAMPLES", "TRACK_RMS_3D_M", "TRACK_SIGMA_M"]
