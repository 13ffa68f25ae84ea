"""The device model reproduces a recorded run bit for bit.

Ten short scenarios with fixed seeds drive :class:`~skinkit_hardware.device.Device` directly
(no host code in the way) through every branch of its control tick: a position programme
with streaming and camera triggers pressing into the skin, an open-loop force programme,
homing (to contact, and without a skin until the travel limit), an injected stuck sensor, the
tip-force, travel, continuous-force and watchdog trips, and an emergency stop on the Wiener
skin. Every streamed row, every event (with its fault) and the final state are compared with
the recording in ``data/device_regression.npz``.

Why exact equality: the recording was made by the same float operations in the same order
(the refactor of ``Device.advance`` into named steps moves code, it does not change one
arithmetic expression), and IEEE 754 arithmetic on doubles is deterministic, so any
difference, even in the last bit, means the tick computes something else. Quantisation
(ADC counts, F/T steps) and the trips would turn a last-bit difference into a visible one
anyway, so a tolerance would hide nothing useful.

Platforms: the few transcendental values the model uses (``math.exp`` once per run, numpy's
trigonometry in the kinematics, the seeded normal stream) come from the platform's libm and
numpy, which may differ in the last bit between machines or numpy versions. Each recording
stores a fingerprint of those, and the test compares with the recording whose fingerprint is
this platform's; where none is, the run cannot be bit-identical for reasons outside the device
model, so the test skips and says so rather than compare. ``device_regression.npz`` was
recorded before the refactor; numpy 2.4.6's trigonometry differs from its platform's in the
last bits, so ``device_regression_<fingerprint>.npz`` was added on that platform (2026-11-24)
by the code that had reproduced the first recording bit for bit on its own platform.

Regenerate after an intended change of the physics (never to make a refactor pass; it rewrites
this platform's recording, or adds one for a new platform — the others must then be regenerated
on theirs or removed):
``SKINKIT_RECORD_DEVICE=1 .venv/bin/python -m pytest tests/hardware/test_device_regression.py``.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.needs_hardware

pytest.importorskip("skinkit_hardware")

from skinkit_hardware import faults as F  # noqa: E402
from skinkit_hardware.device import COLUMNS, Device, Event, Injection, run_device_until  # noqa: E402
from skinkit_hardware.kinematics import Geometry, forward_and_jacobian  # noqa: E402
from skinkit_hardware.params import Limits, RobotParameters  # noqa: E402
from skinkit_hardware.skin import NoSkin, WienerSkin  # noqa: E402

from skinkit.acquisition import FLAG_CAMERA_TRIGGER, FLAG_CONTACT, FLAG_ESTOP, FLAG_LIMIT  # noqa: E402

#: every platform's recording: the first (``device_regression.npz``) and one per platform added since
RECORDINGS = Path(__file__).parent / "data"
RECORD = os.environ.get("SKINKIT_RECORD_DEVICE") == "1"
KINDS = ("home_done", "run_end", "fault", "refused")
MODES = ("idle", "hold", "homing", "running", "fault")
P = RobotParameters()


# -- driving ---------------------------------------------------------------------------
class Run:
    """A device with everything it streamed and reported so far."""

    def __init__(self, dev: Device) -> None:
        self.dev = dev
        self.rows: list[np.ndarray] = []
        self.events: list[Event] = []

    def advance(self, ticks: int, block: int = 500, heartbeat: bool = True) -> None:
        """Advance ``ticks`` control periods in blocks of ``block``, as a host polling would."""
        while ticks > 0:
            n = min(block, ticks)
            if heartbeat:
                self.dev.heartbeat()
            self.dev.advance(n)
            self.collect()
            ticks -= n

    def collect(self) -> None:
        """Take the rows and events the device holds."""
        self.rows.append(self.dev.drain())
        self.events += self.dev.take_events()


def _press(q0: np.ndarray, depth_m: float, rate_hz: float = 100.0, duration_s: float = 1.0) -> np.ndarray:
    """Arm setpoints ``(N, 3)`` [m]: from ``q0`` up to the home pose, then a raised cosine that
    lifts all arms ``depth_m`` (the skin is 1 mm above the home tip) with a small in-plane wobble."""
    n = int(rate_hz * duration_s) + 1
    t = np.arange(n) / rate_hz
    home = Geometry().home_m
    ramp = np.clip(t / 0.2, 0.0, 1.0)[:, None]
    q = q0[None, :] + ramp * (home - q0[None, :])
    s = np.clip((t - 0.2) / (duration_s - 0.2), 0.0, 1.0)
    lift = 0.5 * depth_m * (1.0 - np.cos(2 * np.pi * s))
    wob = 2e-4 * np.sin(2 * np.pi * 3 * s) * (s > 0)
    return q + lift[:, None] + wob[:, None] * np.array([1.0, -0.5, -0.5])


def _held(dev: Device, ticks: int = 200) -> Run:
    run = Run(dev)
    dev.hold()
    run.advance(ticks)
    return run


def _start(run: Run, mode: str, rate_hz: float, sp: np.ndarray, trigger_s: float = 0.0) -> None:
    ev = run.dev.load(mode, rate_hz, sp, trigger_s)
    assert ev is None, ev  # the scenario must pass the firmware's pre-check
    run.dev.start()


def position() -> Run:
    """Position programme into the skin, streamed with camera triggers, uneven polling blocks."""
    run = _held(Device(seed=11, decimation=20))
    _start(run, "position", 100.0, _press(np.array(run.dev.xf), 2.5e-3, duration_s=1.2), 0.1)
    run.advance(13_000, block=337)
    return run


def force() -> Run:
    """Open-loop force programme (a smoothed random walk around the gravity load), decimation 13."""
    rng = np.random.default_rng(5)
    n = 301
    walk = np.cumsum(rng.normal(0, 0.03, (n, 3)), axis=0)
    f = P.mass_kg * P.gravity_m_s2 + 0.2 + 0.25 * np.sin(np.linspace(0, 3 * np.pi, n))[:, None] + walk
    run = Run(Device(seed=12, decimation=13))
    _start(run, "force", 500.0, np.clip(f, 0.0, 0.7))
    run.advance(6_500, block=250)
    return run


def homing() -> Run:
    """Homing to contact, then a short position run at decimation 9 with ~30 ms triggers."""
    dev = Device(seed=13, decimation=9)
    run = Run(dev)
    dev.home()
    run.events += run_device_until(dev, lambda e: any(x.kind == "home_done" for x in e), 5.0)
    run.collect()
    sp = np.linspace(dev.xf, np.array(dev.xf) + 5e-4, 31)
    _start(run, "position", 100.0, sp, 0.03)
    run.advance(3_500)
    return run


def homing_no_contact() -> Run:
    """Homing in free air rises until the travel limit trips it (NO_CONTACT)."""
    dev = Device(seed=14, skin=NoSkin())
    run = Run(dev)
    dev.home(speed_m_s=0.02)
    run.events += run_device_until(dev, lambda e: any(x.kind == "fault" for x in e), 3.0)
    run.collect()
    return run


def stuck() -> Run:
    """Motor 2's sensor sticks 0.2 s into the run: trip, post-fault rows, fault event."""
    run = _held(Device(seed=15, injection=Injection(stuck_motor=2, stuck_after_s=0.2)))
    _start(run, "position", 100.0, _press(np.array(run.dev.xf), 1.5e-3))
    run.advance(5_000)
    return run


def tip_trip() -> Run:
    """A 1 N tip-force limit trips while pressing into the skin, every third tick streamed."""
    run = _held(Device(seed=16, limits=Limits(tip_force_N=1.0), decimation=3))
    _start(run, "position", 100.0, _press(np.array(run.dev.xf), 4.0e-3, duration_s=0.6))
    run.advance(8_000, block=1000)
    return run


def travel() -> Run:
    """A programme that ends at the travel limit: sensor noise reads past it and trips."""
    run = _held(Device(seed=17))
    q0 = np.array(run.dev.xf)
    top = np.array([Limits().travel_m[1], 0.006, 0.006])
    sp = np.concatenate([np.linspace(q0, top, 31), np.repeat(top[None, :], 50, axis=0)])
    _start(run, "position", 100.0, sp)
    run.advance(8_000)
    return run


def thermal() -> Run:
    """A low continuous-force limit the programme passes and the skin's load exceeds."""
    run = _held(Device(seed=18, limits=Limits(continuous_force_N=0.6), decimation=50))
    _start(run, "position", 100.0, _press(np.array(run.dev.xf), 3.0e-3, duration_s=2.0))
    run.advance(20_000, block=1000)
    return run


def estop_wiener() -> Run:
    """Emergency stop mid-run on the Wiener skin; the rows after it show the motors off."""
    run = _held(Device(seed=19, skin=WienerSkin(), decimation=20))
    _start(run, "position", 100.0, _press(np.array(run.dev.xf), 2.0e-3), 0.05)
    run.advance(7_000, block=250)
    run.dev.estop()
    run.advance(1_000, block=250)
    return run


def watchdog() -> Run:
    """Holding with a silent host: the watchdog de-energises at the next advance."""
    run = _held(Device(seed=20))
    run.advance(int(1.2 * Limits().watchdog_s * P.control_rate_hz), block=6_000, heartbeat=False)
    run.advance(10, heartbeat=False)
    return run


SCENARIOS: dict[str, Callable[[], Run]] = {
    f.__name__: f
    for f in (position, force, homing, homing_no_contact, stuck, tip_trip, travel, thermal, estop_wiener)
}
SCENARIOS["watchdog"] = watchdog


# -- recording -------------------------------------------------------------------------
def _arrays(run: Run) -> dict[str, np.ndarray]:
    """Rows, events and final state of a run as arrays."""
    d = run.dev
    rows = np.concatenate(run.rows) if run.rows else np.zeros((0, len(COLUMNS)))
    ev = []
    for e in run.events:
        f, q = e.fault or F.Fault(-1), e.q or (math.nan,) * 3
        ev.append(
            (KINDS.index(e.kind), f.code, f.motor, f.value, f.limit, f.time_s, *q, e.generated, e.index)
        )
    state_f = [*d.x, *d.v, *d.integ, *d.xf, *d.th, *d.setpoint, d.last_fz]
    state_i = [d.tick, d.sample_index, d.generated, *d.last_raw, *d.same_raw, d.off_tick, d.fault_tick]
    state_i += [MODES.index(d.mode), int(d.energised), int(d.streaming)]
    return {
        "rows": rows,
        "events": np.array(ev, dtype=float).reshape(-1, 11),
        "state_f": np.array(state_f, dtype=float),
        "state_i": np.array(state_i, dtype=np.int64),
    }


def fingerprint() -> np.ndarray:
    """The platform-dependent values the model uses (module docstring), as floats."""
    g = Geometry()
    q = np.linspace(g.travel_m[0], g.travel_m[1], 9)
    grid = np.stack([q, q[::-1], np.roll(q, 3)], axis=1)
    tip, jac = forward_and_jacobian(grid, g)
    alpha = 1.0 - math.exp(-2 * math.pi * P.derivative_filter_hz * P.dt)
    noise = np.random.default_rng(0).standard_normal(16)
    return np.concatenate([tip.ravel(), jac.ravel(), [alpha], noise])


def _platform_recording(fp: np.ndarray) -> Path | None:
    """The recording made on a platform with fingerprint ``fp``, if there is one."""
    for path in sorted(RECORDINGS.glob("device_regression*.npz")):
        with np.load(path) as z:
            if np.array_equal(z["fingerprint"], fp):
                return path
    return None


def record() -> Path:
    """Run every scenario and write this platform's recording (see the module docstring): the
    file that has this platform's fingerprint, else a new one named after it."""
    fp = fingerprint()
    out = {"fingerprint": fp}
    for name, scenario in SCENARIOS.items():
        for key, a in _arrays(scenario()).items():
            out[f"{name}__{key}"] = a
    path = _platform_recording(fp) or RECORDINGS / (
        f"device_regression_{hashlib.sha256(fp.tobytes()).hexdigest()[:8]}.npz")
    RECORDINGS.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **out)
    return path


@pytest.fixture(scope="module")
def recording() -> dict[str, np.ndarray]:
    if RECORD:
        record()
    path = _platform_recording(fingerprint())
    if path is None:
        pytest.skip(
            "no recording was made on a platform whose libm/numpy trigonometry and normal stream "
            "agree with this one's to the last bit: a bit-for-bit comparison is not meaningful here"
        )
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


# -- tests -----------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_device_reproduces_the_recording_bit_for_bit(name: str, recording: dict[str, np.ndarray]) -> None:
    got = _arrays(SCENARIOS[name]())
    for key, a in got.items():
        want = recording[f"{name}__{key}"]
        assert a.shape == want.shape, f"{name} {key}: shape {a.shape}, recorded {want.shape}"
        same = (a == want) | (np.isnan(a) & np.isnan(want)) if a.dtype.kind == "f" else a == want
        if not same.all():
            at = tuple(np.argwhere(~same)[0])
            pytest.fail(f"{name} {key}: first difference at {at}: {a[at]!r}, recorded {want[at]!r}")


def test_the_scenarios_reach_the_branches_they_name(recording: dict[str, np.ndarray]) -> None:
    """The recording exercises what the scenarios claim (else an equal run would prove little)."""

    def flags(name: str) -> np.ndarray:
        return recording[f"{name}__rows"][:, COLUMNS.index("flags")].astype(int)

    def fault_codes(name: str) -> set[int]:
        ev = recording[f"{name}__events"]
        return {int(c) for k, c in ev[:, :2] if KINDS[int(k)] == "fault"}

    assert np.any(flags("position") & FLAG_CAMERA_TRIGGER) and np.any(flags("position") & FLAG_CONTACT)
    assert recording["position__events"][:, 0].tolist() == [KINDS.index("run_end")]
    assert recording["force__rows"].shape[0] > 0
    assert KINDS.index("run_end") in recording["force__events"][:, 0]
    assert KINDS.index("home_done") in recording["homing__events"][:, 0]
    assert np.any(flags("homing") & FLAG_CAMERA_TRIGGER)
    expected = {
        "homing_no_contact": F.NO_CONTACT,
        "stuck": F.STUCK_SENSOR,
        "tip_trip": F.TIP_FORCE,
        "travel": F.TRAVEL,
        "thermal": F.CONTINUOUS_FORCE,
        "estop_wiener": F.ESTOP,
        "watchdog": F.WATCHDOG,
    }
    for name, code in expected.items():
        assert fault_codes(name) == {code}, name
    for name in ("stuck", "tip_trip", "travel", "thermal"):
        assert np.any(flags(name) & FLAG_LIMIT), name
    assert np.any(flags("estop_wiener") & FLAG_ESTOP)


def _position_in_blocks(block: int) -> dict[str, np.ndarray]:
    run = _held(Device(seed=11, decimation=20))
    _start(run, "position", 100.0, _press(np.array(run.dev.xf), 2.5e-3, duration_s=1.2), 0.1)
    run.advance(13_000, block=block)
    return _arrays(run)


@pytest.mark.parametrize("block", [1_000, 4_096])
def test_what_the_device_does_does_not_depend_on_how_the_host_polls(block: int) -> None:
    """The same run polled in blocks of 337 ticks and of ``block`` ticks — the run ends inside a
    block in both — streams the same rows and ends in the same state, bit for bit: the device's
    behaviour is its own, not the host's (nor the machine load's, which sets a real host's
    blocks). The integrator reset at the end of a run used to take effect only at the next block."""
    a, b = _position_in_blocks(337), _position_in_blocks(block)
    for key in ("rows", "state_f", "state_i"):
        assert np.array_equal(a[key], b[key], equal_nan=True), key
