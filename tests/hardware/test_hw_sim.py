"""The simulated robot through the ``sim`` driver: homing, protocols, safety interlocks and
the protocol runner into a real experiment file."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.needs_hardware

pytest.importorskip("skinkit_hardware")

from skinkit_hardware import faults as F  # noqa: E402
from skinkit_hardware.device import Device, Injection, run_device_until  # noqa: E402
from skinkit_hardware.drivers.sim import SimDriver  # noqa: E402
from skinkit_hardware.params import Limits, RobotParameters  # noqa: E402

from skinkit import registry  # noqa: E402
from skinkit.acquisition import make_protocol, run_protocol  # noqa: E402
from skinkit.schemas.robot import FLAG_CAMERA_TRIGGER, FLAG_ESTOP, FLAG_LIMIT  # noqa: E402
from skinkit.store import create_experiment, open_experiment  # noqa: E402

P = RobotParameters()
# measured current noise: 0.5 mA standard deviation; 5 sigma bounds "motors off"
I_OFF = 5 * P.current_noise_A + P.current_lsb_A


def fast(name: str, **kw):
    """The named protocol at 1 Hz for one period: the same programme shape, 30x shorter."""
    if name.startswith(("normal_", "in_plane", "out_of_plane")):
        kw = {"frequency": 1.0, "periods": 1, **kw}
    return make_protocol(name, **kw)


def homed(**kw) -> SimDriver:
    limits = kw.pop("limits", None)
    d = SimDriver(limits=limits)
    d.connect(**kw)
    d.home()
    return d


def collect(blocks):
    blocks = list(blocks)
    return {
        c: np.concatenate([getattr(b, c) for b in blocks])
        for c in (
            "time_s",
            "motor_position",
            "motor_current",
            "motor_force",
            "tip_position",
            "tip_force",
            "flags",
        )
    }


def test_registry_gives_the_sim_driver() -> None:
    d = registry.create("skinkit.drivers", "sim")
    assert d.name == "sim"


def test_home_finds_contact_at_about_10_mN() -> None:
    d = homed()
    dev = d.transport.device
    # contact is declared on the first F/T reading >= 10 mN: 2 resolution steps (11.6 mN)
    assert 0.010 <= dev.last_fz <= 0.010 + 3 * P.ft_force_resolution_N
    # zero position is 1 mm (the simulated gap) above the home pose, within the
    # approach step and the noise (10 um p-p)
    np.testing.assert_allclose(d.q_zero, np.full(3, d.geometry.home_m + 0.001), atol=30e-6)


@pytest.mark.parametrize(
    "name,direction",
    [
        ("normal_indentation", (0, 0, 1)),
        ("in_plane_030", (np.cos(np.pi / 6), np.sin(np.pi / 6), 0)),
        ("normal_retraction", (0, 0, -1)),
        (
            "out_of_plane_285",
            (np.cos(np.deg2rad(285)) / np.sqrt(2), np.sin(np.deg2rad(285)) / np.sqrt(2), 1 / np.sqrt(2)),
        ),
    ],
)
def test_trajectory_protocols_follow_their_direction(name: str, direction) -> None:
    d = homed()
    r = collect(d.run(fast(name)))
    tip = r["tip_position"]
    k = int(np.argmax(np.linalg.norm(tip, axis=1)))
    # peak of the one-sided sine is 1.5 mm along the protocol direction. PID bandwidth is
    # ~64 Hz, so a 1 Hz sine lags by ~A f/f_bw ~ 12 um; noise is 10 um p-p: 50 um bound.
    np.testing.assert_allclose(tip[k], 1.5e-3 * np.asarray(direction), atol=50e-6)
    assert d.last_run.lost == 0 and d.last_run.received == r["time_s"].size
    assert np.all(r["flags"] & FLAG_LIMIT == 0)


def test_samples_carry_sensor_resolution_and_force_constant() -> None:
    d = homed()
    r = collect(d.run(fast("normal_indentation")))
    # F/T force quantised to the Nano17's 5.8 mN resolution
    steps = r["tip_force"] / P.ft_force_resolution_N
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    # motor force = force constant(position) x current (thesis Figure 3-16)
    np.testing.assert_allclose(r["motor_force"], P.force_constant(r["motor_position"]) * r["motor_current"])
    # camera triggers at 1 Hz on a 1 s run: at t = 0 (and possibly the last sample at 1 s)
    trig = r["time_s"][(r["flags"] & FLAG_CAMERA_TRIGGER) > 0]
    assert trig[0] == 0.0 and np.all(np.diff(trig) >= 1.0 - 1e-9)


def test_potentiometer_noise_is_about_10_um_peak_to_peak() -> None:
    dev = Device(seed=3)
    dev.hold()
    dev.load("position", 100.0, np.full((101, 3), 0.005))
    dev.start()
    for _ in range(10):
        dev.heartbeat()
        dev.advance(1000)
    q = dev.drain()[200:, 2:5]  # after the move to 5 mm has settled
    # the PID holds the arm within ~1 um, so the reading's spread is the sensor's: sigma =
    # pp/6; the sample std of ~800 Gaussian values is within 15 % of sigma (5 sigma of its
    # sampling error, 1/sqrt(2n) = 2.5 %), plus the ADC step.
    sd = q.std(axis=0)
    assert np.all(np.abs(sd - P.pot_sigma_m) < 0.15 * P.pot_sigma_m + P.adc_span_m[1] / 65535)


def test_force_programme_runs_open_loop() -> None:
    d = homed()
    p = make_protocol("stochastic_full_scale", duration=1.0)
    r = collect(d.run(p))
    # measured motor forces follow the programme's range 0..3.5 N (current noise 0.5 mA x 5.8 N/A)
    assert r["motor_force"].min() > -0.05 and r["motor_force"].max() < 3.5 + 0.05
    assert r["tip_position"][:, 2].max() > 0.5e-3  # ~10 N on a 3 kN/m skin pushes in


def test_wiener_skin_is_stiffer_at_large_indentation() -> None:
    out = {}
    for skin in ("kelvin-voigt", "wiener"):
        d = homed(skin=skin)
        r = collect(d.run(fast("normal_indentation", peak_to_peak=3e-3)))
        z, f = r["tip_position"][:, 2], r["tip_force"][:, 2]
        out[skin] = (f[z > 2.8e-3].mean() / 2.9e-3, f[(z > 0.9e-3) & (z < 1.1e-3)].mean() / 1e-3)
    kv_hi, kv_lo = out["kelvin-voigt"]
    w_hi, w_lo = out["wiener"]
    assert abs(kv_hi - kv_lo) / kv_lo < 0.2  # linear: same secant stiffness (damping aside)
    assert w_hi / w_lo > 1.5  # cubic term: k3 w^2 / k1 = 2e8 * 8.4e-6 / 2000 ~ 0.84 at 2.9 mm


# -- safety ----------------------------------------------------------------------------
def test_travel_limit_refused_before_motion() -> None:
    d = homed()
    dev = d.transport.device
    tick = dev.tick
    with pytest.raises(F.LimitRefused, match=r"travel limit on motor \d at t=.*limit 10.0000 mm"):
        d.run(fast("normal_indentation", peak_to_peak=8e-3))
    assert dev.tick == tick and dev.programme is None  # nothing loaded, nothing moved


def test_peak_and_continuous_force_refused_before_motion() -> None:
    d = homed()
    with pytest.raises(F.LimitRefused, match="peak motor force limit on motor 1.*limit 13.3 N"):
        d.run(make_protocol("stochastic_full_scale", duration=1.0, force_max=20.0))
    with pytest.raises(F.LimitRefused, match="continuous motor force limit on motor 1"):
        d.run(make_protocol("stochastic_full_scale", duration=30.0, force_max=12.0))


def test_firmware_refuses_what_a_host_lets_through() -> None:
    dev = Device()
    ev = dev.load("position", 100.0, np.full((10, 3), 0.0125))
    assert ev is not None and ev.kind == "refused" and ev.fault.code == F.TRAVEL
    assert dev.programme is None


def test_limit_exceeded_during_motion_stops_within_one_control_period(tmp_path) -> None:
    # a 1 N tip-force limit passes the pre-check (it cannot know the skin) and trips in motion
    d = homed(limits=Limits(tip_force_N=1.0), decimation=1)
    path = tmp_path / "fault.h5"
    with create_experiment(path) as exp:
        with pytest.raises(F.DeviceFault, match="tip force limit"):
            run_protocol(d, fast("normal_indentation"), exp)
    dev = d.transport.device
    assert dev.off_tick - dev.fault_tick <= 1  # zero current from the next control tick on
    rec = open_experiment(path).read_record("normal_indentation")
    assert rec.n_samples == d.last_run.received  # every sample received is in the file
    k = int(np.argmax(rec.flags & FLAG_LIMIT > 0))
    assert np.linalg.norm(rec.tip_force[k]) > 1.0
    assert np.all(np.abs(rec.motor_current[k + 1 :]) < I_OFF)
    assert open_experiment(path).record_info("normal_indentation")["complete"] is False


def test_stuck_sensor_trips_the_device() -> None:
    d = homed(injection=Injection(stuck_motor=2, stuck_after_s=0.2))
    with pytest.raises(F.DeviceFault, match="position sensor stuck on motor 2") as info:
        collect(d.run(fast("normal_indentation")))
    # detected after stuck_ticks identical readings (5 ms)
    assert 0.2 <= info.value.fault.time_s <= 0.2 + 1.1 * Limits().stuck_ticks / P.control_rate_hz
    assert not d.transport.device.energised


def test_emergency_stop_from_the_host() -> None:
    d = homed()
    blocks = []
    with pytest.raises(F.DeviceFault, match="emergency stop"):
        for b in d.run(fast("normal_indentation")):
            blocks.append(b)
            if len(blocks) == 3:
                d.emergency_stop()
    flags = np.concatenate([b.flags for b in blocks])
    cur = np.concatenate([b.motor_current for b in blocks])
    assert np.any(flags & FLAG_ESTOP)
    assert np.all(np.abs(cur[np.argmax(flags & FLAG_ESTOP > 0) + 1 :]) < I_OFF)


def test_watchdog_deenergises_a_silent_host() -> None:
    dev = Device()
    dev.hold()
    events = run_device_until(dev, lambda e: False, 0.1)  # with heartbeats: no trip
    assert dev.energised and not events
    dev.advance(int(1.2 * Limits().watchdog_s * P.control_rate_hz))  # silent beyond the watchdog
    dev.advance(10)
    ev = dev.take_events()
    assert not dev.energised and ev and ev[0].fault.code == F.WATCHDOG


class FakeWall:
    """A wall clock the test moves by hand [s]."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


WD_TICKS = int(round(Limits().watchdog_s * P.control_rate_hz))


def test_watchdog_counts_device_ticks_not_the_wall_clock_of_a_stalled_device() -> None:
    wall = FakeWall()
    dev = Device(clock=wall)
    dev.hold()
    wall.t += 60.0  # the emulator descheduled for a minute: no tick passed, nobody was silent
    dev.advance(100)
    assert dev.energised and not dev.take_events()
    assert dev.host_silence_s() == pytest.approx(100 / P.control_rate_hz)


def test_a_device_ahead_of_the_wall_clock_waits_for_the_host_then_trips_on_both_clocks() -> None:
    wall = FakeWall()
    dev = Device(clock=wall)
    dev.hold()
    dev.advance(WD_TICKS)  # fast-forward: a watchdog time of device time in no wall time
    assert not dev.waiting_for_host()  # exactly the limit is not past it
    dev.advance(100)
    assert dev.waiting_for_host() and dev.energised  # past it on the device clock only
    dev.check_watchdog()
    assert dev.energised
    dev.heartbeat()  # the host speaks: the device may run on
    assert not dev.waiting_for_host()
    dev.advance(WD_TICKS + 100)
    wall.t += Limits().watchdog_s + 0.01  # ... and now silent on the wall clock too
    dev.check_watchdog()
    ev = dev.take_events()
    assert not dev.energised and not dev.waiting_for_host()  # de-energised: nothing to wait for
    assert ev and ev[0].fault.code == F.WATCHDOG
    assert ev[0].fault.value == pytest.approx(Limits().watchdog_s + 0.01)  # the smaller silence


def test_a_device_held_by_its_host_counts_the_silence_on_the_wall_clock() -> None:
    wall = FakeWall()
    dev = Device(clock=wall)
    dev.hold()
    dev.advance(100)
    wall.t += 0.4  # held (the host does not read): no tick passes, the wall clock counts
    dev.check_watchdog(held=True)
    assert dev.energised
    wall.t += 0.2
    dev.check_watchdog(held=True)
    ev = dev.take_events()
    assert not dev.energised and ev[0].fault.code == F.WATCHDOG
    assert ev[0].fault.value == pytest.approx(0.6)  # the silence that tripped it, not the ticks'


def test_runner_writes_a_complete_record(tmp_path) -> None:
    d = homed()
    path = tmp_path / "run.h5"
    p = fast("in_plane_090")
    with create_experiment(path) as exp:
        s = run_protocol(d, p, exp, progress=True)
    rec = open_experiment(path).read_record("in_plane_090")
    assert s.samples == rec.n_samples == 1000 and s.lost == 0 and s.fault is None
    assert rec.protocol.parameters["frequency"] == 1.0
    info = open_experiment(path).record_info("in_plane_090")
    assert info["complete"] is True


def test_run_before_home_is_refused() -> None:
    d = SimDriver()
    d.connect()
    with pytest.raises(Exception, match="home"):
        d.run(fast("normal_indentation"))


def test_thermal_filter_matches_the_device_recurrence() -> None:
    from skinkit_hardware.safety import thermal_rms

    rng = np.random.default_rng(0)
    f = rng.normal(2, 1, (3000, 3))
    a = np.exp(-1 / (1000 * 0.05))  # tau 50 ms: several closed-form chunks of 2500 samples
    th = np.zeros(3)
    ref = np.empty_like(f)
    for k in range(f.shape[0]):
        th = a * th + (1 - a) * f[k] ** 2
        ref[k] = th
    np.testing.assert_allclose(thermal_rms(f, 1000, 0.05), np.sqrt(ref), rtol=1e-10)
