"""Calibration routines (thesis 3.3.2 and 4.1.4).

* position transducers against a reference (micrometer, 500 um steps): gain and offset;
* force constant against position: ``Kf(q)`` from measured current and force at several
  arm positions, fitted by a polynomial;
* sideways scale factor: the inverse slope of sideways stiffness estimates against
  reference (Instron) stiffnesses;
* robot mass, damping and stiffness from a stochastic force run in free air (and the
  stiffness of an added spring as the difference), by least squares on
  ``F = M a + B v + K x + c`` (the lumped model of thesis Eqs 4.2-4.7, fitted in the time
  domain).

Each routine is a pure fit on arrays (usable with real data) plus, where useful, a helper
that runs the experiment on the simulated device. The results form a
:class:`RobotCalibration`, stored with the experiment (as
``/calibrations/robot``) and applied to a driver with :meth:`RobotCalibration.apply`.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy.signal import savgol_filter

from skinkit.errors import SkinkitError


class CalibrationError(SkinkitError):
    """Calibration data that cannot give a calibration (too few points, wrong shapes)."""


def _arr(x: Any, name: str, ndim: int) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim != ndim or not np.all(np.isfinite(a)):
        raise CalibrationError(f"calibration: {name} must be a finite {ndim}-d array, got shape {a.shape}")
    return a


@dataclass(frozen=True)
class LinearFit:
    """``y = gain * x + offset`` with the residual standard deviation and maximum error."""

    gain: float
    offset: float
    residual_std: float
    max_error: float


def fit_position(reference_m: np.ndarray, reading_m: np.ndarray) -> LinearFit:
    """Transducer calibration: true position as a linear function of the reading.

    ``reference_m`` ``(n,)`` micrometer positions [m], ``reading_m`` ``(n,)`` mean transducer
    readings [m] at those positions (n >= 3).
    """
    x, y = _arr(reading_m, "reading_m", 1), _arr(reference_m, "reference_m", 1)
    if x.size != y.size or x.size < 3:
        raise CalibrationError(f"position calibration needs >= 3 paired points, got {x.size} and {y.size}")
    gain, offset = np.polyfit(x, y, 1)
    res = y - (gain * x + offset)
    return LinearFit(
        float(gain), float(offset), float(res.std(ddof=2) if x.size > 2 else 0.0), float(np.abs(res).max())
    )


def fit_force_constant(
    position_m: np.ndarray, current_A: np.ndarray, force_N: np.ndarray, degree: int = 2
) -> np.ndarray:
    """Polynomial coefficients (highest power first) of ``Kf(q)`` [N/A] from steps.

    ``position_m``, ``current_A``, ``force_N``: ``(n,)`` arm position, current step and the
    force step it produced. Each point gives ``Kf = F / I``; the polynomial is fitted in q.
    """
    q, i, f = (
        _arr(a, n, 1) for a, n in ((position_m, "position_m"), (current_A, "current_A"), (force_N, "force_N"))
    )
    if not (q.size == i.size == f.size) or q.size < degree + 1:
        raise CalibrationError(f"force-constant calibration needs >= {degree + 1} points of equal length")
    if np.any(np.abs(i) < 1e-6):
        raise CalibrationError("force-constant calibration: a current step is zero")
    return np.polyfit(q, f / i, degree)


def sideways_scale(reference_N_per_m: np.ndarray, estimated_N_per_m: np.ndarray) -> float:
    """Factor to multiply a motor's force constant by in sideways motion (thesis 4.1.4):
    the inverse of the slope (through the origin) of estimates against references."""
    r, e = _arr(reference_N_per_m, "reference", 1), _arr(estimated_N_per_m, "estimated", 1)
    if r.size != e.size or r.size < 1:
        raise CalibrationError("sideways scale needs paired reference and estimated stiffnesses")
    slope = float(r @ e / (r @ r))
    return 1.0 / slope


@dataclass(frozen=True)
class LumpedFit:
    """``F = M a + B v + K x + c``: mass [kg], damping [N s/m], stiffness [N/m], offset [N],
    and the variance accounted for [%] (thesis Eq 4.8)."""

    mass_kg: float
    damping_Ns_per_m: float
    stiffness_N_per_m: float
    offset_N: float
    vaf_percent: float


def fit_mass_damping_stiffness(
    time_s: np.ndarray, position_m: np.ndarray, force_N: np.ndarray, window: int = 31
) -> LumpedFit:
    """Least-squares lumped model from a force input and the resulting position.

    Velocity and acceleration come from a Savitzky-Golay filter (cubic, ``window`` samples)
    so that the 10 um p-p potentiometer noise is not differentiated raw; the force is passed
    through the same smoother so both sides share its lag-free response.
    """
    t, x, f = _arr(time_s, "time_s", 1), _arr(position_m, "position_m", 1), _arr(force_N, "force_N", 1)
    if not (t.size == x.size == f.size) or t.size < 3 * window:
        raise CalibrationError(f"lumped fit needs >= {3 * window} samples of equal length")
    dt = float(np.median(np.diff(t)))
    xs = savgol_filter(x, window, 3)
    v = savgol_filter(x, window, 3, deriv=1, delta=dt)
    a = savgol_filter(x, window, 3, deriv=2, delta=dt)
    fs = savgol_filter(f, window, 3)
    keep = slice(window, -window)
    A = np.stack([a, v, xs, np.ones_like(x)], axis=1)[keep]
    coef, *_ = np.linalg.lstsq(A, fs[keep], rcond=None)
    pred = A @ coef
    vaf = 100.0 * (1.0 - np.var(fs[keep] - pred) / np.var(fs[keep]))
    return LumpedFit(*(float(c) for c in coef), float(vaf))


@dataclass
class RobotCalibration:
    """Everything the calibration routines produce for one robot (SI units, per motor)."""

    position_gain: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])
    position_offset_m: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    force_constant_poly: list[list[float]] = field(default_factory=list)  # per motor, highest power first
    sideways_scale: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])
    robot: dict[str, float] = field(default_factory=dict)  # mass_kg, damping_Ns_per_m, stiffness_N_per_m

    def to_json(self) -> str:
        """The calibration as canonical JSON (sorted keys)."""
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> RobotCalibration:
        """A calibration from :meth:`to_json`'s text; :class:`CalibrationError` when it is malformed."""
        try:
            return cls(**json.loads(text))
        except (TypeError, ValueError) as exc:
            raise CalibrationError(f"robot calibration: malformed ({exc})") from None

    def force_constant(self, q: np.ndarray) -> np.ndarray:
        """``Kf`` [N/A] at arm positions ``q`` ``(..., 3)`` [m]."""
        q = np.asarray(q, dtype=float)
        if not self.force_constant_poly:
            raise CalibrationError("robot calibration: no force-constant calibration")
        return np.stack([np.polyval(self.force_constant_poly[j], q[..., j]) for j in range(3)], axis=-1)

    def apply(self, driver: Any) -> None:
        """Make ``driver`` convert currents with the calibrated force constant."""
        if self.force_constant_poly:
            driver.force_constant = self.force_constant

    def save(self, experiment: Any) -> None:
        """Store with the experiment (``/calibrations/robot``)."""
        experiment.write_calibration("robot", json.loads(self.to_json()))

    @classmethod
    def load(cls, experiment: Any) -> RobotCalibration:
        """The robot calibration stored in ``experiment``; :class:`CalibrationError` when it holds none."""
        if "robot" not in experiment.calibration_names():
            raise CalibrationError(f"{experiment.path}: no robot calibration stored")
        return cls.from_json(json.dumps(experiment.read_calibration("robot")))


# -- experiments on the simulated device ------------------------------------------------
def simulate_force_constant_steps(
    heights_m: np.ndarray, currents_A: np.ndarray, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thesis 3.3.2 on the simulator: the arms push a stiff load cell placed at each height
    with each current in turn; returns ``(position, current step, force step)`` per motor
    and step, relative to the first current (steps cancel gravity and the robot's springs).

    All three arms push equally, so each carries a third of the normal tip force (the
    Jacobian's z row is 1/3 per arm at equal heights).
    """
    from skinkit_hardware.device import Device
    from skinkit_hardware.kinematics import forward
    from skinkit_hardware.skin import KelvinVoigtSkin

    qs, cs, fs = [], [], []
    for h in np.asarray(heights_m, float):
        # a stiff, slightly damped load cell that also holds the tip sideways
        cell = KelvinVoigtSkin(2e5, 2e5, 20.0, 20.0, glued=True)
        dev = Device(skin=cell, seed=seed)
        dev.skin_origin = forward(np.full(3, h), dev.geometry)
        dev.place_arms([float(h)] * 3)  # the load cell sits on the arms
        level = []
        prev = 0.0
        for i in np.asarray(currents_A, float):
            force = i * float(dev.params.force_constant(h))
            # a 50 ms ramp: a step into the stiff, undamped load cell would ring past the tip limit
            prog = np.concatenate([np.linspace(prev, force, 50), np.full(251, force)])
            prev = force
            dev.load("force", 1000.0, np.repeat(prog[:, None], 3, axis=1))
            dev.start()
            while dev.mode == "running":
                dev.heartbeat()
                dev.advance(1000)
            rows = dev.drain()[100:]  # the settled half
            level.append((rows[:, 2:5].mean(), rows[:, 5:8].mean(), rows[:, 10].mean() / 3.0))
        for q, c, f in level[1:]:
            qs.append(q)
            cs.append(c - level[0][1])
            fs.append(f - level[0][2])
    return np.array(qs), np.array(cs), np.array(fs)


def simulate_spring_run(
    k_spring_N_per_m: float, duration_s: float = 2.0, force_std_N: float = 0.25, seed: int = 0
) -> LumpedFit:
    """Thesis 4.1.4 on the simulator: a stochastic normal force (all three motors, 200 Hz
    band) on a calibration spring of known stiffness, recorded at the full 10 kHz; returns
    the lumped fit of summed motor force against the tip's normal position."""
    from skinkit.plugin.drivers import stochastic
    from skinkit_hardware.device import Device
    from skinkit_hardware.skin import KelvinVoigtSkin

    # the spring is glued at the home pose; a stiff sideways guide keeps the tip on the normal
    dev = Device(
        skin=KelvinVoigtSkin(k_spring_N_per_m, 2000.0, 0.0, 0.0, glued=True), decimation=1, seed=seed
    )
    dev.skin_origin = dev.tip_home.copy()
    h = dev.geometry.home_m
    dev.place_arms([h] * 3)
    p = dev.params
    hold = p.mass_kg * p.gravity_m_s2 + p.stiffness_N_per_m * (h - p.spring_rest_m)
    n = int(round(duration_s * 1000)) + 1
    u = hold + force_std_N * stochastic(n, 1000.0, 200.0, seed)
    ev = dev.load("force", 1000.0, np.repeat(u[:, None], 3, axis=1))
    if ev is not None:
        raise CalibrationError(f"spring run refused: {ev.fault.message()}")
    dev.start()
    while dev.mode == "running":
        dev.heartbeat()
        dev.advance(1000)
    rows = dev.drain()
    t = rows[:, 1] / p.control_rate_hz
    q = rows[:, 2:5]
    return fit_mass_damping_stiffness(t, q.mean(axis=1), (p.force_constant(q) * rows[:, 5:8]).sum(axis=1))


def robot_from_spring_runs(k_reference_N_per_m: np.ndarray, fits: list[LumpedFit]) -> dict[str, float]:
    """Robot mass, damping and stiffness from runs on springs of known stiffness: the
    stiffness estimates against the references give the robot's own stiffness (intercept)
    and the sensitivity (slope, ~1 when the force constant is right); mass and damping are
    the means (independent of the spring, thesis Figures 4-9 and 4-10)."""
    k = _arr(k_reference_N_per_m, "k_reference_N_per_m", 1)
    if k.size != len(fits) or k.size < 2:
        raise CalibrationError("robot calibration needs >= 2 spring runs with their reference stiffness")
    est = np.array([f.stiffness_N_per_m for f in fits])
    slope, intercept = np.polyfit(k, est, 1)
    return {
        "mass_kg": float(np.mean([f.mass_kg for f in fits])),
        "damping_Ns_per_m": float(np.mean([f.damping_Ns_per_m for f in fits])),
        "stiffness_N_per_m": float(intercept),
        "sensitivity": float(slope),
    }
