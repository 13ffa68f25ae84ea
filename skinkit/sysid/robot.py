"""The robot's own dynamics: calibration against springs and masses, and removal.

Thesis 4.1.4. The identified system is robot plus skin: ``K_meas = s (K_skin + K_robot)``
(and likewise B and I), where ``s`` is the ratio of the force constant the controller
assumes to the effective one (above 1 in sideways motions, where the platform springs and
linear slides take up force). Runs against springs of known stiffness (no added mass or
damping) give ``s`` (slope of measured against reference stiffness), the robot stiffness
(intercept / s) and the robot's moving mass and damping (mean over the runs / s). Runs with
added masses check the moving mass (intercept of measured inertia against added mass).
Runs at several mean positions give a position-dependent force-constant factor ``c(x)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from skinkit.sysid.checks import SysidError
from skinkit.sysid.lti import SecondOrder


@dataclass(frozen=True)
class RobotDynamics:
    """What the robot adds to every identified system.

    Attributes:
        mass_kg: moving mass [kg].
        damping_Ns_per_m: damping [N s/m].
        stiffness_N_per_m: stiffness [N/m].
        force_scale: factor applied to measured K, B, I (1/s; 1 under normal indentation).
        position_poly: coefficients (highest power first, position in m) of the relative
            force-constant factor ``c(x)``; empty means ``c = 1``.
    """

    mass_kg: float = 0.0
    damping_Ns_per_m: float = 0.0
    stiffness_N_per_m: float = 0.0
    force_scale: float = 1.0
    position_poly: tuple[float, ...] = ()

    def factor(self, mean_position_m: float | None = None) -> float:
        """Multiplier of measured K, B, I at ``mean_position_m`` [m]."""
        c = 1.0
        if self.position_poly:
            if mean_position_m is None:
                raise SysidError("this robot calibration depends on position: give the mean "
                                 "position of the record")
            c = float(np.polyval(self.position_poly, mean_position_m))
        return self.force_scale / c

    def remove(self, total: SecondOrder, mean_position_m: float | None = None) -> SecondOrder:
        """Skin dynamics from identified robot-plus-skin dynamics ``total``."""
        f = self.factor(mean_position_m)
        return SecondOrder(K=total.K * f - self.stiffness_N_per_m,
                           B=total.B * f - self.damping_Ns_per_m,
                           I=total.I * f - self.mass_kg)

    def add(self, skin: SecondOrder, mean_position_m: float | None = None) -> SecondOrder:
        """Robot-plus-skin dynamics as measured (inverse of :meth:`remove`)."""
        f = self.factor(mean_position_m)
        return SecondOrder(K=(skin.K + self.stiffness_N_per_m) / f,
                           B=(skin.B + self.damping_Ns_per_m) / f,
                           I=(skin.I + self.mass_kg) / f)

    def to_dict(self) -> dict[str, object]:
        """The robot dynamics as a plain dict (SI units in the keys)."""
        return {"mass_kg": self.mass_kg, "damping_Ns_per_m": self.damping_Ns_per_m,
                "stiffness_N_per_m": self.stiffness_N_per_m, "force_scale": self.force_scale,
                "position_poly": list(self.position_poly)}


@dataclass(frozen=True)
class SpringCalibration:
    """Regression of measured on reference stiffness: ``K_meas = slope K_ref + intercept``."""

    slope: float
    intercept_N_per_m: float
    robot: RobotDynamics
    rms_error_N_per_m: float


def _systems(measured: Sequence[SecondOrder], n: int, what: str) -> None:
    if len(measured) != n:
        raise SysidError(f"{what}: {len(measured)} identified systems for {n} references")
    if n < 2:
        raise SysidError(f"{what}: need at least 2 calibration runs, got {n}")


def calibrate_springs(measured: Sequence[SecondOrder], reference_K_N_per_m: Sequence[float]
                      ) -> SpringCalibration:
    """Robot stiffness, damping, mass and force scale from runs against known springs."""
    ref = np.asarray(reference_K_N_per_m, float)
    _systems(measured, ref.size, "calibrate_springs")
    if np.ptp(ref) <= 0:
        raise SysidError("calibrate_springs: the reference stiffnesses must differ")
    K = np.array([m.K for m in measured])
    slope, intercept = np.polyfit(ref, K, 1)
    if slope <= 0:
        raise SysidError(f"calibrate_springs: measured stiffness falls with reference (slope "
                         f"{slope:.3g}); check the runs")
    rms = float(np.sqrt(np.mean((K - (slope * ref + intercept)) ** 2)))
    robot = RobotDynamics(mass_kg=float(np.mean([m.I for m in measured]) / slope),
                          damping_Ns_per_m=float(np.mean([m.B for m in measured]) / slope),
                          stiffness_N_per_m=float(intercept / slope), force_scale=1.0 / slope)
    return SpringCalibration(float(slope), float(intercept), robot, rms)


def calibrate_mass(measured: Sequence[SecondOrder], added_kg: Sequence[float],
                   robot: RobotDynamics | None = None) -> tuple[float, float]:
    """Moving mass [kg] (intercept) and slope [1] of inertia against added mass.

    ``measured`` are runs with masses ``added_kg`` fixed to the tip (and a spring to keep
    them attached); their inertia is scaled by ``robot.force_scale`` first. The slope
    should be near 1.
    """
    add = np.asarray(added_kg, float)
    _systems(measured, add.size, "calibrate_mass")
    s = 1.0 if robot is None else robot.force_scale
    inertia = np.array([m.I for m in measured]) * s
    slope, intercept = np.polyfit(add, inertia, 1)
    return float(intercept), float(slope)


def calibrate_position(measured_K: Sequence[float], reference_K: Sequence[float],
                       mean_position_m: Sequence[float], degree: int = 1) -> tuple[float, ...]:
    """Polynomial ``c(x)`` (highest power first) of the ratio of measured to reference
    stiffness against mean position [m], normalised to 1 at the mean calibration position."""
    kk = np.asarray(measured_K, float) / np.asarray(reference_K, float)
    x = np.asarray(mean_position_m, float)
    if x.size != kk.size or x.size <= degree:
        raise SysidError(f"calibrate_position: need more than {degree} runs with one position each")
    p = np.polyfit(x, kk, degree)
    return tuple(float(c) for c in p / np.polyval(p, x.mean()))
