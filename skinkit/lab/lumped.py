"""A virtual stochastic-force session on a lumped skin with a known truth.

Truth by default: the forearm of thesis Table 7 (K = 1.45 kN/m, B = 4.76 N s/m,
I = 15.5 g) behind the robot's own moving mass (25 g), followed by the Wiener
nonlinearity of Table 8 (C1 = 8.6 mm, C2 = 0.51 /N); a 200 Hz Gaussian force of mean 1 N
and 0.5 N rms sampled at 2 kHz for 5 s, 30 dB output noise.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from skinkit.schemas import Protocol, RobotRecord
from skinkit.sysid.lti import SecondOrder
from skinkit.sysid.robot import RobotDynamics
from skinkit.sysid.simulate import simulate_record


@dataclass(frozen=True)
class LumpedTruth:
    """What the virtual session is made of (SI)."""

    K_N_per_m: float = 1450.0
    B_Ns_per_m: float = 4.76
    I_kg: float = 0.0155
    robot_mass_kg: float = 0.025
    C1_m: float = 8.6e-3
    C2_per_N: float = 0.51
    mean_force_N: float = 1.0
    rms_force_N: float = 0.5
    cutoff_hz: float = 200.0
    rate_hz: float = 2000.0
    duration_s: float = 5.0
    snr_db: float = 30.0

    @property
    def skin(self) -> SecondOrder:
        """The skin's second-order system (K, B, I)."""
        return SecondOrder(self.K_N_per_m, self.B_Ns_per_m, self.I_kg)

    @property
    def robot(self) -> RobotDynamics:
        """The robot's dynamics (its mass)."""
        return RobotDynamics(mass_kg=self.robot_mass_kg)

    def to_dict(self) -> dict[str, Any]:
        """The truth as a plain dict."""
        return asdict(self)


def stochastic_session(truth: LumpedTruth = LumpedTruth(), wiener: bool = True,
                       seed: int | np.random.Generator = 0) -> RobotRecord:
    """Simulate the probe's normal position under the stochastic force programme; returns a
    :class:`RobotRecord` named ``stochastic_wiener`` or ``stochastic_linear`` (tip force and
    position along z; x, y zero).

    With ``wiener`` the mass-spring-damper (robot included) is scaled to unit DC gain and
    followed by the static nonlinearity, as thesis Eq. 4.9 models it; else it is linear.
    """
    total = SecondOrder(truth.K_N_per_m, truth.B_Ns_per_m, truth.I_kg + truth.robot_mass_kg)
    sim = simulate_record(total, duration_s=truth.duration_s, rate_hz=truth.rate_hz,
                          cutoff_hz=truth.cutoff_hz, rms_N=truth.rms_force_N,
                          mean_N=truth.mean_force_N, snr_db=truth.snr_db,
                          wiener=(truth.C1_m, truth.C2_per_N) if wiener else None, seed=seed)
    name = "stochastic_wiener" if wiener else "stochastic_linear"
    rec = sim.to_robot_record(axis=2, name=name)
    protocol = Protocol(name, kind="force",
                        parameters={"mean_force": truth.mean_force_N, "rms_force": truth.rms_force_N,
                                    "cutoff": truth.cutoff_hz, "rate": truth.rate_hz,
                                    "duration": truth.duration_s},
                        units={"mean_force": "N", "rms_force": "N", "cutoff": "Hz", "rate": "Hz",
                               "duration": "s"},
                        duration_s=truth.duration_s,
                        description="virtual lab: Gaussian force, low-pass filtered, normal axis")
    return RobotRecord(time_s=rec.time_s, tip_force=rec.tip_force, tip_position=rec.tip_position,
                       protocol=protocol)
