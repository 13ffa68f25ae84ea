"""Synthetic stochastic-identification records with a known truth (linear or Wiener)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skinkit.schemas import Protocol, RobotRecord
from skinkit.sysid.inputs import gaussian_force
from skinkit.sysid.lti import SecondOrder, simulate


@dataclass
class SimulatedRecord:
    """A simulated record: force ``(N,)`` [N], noisy position ``(N,)`` [m], the noise-free
    position [m] and the noise standard deviation [m]."""

    force_N: np.ndarray
    position_m: np.ndarray
    clean_m: np.ndarray
    noise_std_m: float
    rate_hz: float

    @property
    def time_s(self) -> np.ndarray:
        """Sample times (N,) [s] from 0."""
        return np.arange(self.force_N.size) / self.rate_hz

    def to_robot_record(self, axis: int = 2, name: str = "stochastic") -> RobotRecord:
        """As a :class:`RobotRecord` with the signals on tip ``axis`` (others zero)."""
        f = np.zeros((self.force_N.size, 3))
        p = np.zeros_like(f)
        f[:, axis] = self.force_N
        p[:, axis] = self.position_m
        return RobotRecord(time_s=self.time_s, tip_force=f, tip_position=p,
                           protocol=Protocol(name, kind="force"))


def exponential(x: np.ndarray, C1_m: float, C2_per_N: float) -> np.ndarray:
    """Thesis Eq. 4.9: ``C1 (1 - exp(-C2 x))`` [m] of ``x`` [N]."""
    return C1_m * -np.expm1(-C2_per_N * x)


def simulate_record(system: SecondOrder, *, duration_s: float = 5.0, rate_hz: float = 2000.0,
                    cutoff_hz: float = 200.0, rms_N: float = 0.5, mean_N: float = 0.0,
                    snr_db: float = 30.0, wiener: tuple[float, float] | None = None,
                    seed: int | np.random.Generator = 0) -> SimulatedRecord:
    """Drive ``system`` with a Gaussian force low-pass filtered at ``cutoff_hz``.

    The force varies linearly between samples (exact first-order-hold simulation). With
    ``wiener = (C1_m, C2_per_N)`` the linear part is scaled to unit DC gain (its output is
    in newtons) and followed by :func:`exponential`. White output noise is added at
    ``snr_db`` (ratio of the clean output's variance to the noise variance, in dB).
    """
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    f = gaussian_force(duration_s, rate_hz, cutoff_hz=cutoff_hz, rms_N=rms_N, mean_N=mean_N,
                       seed=rng)
    if wiener is None:
        clean = simulate(system, f, rate_hz)
    else:
        x = simulate(SecondOrder.from_scaled(system.Is_s2, system.Bs_s), f, rate_hz)
        clean = exponential(x, *wiener)
    noise_std = float(np.std(clean) * 10 ** (-snr_db / 20))
    y = clean + noise_std * rng.standard_normal(f.size)
    return SimulatedRecord(f, y, clean, noise_std, rate_hz)
