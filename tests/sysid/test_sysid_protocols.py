"""Input design, incremental analysis, robot calibration and cohort statistics."""

from __future__ import annotations

import numpy as np
import pytest
from sysid_truth import C1_M, C2_PER_N, SKIN

from skinkit.sysid import (
    RobotDynamics,
    SecondOrder,
    SysidError,
    calibrate_mass,
    calibrate_position,
    calibrate_springs,
    identify_linear,
)
from skinkit.sysid.cohort import cv_table, write_csv
from skinkit.sysid.incremental import identify_incremental, youngs_modulus
from skinkit.sysid.inputs import gaussian_force, incremental, preconditioning, scale_to_limit
from skinkit.sysid.lti import simulate
from skinkit.sysid.simulate import exponential, simulate_record


def test_gaussian_force_is_band_limited_and_scaled():
    f = gaussian_force(5.0, 2000.0, cutoff_hz=200.0, rms_N=0.7, mean_N=1.0, seed=0)
    assert f.size == 10000
    assert np.std(f) == pytest.approx(0.7, rel=1e-12)
    assert np.mean(f) == pytest.approx(1.0, abs=1e-12)
    spec = np.abs(np.fft.rfft((f - f.mean()) * np.hanning(f.size))) ** 2  # window: no leakage
    fr = np.fft.rfftfreq(f.size, 1 / 2000.0)
    # a zero-phase 4th-order Butterworth is down 160 dB per decade in power: above twice the
    # cut-off (-48 dB at 400 Hz) about 1e-5 of the power remains
    assert spec[fr > 400].sum() / spec.sum() < 1e-4
    peak = gaussian_force(1.0, 2000.0, peak_N=3.5, seed=1)
    assert np.max(np.abs(peak)) == pytest.approx(3.5)
    assert np.max(np.abs(scale_to_limit(f, 10.5))) == pytest.approx(10.5)
    with pytest.raises(SysidError, match="cutoff"):
        gaussian_force(1.0, 100.0, cutoff_hz=200.0, rms_N=1.0)


def test_preconditioning_schedule():
    p = preconditioning(6.0, 1000.0, stochastic_s=2.0, hold_s=1.0, seed=0)
    pre, ident = p.segments
    # three 0.5 Hz periods (6 s), a half-period ramp up (1 s), 1 s hold, then 2 s stochastic
    assert pre.stop == 8000 and ident.stop - ident.start == 2000
    assert p.force_N[:6000].max() == pytest.approx(6.0, rel=1e-3)
    assert np.all(p.force_N[7000:8000] == 6.0)
    seg = p.force_N[ident.start:]
    assert seg.min() >= -1e-9 and seg.max() <= 6.0 + 1e-9


@pytest.mark.parametrize("protocol", ["A", "B"])
def test_incremental_programme(protocol):
    p = incremental(protocol, 3.0, 1000.0, n_steps=15, step_s=1.0, precondition_s=0.5, seed=0)
    ident = p.identify_segments()
    assert len(ident) == 30
    means = [s.mean_N for s in ident]
    assert means[:15] == sorted(means[:15]) and means[15:] == sorted(means[15:], reverse=True)
    assert [s.direction for s in ident] == ["up"] * 15 + ["down"] * 15
    for s in ident:
        seg = p.force_N[s.start:s.stop]
        # 20 % of full scale: the stochastic part spans at most +-0.3 N about its mean
        assert np.max(np.abs(seg - s.mean_N)) <= 0.3 + 1e-9
    pre = [s for s in p.segments if s.kind == "precondition"]
    if protocol == "A":
        assert max(p.force_N[s.start:s.stop].max() for s in pre) == pytest.approx(3.0, rel=1e-2)
    else:
        nxt = {s.start: s for s in ident}
        for s in pre:
            assert np.allclose(p.force_N[s.start:s.stop], nxt[s.stop].mean_N)


def test_incremental_stiffness_follows_wiener_slope(total):
    # Protocol B through a Wiener skin: each increment's K is the local stiffness
    # 1 / g'(F) = 1 / (C1 C2 exp(-C2 F)) at its mean force F. The secant over a Gaussian
    # force of sigma ~0.1 N differs from the tangent by C2^2 sigma^2 / 2 ~ 0.1 %.
    rate = 2000.0
    prog = incremental("B", 3.0, rate, n_steps=4, step_s=3.0, precondition_s=0.5, seed=3)
    x = simulate(SecondOrder.from_scaled(total.Is_s2, total.Bs_s), prog.force_N, rate)
    y = exponential(x, C1_M, C2_PER_N)
    y = y + 1e-6 * np.random.default_rng(3).standard_normal(y.size)  # 1 um sensor noise
    res = identify_incremental(prog.force_N, y, rate, prog.segments, memory_s=0.12,
                               probe_radius_m=2e-3)
    table = res.table()
    assert len(table) == 8 and all(r["valid"] for r in table)
    for r in table:
        k_local = 1 / (C1_M * C2_PER_N * np.exp(-C2_PER_N * r["mean_force_N"]))
        assert r["K_N_per_m"] == pytest.approx(k_local, rel=0.03)
        assert r["E_Pa"] == pytest.approx((1 - 0.45**2) * r["K_N_per_m"] / 4e-3)
    ups = [r["K_N_per_m"] for r in table if r["direction"] == "up"]
    assert ups == sorted(ups)  # stiffening with indentation
    # the truth has no hysteresis: down and up agree at each level
    assert len(res.hysteresis()) == 4
    for h in res.hysteresis():
        assert h["K_ratio"] == pytest.approx(1.0, abs=0.03)
        assert abs(h["position_offset_m"]) < 20e-6
    # the same from a RobotRecord, segments found from the force alone
    from skinkit.sysid.simulate import SimulatedRecord

    rr = SimulatedRecord(prog.force_N, y, y, 1e-6, rate).to_robot_record()
    auto = identify_incremental(rr, memory_s=0.12).table()
    assert [r["direction"] for r in auto] == [r["direction"] for r in table]
    for r in auto:
        k_local = 1 / (C1_M * C2_PER_N * np.exp(-C2_PER_N * r["mean_force_N"]))
        assert r["K_N_per_m"] == pytest.approx(k_local, rel=0.03)


def test_incremental_keeps_going_after_a_bad_increment(total):
    rec = simulate_record(total, seed=2)
    f = rec.force_N.copy()
    f[:3000] = 0.5  # constant force in the first segment
    res = identify_incremental(f, rec.position_m, 2000.0, [(0, 3000), (3000, 10000)])
    t = res.table()
    assert "constant" in t[0]["error"] and t[1]["valid"]


def test_youngs_modulus_thesis_form():
    # thesis: E = (1 - nu^2) K / (2 Rp); 1.45 kN/m on a 5 mm radius probe with nu = 0.45
    assert youngs_modulus(1450.0, 5e-3) == pytest.approx(0.7975 * 1450 / 0.01)
    with pytest.raises(SysidError, match="radius"):
        youngs_modulus(1.0, 0.0)


def test_spring_and_mass_calibration_recover_robot(total):
    robot = RobotDynamics(mass_kg=0.025, damping_Ns_per_m=2.0, stiffness_N_per_m=60.0,
                          force_scale=1 / 1.15)
    springs = [600.0, 1200.0, 2400.0]
    runs = []
    for k, K in enumerate(springs):
        rec = simulate_record(robot.add(SecondOrder(K, 0.0, 0.0)), seed=30 + k)
        runs.append(identify_linear(rec.force_N, rec.position_m, 2000.0).total)
    cal = calibrate_springs(runs, springs)
    # each run is identified to ~0.5 %; the regression inherits that
    assert cal.slope == pytest.approx(1.15, rel=0.02)
    assert cal.robot.force_scale == pytest.approx(1 / 1.15, rel=0.02)
    assert cal.robot.stiffness_N_per_m == pytest.approx(60.0, abs=25.0)
    assert cal.robot.mass_kg == pytest.approx(0.025, rel=0.03)
    assert cal.robot.damping_Ns_per_m == pytest.approx(2.0, rel=0.05)
    masses = [0.0, 0.01, 0.02]
    mruns = []
    for k, m in enumerate(masses):
        rec = simulate_record(robot.add(SecondOrder(1000.0, 0.0, m)), seed=40 + k)
        mruns.append(identify_linear(rec.force_N, rec.position_m, 2000.0).total)
    m0, slope = calibrate_mass(mruns, masses, cal.robot)
    assert m0 == pytest.approx(0.025, rel=0.05) and slope == pytest.approx(1.0, rel=0.05)
    # and removal gives the skin back
    rec = simulate_record(robot.add(SKIN), seed=50)
    skin = identify_linear(rec.force_N, rec.position_m, 2000.0, robot=cal.robot).skin
    assert skin.K == pytest.approx(SKIN.K, rel=0.03)
    assert skin.I == pytest.approx(SKIN.I, rel=0.1)  # 15.5 g beside 25 g of robot


def test_position_dependent_force_constant():
    x = np.array([1e-3, 2e-3, 3e-3, 4e-3])
    ratio = 1 + 20.0 * (x - 2.5e-3)  # 2 % per mm
    poly = calibrate_position(ratio * 500.0, np.full(4, 500.0), x)
    robot = RobotDynamics(position_poly=poly)
    assert robot.factor(2.5e-3) == pytest.approx(1.0)
    assert robot.factor(4e-3) == pytest.approx(1 / 1.03)
    with pytest.raises(SysidError, match="mean position"):
        robot.factor()


def test_cv_table_thesis_definition(tmp_path):
    trials = []
    for subject, base in (("s1", 8.0), ("s2", 10.0)):
        for v in (base - 0.5, base + 0.5):
            trials.append({"subject": subject, "site": "forearm", "direction": "N",
                           "C1_m": v * 1e-3})
    t = cv_table(trials, parameters=("C1_m",))
    assert len(t) == 1
    r = t[0]
    within = np.mean([np.std([7.5, 8.5], ddof=1) / 8, np.std([9.5, 10.5], ddof=1) / 10])
    across = np.std([7.5, 8.5, 9.5, 10.5], ddof=1) / 9
    assert r["cv_within_pct"] == pytest.approx(100 * within)
    assert r["cv_across_pct"] == pytest.approx(100 * across)
    assert r["n_subjects"] == 2 and r["n_trials"] == 4
    write_csv(t, tmp_path / "cv.csv")
    assert (tmp_path / "cv.csv").read_text().startswith("site,direction,parameter")
    with pytest.raises(SysidError, match="lacks"):
        cv_table([{"subject": "s1"}])


@pytest.mark.parametrize("protocol", ["A", "B"])
def test_detect_segments_finds_the_stochastic_steps(protocol):
    from skinkit.sysid.incremental import detect_segments

    p = incremental(protocol, 3.0, 2000.0, n_steps=4, step_s=3.0, precondition_s=0.5, seed=5)
    found = detect_segments(p.force_N, 2000.0)
    true = p.identify_segments()
    assert len(found) == len(true)
    for a, b in zip(found, true, strict=True):
        # inside the true step, and covering most of it (trim 0.25 s + window at each end)
        assert b.start <= a.start < a.stop <= b.stop
        assert (a.stop - a.start) > 0.6 * (b.stop - b.start)
        assert a.direction == b.direction
    with pytest.raises(SysidError, match="cutoff"):
        detect_segments(p.force_N, 2000.0, cutoff_hz=5000.0)
