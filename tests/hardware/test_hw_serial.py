"""The serial driver end to end against the emulator process on a real pseudo-terminal:
equivalence with ``sim``, the wire format, and fault injection."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytestmark = pytest.mark.needs_hardware
pytest.importorskip("skinkit_hardware")

from skinkit_hardware import faults as F  # noqa: E402
from skinkit_hardware.drivers.serial import SerialDriver, SerialTransport  # noqa: E402
from skinkit_hardware.drivers.sim import SimDriver  # noqa: E402
from skinkit_hardware.params import Limits, RobotParameters  # noqa: E402
from skinkit_hardware.testing import EmulatorProcess, kill_after_samples  # noqa: E402
from skinkit_hardware.wire import serial_codec as S  # noqa: E402

from skinkit.acquisition import make_protocol, run_protocol  # noqa: E402
from skinkit.schemas.robot import FLAG_LIMIT, FLAG_SAMPLES_LOST  # noqa: E402
from skinkit.store import create_experiment, open_experiment  # noqa: E402

P = RobotParameters()
I_OFF = 5 * P.current_noise_A + P.current_lsb_A  # 5 sigma of the current-sense noise
FAST = ("--speed", "0", "--baud", "0")


def proto(periods: int = 1, **kw):
    return make_protocol("normal_indentation", frequency=1.0, periods=periods, **kw)


def stack(blocks, c):
    return np.concatenate([getattr(b, c) for b in blocks])


def serial_driver(emu, **kw) -> SerialDriver:
    d = SerialDriver(limits=kw.pop("limits", None))
    d.connect(port=emu.address, **kw)
    d.home()
    return d


def test_frames_round_trip_and_resynchronise_after_corruption() -> None:
    send = S.Sender()
    rng = np.random.default_rng(0)
    rows = np.zeros((40, 15))
    rows[:, 0] = np.arange(40)
    rows[:, 1] = np.arange(40) * 10
    rows[:, 2:5] = (
        P.adc_span_m[0] + rng.integers(0, 65535, (40, 3)) * (P.adc_span_m[1] - P.adc_span_m[0]) / 65535
    )
    rows[:, 8:11] = rng.integers(-2000, 2000, (40, 3)) * P.ft_force_resolution_N
    frames = [f for _, f in S.encode_samples(send, rows, P)]
    bad = bytearray(frames[0])
    bad[10] ^= 0xFF
    reader = S.FrameReader()
    got = reader.feed(bytes(bad) + b"\x00\xa5" + frames[1])
    assert reader.corrupted == 1 and len(got) == 1
    back = S.decode_samples(got[0][2], P)
    np.testing.assert_allclose(back, rows[32:], atol=1e-12)  # counts are exact: no added quantisation
    assert reader.seq_gaps == 0  # the first frame seen starts the sequence


def test_serial_records_equal_sim_within_sensor_noise() -> None:
    p = proto()
    sim = SimDriver()
    sim.connect()
    sim.home()
    a = list(sim.run(p))
    with EmulatorProcess("serial", *FAST) as emu:
        d = serial_driver(emu)
        b = list(d.run(p))
        d.disconnect()
    np.testing.assert_array_equal(stack(a, "time_s"), stack(b, "time_s"))
    # two runs differ only in their noise realisation (the emulator's device idles in real
    # time before the run). Each arm reading carries sigma = 10 um / 6; the difference of two
    # readings through the ~unit-gain kinematics stays below 4 x sqrt(2) sigma x 3 arms < 30 um.
    assert np.abs(stack(a, "tip_position") - stack(b, "tip_position")).max() < 30e-6
    # force: the skin (3 kN/m) times that position difference, plus 2 resolution steps
    assert np.abs(stack(a, "tip_force") - stack(b, "tip_force")).max() < 3000 * 30e-6 + 2 * 5.8e-3
    assert d.last_run.lost == 0 and d.last_run.received == stack(a, "time_s").size


def test_emulator_killed_mid_protocol_keeps_every_sample(tmp_path) -> None:
    path = tmp_path / "killed.h5"
    with EmulatorProcess("serial", "--speed", "1", "--baud", "0") as emu:
        d = serial_driver(emu)
        kill_after_samples(d, emu)
        with create_experiment(path) as exp:
            with pytest.raises(F.DeviceFault, match="serial: (link lost|no data)"):
                run_protocol(d, proto(periods=5), exp)
        received = d.last_run.received
        d.disconnect()
    assert received > 0
    rec = open_experiment(path).read_record("normal_indentation")
    assert rec.n_samples == received
    assert open_experiment(path).record_info("normal_indentation")["complete"] is False


def test_dropped_and_corrupted_frames_are_counted_and_stored(tmp_path) -> None:
    path = tmp_path / "lossy.h5"
    with EmulatorProcess(
        "serial", *FAST, "--drop-rate", "0.05", "--corrupt-rate", "0.05", "--seed", "3"
    ) as emu:
        d = serial_driver(emu)
        with create_experiment(path) as exp:
            s = run_protocol(d, proto(periods=2), exp)
        st = d.last_run
        d.disconnect()
    assert st.lost > 0 and st.corrupted_frames > 0
    assert st.received + st.lost == st.generated  # nothing disappears silently
    rec = open_experiment(path).read_record("normal_indentation")
    assert rec.n_samples == st.received == s.samples
    assert open_experiment(path).record_info("normal_indentation")["extra"]["samples_lost"] == st.lost
    # every gap is flagged on the sample after it and visible in the device time stamps
    gaps = np.round(np.diff(rec.time_s) * P.control_rate_hz / 10).astype(int) - 1
    head = round(rec.time_s[0] * 1000)  # samples lost before the first one received
    tail = st.generated - 1 - round(rec.time_s[-1] * 1000)  # ... and after the last one
    assert head + gaps.sum() + tail == st.lost
    assert np.count_nonzero(rec.flags & FLAG_SAMPLES_LOST) == np.count_nonzero(gaps) + (rec.time_s[0] > 0)


def test_stuck_sensor_over_serial() -> None:
    with EmulatorProcess("serial", *FAST, "--stuck-motor", "1", "--stuck-after", "0.3") as emu:
        d = serial_driver(emu)
        with pytest.raises(F.DeviceFault, match="position sensor stuck on motor 1"):
            list(d.run(proto()))
        d.disconnect()


def test_silent_host_trips_the_watchdog() -> None:
    with EmulatorProcess("serial", "--speed", "1", "--baud", "0") as emu:
        d = serial_driver(emu, heartbeat_thread=False)
        blocks = []
        with pytest.raises(F.DeviceFault, match=r"watchdog \(host silent\)") as exc:
            for b in d.run(proto(periods=3)):
                blocks.append(b)
                if len(blocks) == 2:
                    # the host stops talking but keeps reading, so the trip is seen whenever it
                    # comes: the watchdog counts device time, which a loaded machine slows down
                    d.transport.heartbeat_s = float("inf")
        d.disconnect()
    assert_silence_within_a_burst(exc.value.fault)
    flags, cur = stack(blocks, "flags"), stack(blocks, "motor_current")
    k = int(np.argmax(flags & FLAG_LIMIT > 0))
    assert flags[k] & FLAG_LIMIT and np.all(np.abs(cur[k + 1 :]) < I_OFF)


@pytest.mark.realtime
def test_at_speed_1_the_watchdog_trips_within_its_time_of_wall_time() -> None:
    """What the watchdog protects in real use, on the wall clock: an emulator that keeps real
    time (an idle machine) de-energises within the watchdog time of the host's last word. The
    budget: the last heartbeat went out up to 50 ms before the host fell silent, then 0.5 s of
    silence, one 10 ms step, 20 ms of post-fault samples and the link; 0.2 s covers them with room."""
    wd = Limits().watchdog_s
    with EmulatorProcess("serial", "--speed", "1", "--baud", "0") as emu:
        d = serial_driver(emu, heartbeat_thread=False)
        t_silent = None
        with pytest.raises(F.DeviceFault, match=r"watchdog \(host silent\)"):
            for _ in d.run(proto(periods=3)):
                if t_silent is None:
                    d.transport.heartbeat_s = float("inf")
                    t_silent = time.monotonic()
        elapsed = time.monotonic() - t_silent
        d.disconnect()
    assert wd - 0.05 < elapsed < wd + 0.2


def assert_silence_within_a_burst(fault: F.Fault) -> None:
    """The silence a watchdog trip reports [s]: over the limit, by at most 10 ms -- the device
    checks it every 10 ms step of its own time and never steps further past the limit (the
    smaller of its silence and the wall clock's is the one reported)."""
    wd = Limits().watchdog_s
    assert fault.code == F.WATCHDOG and wd < fault.value <= wd + 0.01 + 1e-9


def test_limits_over_serial_refused_before_motion_and_stopped_in_motion() -> None:
    with EmulatorProcess("serial", *FAST) as emu:
        d = serial_driver(emu, decimation=1, limits=Limits(tip_force_N=1.0))
        with pytest.raises(F.LimitRefused, match="travel limit on motor"):
            d.run(proto(peak_to_peak=8e-3))
        blocks = []
        with pytest.raises(F.DeviceFault, match="tip force limit"):
            for b in d.run(proto()):
                blocks.append(b)
        flags, cur = stack(blocks, "flags"), stack(blocks, "motor_current")
        k = int(np.argmax(flags & FLAG_LIMIT > 0))
        # decimation 1 streams every control tick: the tick after the trip has no current
        assert np.all(np.abs(cur[k + 1 :]) < I_OFF)
        # the firmware refuses an over-travel programme even when the host does not check
        t = d.transport
        t.send("clear")
        t.send("load", mode="position", rate_hz=100.0, setpoints=np.full((10, 3), 0.0125))
        events = []
        t_end = time.monotonic() + 10
        while not events and time.monotonic() < t_end:
            events += t.receive(0.05)[1]
        assert events[0].kind == "refused" and events[0].fault.code == F.TRAVEL
        d.disconnect()


def test_missing_port_is_a_clear_error() -> None:
    with pytest.raises(F.DeviceFault, match="cannot open port"):
        SerialTransport("/dev/does-not-exist", 115200, P, heartbeat_thread=False)



def throttle(pid: int, seconds: float, run_s: float = 0.002, stop_s: float = 0.098) -> None:
    """Let process ``pid`` run ``run_s`` out of every ``run_s + stop_s`` [s] (SIGSTOP/SIGCONT)
    for ``seconds``: a starved process, the worst a loaded machine does to it, made certain."""
    import os
    import signal

    t_end = time.monotonic() + seconds
    try:
        while time.monotonic() < t_end:
            os.kill(pid, signal.SIGSTOP)
            time.sleep(stop_s)
            os.kill(pid, signal.SIGCONT)
            time.sleep(run_s)
    finally:
        os.kill(pid, signal.SIGCONT)


def test_a_starved_emulator_never_blames_the_host() -> None:
    """The emulator given 2 % of a CPU for the first 3 s of a run (its device then runs ~20x
    slower than real time and catches up in bursts of 5 x 10 ms between reads of the link).
    The watchdog counts the device's own ticks, and the link is read between bursts, so a
    starved emulator never takes its own stall for host silence (on wall time it did: 0.6 s
    of 'silence' while the live host's heartbeats sat unread). The run completes, nothing lost."""
    import threading

    with EmulatorProcess("serial", "--speed", "1", "--baud", "0") as emu:
        d = serial_driver(emu)
        starve = threading.Thread(target=throttle, args=(emu.proc.pid, 3.0), daemon=True)
        starve.start()
        try:
            blocks = list(d.run(proto()))
        finally:
            starve.join()
        st = d.last_run
        d.disconnect()
    assert st.fault is None and st.lost == 0
    assert st.received == st.generated == stack(blocks, "time_s").size
