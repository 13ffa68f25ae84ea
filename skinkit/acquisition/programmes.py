"""Programmes: what a protocol asks the robot to do, sample by sample.

A :class:`Programme` is robot-agnostic: a trajectory of the probe tip relative to the
contact (zero) position, or a force programme per motor. Drivers turn it into their
device's setpoints (inverse kinematics, units, limits).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skinkit.errors import SchemaError


@dataclass(frozen=True)
class Programme:
    """Setpoints at a fixed rate.

    Attributes:
        kind: ``"trajectory"`` (tip positions, position control) or ``"force"``
            (motor forces, open loop).
        rate_hz: setpoint rate [Hz]; the device interpolates linearly between setpoints.
        setpoints: ``(N, 3)`` tip displacement from the zero position [m] (robot frame:
            x, y in the skin plane, z into the skin) for a trajectory; motor forces [N]
            (motors 1, 2, 3) for a force programme.
        camera_rate_hz: camera trigger rate [Hz] (0: no triggers).
    """

    kind: str
    rate_hz: float
    setpoints: np.ndarray
    camera_rate_hz: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in ("trajectory", "force"):
            raise SchemaError("Programme.kind", f"must be 'trajectory' or 'force', got {self.kind!r}")
        sp = np.asarray(self.setpoints, dtype=float)
        if sp.ndim != 2 or sp.shape[1] != 3 or sp.shape[0] < 2:
            raise SchemaError("Programme.setpoints", f"expected shape (N>=2, 3), got {sp.shape}")
        if not np.all(np.isfinite(sp)):
            raise SchemaError("Programme.setpoints", "contains NaN or infinite values")
        if not self.rate_hz > 0:
            raise SchemaError("Programme.rate_hz", f"must be > 0, got {self.rate_hz}")
        object.__setattr__(self, "setpoints", sp)

    @property
    def n(self) -> int:
        """Number of setpoints."""
        return int(self.setpoints.shape[0])

    @property
    def duration_s(self) -> float:
        """Time from the first to the last setpoint [s]."""
        return (self.n - 1) / self.rate_hz

    @property
    def time_s(self) -> np.ndarray:
        """``(N,)`` setpoint times [s]."""
        return np.arange(self.n) / self.rate_hz


def direction(theta_deg: float, phi_deg: float) -> np.ndarray:
    """Unit vector of thesis Table 12: ``theta`` in the skin plane from x, ``phi`` from the
    skin plane towards the normal (z, into the skin). Normal indentation is phi = 90."""
    th, ph = np.deg2rad(theta_deg), np.deg2rad(phi_deg)
    return np.array([np.cos(ph) * np.cos(th), np.cos(ph) * np.sin(th), np.sin(ph)])


def one_sided_sine(t: np.ndarray, peak_to_peak: float, frequency_hz: float) -> np.ndarray:
    """``pp/2 (1 - cos 2 pi f t)``: starts and ends at zero, peaks at ``pp`` (thesis 7.2.1)."""
    return 0.5 * peak_to_peak * (1.0 - np.cos(2 * np.pi * frequency_hz * t))


def stochastic(n: int, rate_hz: float, cutoff_hz: float, seed: int) -> np.ndarray:
    """``(n,)`` Gaussian white noise low-passed at ``cutoff_hz`` (4th-order Butterworth,
    zero phase), normalised to zero mean and unit standard deviation, clipped at +-3."""
    from scipy.signal import butter, sosfiltfilt

    rng = np.random.default_rng(seed)
    x = rng.standard_normal(n + 2000)
    sos = butter(4, min(cutoff_hz, 0.45 * rate_hz), fs=rate_hz, output="sos")
    y = sosfiltfilt(sos, x)[1000:-1000]
    y = (y - y.mean()) / y.std()
    return np.clip(y, -3.0, 3.0)
