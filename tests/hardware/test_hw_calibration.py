"""Calibration routines: closed-form checks of the fits, and the thesis 4.1.4 procedures
run on the simulated robot whose true parameters are known."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.needs_hardware
pytest.importorskip("skinkit_hardware")

from skinkit_hardware import calibration as C  # noqa: E402
from skinkit_hardware.drivers.sim import SimDriver  # noqa: E402
from skinkit_hardware.params import RobotParameters  # noqa: E402

from skinkit.store import create_experiment, open_experiment  # noqa: E402

P = RobotParameters()
# The lumped fit differentiates with a 31-sample cubic Savitzky-Golay filter and pairs each
# force with the position the 10 kHz integrator produces one step later; on an exact
# mass-spring-damper (test below) that biases mass and stiffness by ~5 %. Bound: 10 %.
LUMPED_RTOL = 0.10


def test_position_fit_recovers_gain_and_offset_within_noise() -> None:
    rng = np.random.default_rng(0)
    ref = np.arange(0, 0.0101, 0.0005)  # micrometer, 500 um steps (thesis 3.3.2)
    reading = (ref - 2e-4) / 1.02 + rng.normal(0, 3e-6, ref.size)  # 3 um reading noise
    fit = C.fit_position(ref, reading)
    # slope standard error ~ sigma / (std(x) sqrt(n)) ~ 3e-6 / (3e-3 * 4.6) ~ 2e-4
    assert fit.gain == pytest.approx(1.02, abs=1e-3) and fit.offset == pytest.approx(2e-4, abs=1e-5)
    assert fit.residual_std == pytest.approx(3e-6 * 1.02, rel=0.5)
    with pytest.raises(C.CalibrationError, match=">= 3 paired points"):
        C.fit_position([0.0, 1.0], [0.0, 1.0])


def test_lumped_fit_on_an_exact_mass_spring_damper() -> None:
    from skinkit.acquisition import stochastic

    dt, n = 1e-4, 20000
    f = np.interp(np.arange(n) * dt, np.arange(2001) / 1000.0, 1 + 0.3 * stochastic(2001, 1000.0, 200.0, 0))
    m, b, k = 0.075, 6.0, 1300.0
    x = np.empty(n)
    xx = v = 0.0
    for i in range(n):  # the simulator's semi-implicit Euler
        v += (f[i] - b * v - k * xx) / m * dt
        xx += v * dt
        x[i] = xx
    fit = C.fit_mass_damping_stiffness(np.arange(n) * dt, x, f)
    assert fit.mass_kg == pytest.approx(m, rel=LUMPED_RTOL)
    assert fit.damping_Ns_per_m == pytest.approx(b, rel=LUMPED_RTOL)
    assert fit.stiffness_N_per_m == pytest.approx(k, rel=LUMPED_RTOL)
    assert fit.vaf_percent > 95


def test_robot_mass_damping_stiffness_from_spring_runs() -> None:
    ks = np.array([500.0, 2000.0])
    fits = [C.simulate_spring_run(k, duration_s=1.0) for k in ks]
    robot = C.robot_from_spring_runs(ks, fits)
    # the three arms move together: M = 3 m, B = 3 b, and the robot's own stiffness 3 k
    assert robot["mass_kg"] == pytest.approx(3 * P.mass_kg, rel=LUMPED_RTOL)
    assert robot["damping_Ns_per_m"] == pytest.approx(3 * P.damping_Ns_per_m, rel=LUMPED_RTOL)
    assert robot["sensitivity"] == pytest.approx(1.0, rel=LUMPED_RTOL)
    # intercept: 3 k = 300 N/m, carrying the slope's 10 % of the spring range's mean (125 N/m)
    assert robot["stiffness_N_per_m"] == pytest.approx(3 * P.stiffness_N_per_m, abs=LUMPED_RTOL * 1250 + 30)


def test_force_constant_against_position() -> None:
    heights = np.linspace(0.001, 0.009, 5)
    q, di, df = C.simulate_force_constant_steps(heights, [0.1, 0.5])
    poly = C.fit_force_constant(q, di, df)
    # the load cell (2e5 N/m) deflects ~35 um per step, which the robot's own 100 N/m
    # springs resist: 3 x 100 / 2e5 = 0.15 % of the step force; 0.5 % bound
    np.testing.assert_allclose(np.polyval(poly, q), P.force_constant(q), rtol=5e-3)
    assert C.sideways_scale(np.array([126.0, 220.0]), np.array([126.0, 220.0]) * 1.25) == pytest.approx(0.8)


def test_calibration_is_stored_and_applied(tmp_path) -> None:
    cal = C.RobotCalibration(force_constant_poly=[[0.0, 0.0, 5.0]] * 3, robot={"mass_kg": 0.075})
    with create_experiment(tmp_path / "cal.h5") as exp:
        cal.save(exp)
    back = C.RobotCalibration.load(open_experiment(tmp_path / "cal.h5"))
    assert back == cal
    d = SimDriver()
    back.apply(d)
    np.testing.assert_allclose(d.force_constant(np.full((2, 3), 0.004)), 5.0)
