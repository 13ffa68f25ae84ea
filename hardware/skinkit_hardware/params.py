"""Physical parameters and safety limits of the microrobot, with their sources.

Values from the thesis are cited by section; the rest are documented assumptions chosen
to be physically plausible for a voice-coil robot of this size (BEI Kimco LA10-12-027A).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RobotParameters:
    """Dynamics and sensors of one robot (per arm unless stated). SI units.

    Attributes:
        mass_kg: moving mass per arm, platform share included (thesis 4.1.4: ~0.025 kg).
        damping_Ns_per_m: viscous damping per arm (slides, potentiometer wiper) [assumed].
        stiffness_N_per_m: retaining-spring stiffness per arm [assumed].
        spring_rest_m: arm position where the spring is unloaded [assumed].
        gravity_m_s2: gravity along -z.
        force_constant_N_per_A: force constant at mid-stroke, 13.3 N / 2.28 A (thesis 3.2.3).
        force_constant_droop: fractional drop of the force constant at the stroke ends
            (thesis Figure 3-16 shows a position dependence; its shape is assumed parabolic).
        peak_current_A: amplifier/motor peak current (thesis 3.2.3: 2.28 A at 13.3 N).
        control_rate_hz: PID rate per axis (thesis 3.2.2: 10 kHz).
        pot_noise_pp_m: potentiometer noise peak to peak (thesis 3.3.2: ~10 um); the standard
            deviation is a sixth of it (Gaussian, 99.7 % within peak to peak).
        adc_bits, adc_span_m: position ADC (16 bit over the stroke plus margins, thesis 3.3.2).
        current_noise_A: current-sense noise, standard deviation [assumed 0.5 mA].
        current_lsb_A: current reading resolution.
        ft_force_resolution_N: Nano17 force resolution (thesis Table 5: 5.8 mN).
        ft_torque_resolution_Nm: Nano17 torque resolution (1/32 N mm, ATI SI-32-0.2).
        probe_length_m: tip above the F/T sensor origin [assumed].
        kp_N_per_m, ki_N_per_m_s, kd_Ns_per_m: PID gains (about 64 Hz bandwidth, damping 0.7).
        derivative_filter_hz: low-pass on the position used by the D term (thesis 3.2.2: 1 kHz).
        thermal_time_constant_s: time constant of the coil heating model behind the
            continuous-force limit [assumed].
    """

    mass_kg: float = 0.025
    damping_Ns_per_m: float = 2.0
    stiffness_N_per_m: float = 100.0
    spring_rest_m: float = 0.005
    gravity_m_s2: float = 9.81
    force_constant_N_per_A: float = 13.3 / 2.28
    force_constant_droop: float = 0.15
    peak_current_A: float = 2.28
    control_rate_hz: float = 10_000.0
    pot_noise_pp_m: float = 10e-6
    adc_bits: int = 16
    adc_span_m: tuple[float, float] = (-0.001, 0.011)
    current_noise_A: float = 0.5e-3
    current_lsb_A: float = 1e-4
    ft_force_resolution_N: float = 5.8e-3
    ft_torque_resolution_Nm: float = 1.0 / 32.0 * 1e-3
    probe_length_m: float = 0.010
    kp_N_per_m: float = 4000.0
    ki_N_per_m_s: float = 3.2e5
    kd_Ns_per_m: float = 14.0
    derivative_filter_hz: float = 1000.0
    thermal_time_constant_s: float = 10.0
    stroke_m: tuple[float, float] = (0.0, 0.010)

    @property
    def dt(self) -> float:
        """Control period [s]."""
        return 1.0 / self.control_rate_hz

    @property
    def pot_sigma_m(self) -> float:
        """Standard deviation of the potentiometer noise [m] (peak-to-peak / 6)."""
        return self.pot_noise_pp_m / 6.0

    def force_constant(self, q: np.ndarray | float) -> np.ndarray | float:
        """Force constant [N/A] at arm position ``q`` [m]: parabolic droop towards the stroke ends."""
        lo, hi = self.stroke_m
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        s = (np.asarray(q) - mid) / half
        return self.force_constant_N_per_A * (1.0 - self.force_constant_droop * np.minimum(s * s, 1.5))


@dataclass(frozen=True)
class Limits:
    """Safety limits enforced by the host driver (before motion) and the device (every tick).

    Attributes:
        peak_force_N: per-motor peak force (thesis 3.2.3: 13.3 N).
        continuous_force_N: per-motor continuous force, as the RMS over the coil's thermal
            time constant (thesis 3.2.3: 4.95 N).
        travel_m: per-arm position range [m]; leaving it trips the device.
        tip_force_N: magnitude of the tip force that trips the device [assumed: above the
            10.5 N summed normal force of thesis 4.1.3].
        watchdog_s: host silence that de-energises the motors.
        stuck_ticks: identical consecutive position readings that declare a sensor stuck
            (the 10 um p-p noise spans ~40 ADC steps, so 50 identical readings do not happen
            by chance).
        post_fault_s: samples still streamed after a trip, so the record shows the stop.
    """

    peak_force_N: float = 13.3
    continuous_force_N: float = 4.95
    travel_m: tuple[float, float] = (0.0, 0.010)
    tip_force_N: float = 12.0
    watchdog_s: float = 0.5
    stuck_ticks: int = 50
    post_fault_s: float = 0.02

    def to_dict(self) -> dict[str, float]:
        """The limits as a flat dict of SI floats."""
        return {
            "peak_force_N": self.peak_force_N,
            "continuous_force_N": self.continuous_force_N,
            "travel_min_m": self.travel_m[0],
            "travel_max_m": self.travel_m[1],
            "tip_force_N": self.tip_force_N,
            "watchdog_s": self.watchdog_s,
        }
