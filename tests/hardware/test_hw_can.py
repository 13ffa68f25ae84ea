"""The CAN driver: the DBC read by cantools, python-can's virtual bus in one process, the
loopback bridge to the emulator process, equivalence with ``sim``, and fault injection."""

from __future__ import annotations

import threading

import numpy as np
import pytest

pytestmark = pytest.mark.needs_hardware
pytest.importorskip("skinkit_hardware")

import can  # noqa: E402
from skinkit_hardware import faults as F  # noqa: E402
from skinkit_hardware.can_bridge import BridgeError, parse_loopback  # noqa: E402
from skinkit_hardware.can_emulator import CanLinkServer  # noqa: E402
from skinkit_hardware.device import Device, wall_clock  # noqa: E402
from skinkit_hardware.drivers.can import CanDriver  # noqa: E402
from skinkit_hardware.drivers.sim import SimDriver  # noqa: E402
from skinkit_hardware.emulator import serve  # noqa: E402
from skinkit_hardware.params import RobotParameters  # noqa: E402
from skinkit_hardware.testing import EmulatorProcess, kill_after_samples  # noqa: E402
from skinkit_hardware.wire import can_codec as C  # noqa: E402

from skinkit.acquisition import make_protocol, run_protocol  # noqa: E402
from skinkit.schemas.robot import FLAG_SAMPLES_LOST  # noqa: E402
from skinkit.store import create_experiment, open_experiment  # noqa: E402

P = RobotParameters()
FAST = ("--speed", "0", "--bitrate", "0")


def proto(periods: int = 1, **kw):
    return make_protocol("normal_indentation", frequency=1.0, periods=periods, **kw)


def stack(blocks, c):
    return np.concatenate([getattr(b, c) for b in blocks])


def test_dbc_scales_match_the_sensor_model() -> None:
    db = C.database()
    force = db.get_message_by_name("ROBOT_SAMPLE_FORCE").get_signal_by_name("ForceX")
    cur = db.get_message_by_name("ROBOT_SAMPLE_CURRENT").get_signal_by_name("Current1")
    torque = db.get_message_by_name("ROBOT_SAMPLE_TORQUE").get_signal_by_name("TorqueX")
    assert force.scale == pytest.approx(P.ft_force_resolution_N)
    assert cur.scale == pytest.approx(P.current_lsb_A)
    assert torque.scale == pytest.approx(P.ft_torque_resolution_Nm)
    assert all(m.length <= 8 and not m.is_extended_frame for m in db.messages)


def test_samples_survive_the_can_encoding_exactly() -> None:
    rows = np.zeros((3, 15))
    rows[:, 0] = [65535, 65536, 65537]  # the 16-bit index wraps; the host unwraps it
    rows[:, 1] = [10, 20, 30]
    lo, hi = P.adc_span_m
    rows[:, 2:5] = lo + np.array([[1, 2, 3], [40000, 5, 6], [7, 8, 65535]]) * (hi - lo) / 65535
    rows[:, 8:11] = np.array([[1, -2, 300]] * 3) * P.ft_force_resolution_N
    asm = C.SampleAssembler(P)
    asm.last16, asm.base = 65534, 65534
    msgs = [m for frames in C.encode_samples(rows, P) for m in frames]
    back, _ = asm.feed(msgs)
    np.testing.assert_allclose(back, rows, atol=1e-12)


def test_bridge_refuses_non_loopback_addresses() -> None:
    assert parse_loopback("127.0.0.1:5000") == ("127.0.0.1", 5000)
    with pytest.raises(BridgeError, match="not a loopback"):
        parse_loopback("192.168.1.10:5000")
    with pytest.raises(BridgeError, match="not a loopback"):
        parse_loopback("224.0.0.1:5000")  # no multicast either


def test_virtual_bus_in_one_process_matches_sim() -> None:
    link = CanLinkServer(None, 0, 65536, 0.0, 0.0, np.random.default_rng(1), P)
    stop = threading.Event()
    th = threading.Thread(
        target=serve,
        args=(Device(clock=wall_clock, seed=5), link, 0.0, None),
        kwargs={"stop": stop},
        daemon=True,
    )
    th.start()
    try:
        d = CanDriver()
        d.connect(bus=can.Bus(interface="virtual", channel=link.channel))
        d.home()
        b = list(d.run(proto()))
        d.disconnect()
    finally:
        stop.set()
        th.join(5)
        link.close()
    sim = SimDriver()
    sim.connect()
    sim.home()
    a = list(sim.run(proto()))
    np.testing.assert_array_equal(stack(a, "time_s"), stack(b, "time_s"))
    # same bound as for serial: independent 10 um p-p noise on each of 3 arms (< 30 um)
    assert np.abs(stack(a, "tip_position") - stack(b, "tip_position")).max() < 30e-6


def test_can_emulator_process_over_the_loopback_bridge_matches_sim() -> None:
    sim = SimDriver()
    sim.connect()
    sim.home()
    a = list(sim.run(proto()))
    with EmulatorProcess("can", *FAST) as emu:
        d = CanDriver()
        d.connect(port=emu.address)
        d.home()
        b = list(d.run(proto()))
        d.disconnect()
    np.testing.assert_array_equal(stack(a, "time_s"), stack(b, "time_s"))
    assert np.abs(stack(a, "tip_position") - stack(b, "tip_position")).max() < 30e-6
    assert np.abs(stack(a, "tip_force") - stack(b, "tip_force")).max() < 3000 * 30e-6 + 2 * 5.8e-3
    assert d.last_run.lost == 0


def test_can_dropped_frames_are_counted_and_stored(tmp_path) -> None:
    path = tmp_path / "can_lossy.h5"
    with EmulatorProcess("can", *FAST, "--drop-rate", "0.01", "--corrupt-rate", "0.01", "--seed", "2") as emu:
        d = CanDriver()
        d.connect(port=emu.address)
        d.home()
        with create_experiment(path) as exp:
            s = run_protocol(d, proto(), exp)
        st = d.last_run
        d.disconnect()
    # a sample loses one of its 5 frames with p ~ 1 - 0.98^5 ~ 10 %: ~100 of 1000 lost
    assert st.lost > 0 and st.received + st.lost == st.generated
    rec = open_experiment(path).read_record("normal_indentation")
    assert rec.n_samples == s.samples == st.received
    assert np.count_nonzero(rec.flags & FLAG_SAMPLES_LOST) > 0


def test_can_emulator_killed_mid_protocol(tmp_path) -> None:
    path = tmp_path / "can_killed.h5"
    with EmulatorProcess("can", "--speed", "1", "--bitrate", "0") as emu:
        d = CanDriver()
        d.connect(port=emu.address)
        d.home()
        kill_after_samples(d, emu)
        with create_experiment(path) as exp:
            with pytest.raises(F.DeviceFault, match="can: (link lost|no data)"):
                run_protocol(d, proto(periods=5), exp)
        received = d.last_run.received
        d.disconnect()
    assert received > 0
    assert open_experiment(path).read_record("normal_indentation").n_samples == received


def test_can_stuck_sensor_and_watchdog() -> None:
    with EmulatorProcess("can", *FAST, "--stuck-motor", "3", "--stuck-after", "0.2") as emu:
        d = CanDriver()
        d.connect(port=emu.address)
        d.home()
        with pytest.raises(F.DeviceFault, match="position sensor stuck on motor 3"):
            list(d.run(proto()))
        d.disconnect()


def test_can_silent_host_trips_the_watchdog() -> None:
    from skinkit_hardware.params import Limits

    with EmulatorProcess("can", "--speed", "1", "--bitrate", "0") as emu:
        d = CanDriver()
        d.connect(port=emu.address, heartbeat_thread=False)
        d.home()
        blocks = []
        with pytest.raises(F.DeviceFault, match=r"watchdog \(host silent\)") as exc:
            for b in d.run(proto(periods=3)):
                blocks.append(b)
                if len(blocks) == 2:
                    # silent but still reading: the trip comes on the device's clock (see serial)
                    d.transport.heartbeat_s = float("inf")
        d.disconnect()
    wd = Limits().watchdog_s  # checked every 10 ms step of device time, never a step further
    assert exc.value.fault.code == F.WATCHDOG and wd < exc.value.fault.value <= wd + 0.01 + 1e-9
    assert sum(b.n_samples for b in blocks) == d.last_run.received
