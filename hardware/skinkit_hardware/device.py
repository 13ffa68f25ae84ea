"""The device model: the robot's firmware and physics, ticked at the control rate.

One :class:`Device` is what a real controller (the thesis's CompactRIO FPGA) would be: it
holds a preloaded programme in its own memory, runs a PID per arm at 10 kHz (position
mode) or applies a motor-force programme open loop (force mode), enforces the safety
limits every tick, and streams decimated samples. The in-process ``sim`` driver calls it
directly; the emulator process wraps it behind the serial and CAN wire protocols.

Physics per arm (semi-implicit Euler at the control period):
``m a = Kf(x) I - b v - k (x - x_rest) - m g + (J^T f_skin)_i``, with hard stops 0.5 mm
outside the travel range. The skin force acts at the tip; it reaches the arms through the
kinematic Jacobian ``J`` (virtual work), which is refreshed every 100 ticks (the tip moves
<0.1 mm in 10 ms in every protocol, so the linearisation error is below 1 um).

Watchdog: the firmware counts its own control ticks since the last host command and
de-energises after ``Limits.watchdog_s`` of them, as an FPGA counter would. Counting ticks
bounds exactly what the watchdog protects -- how far the robot moves on a dead host -- however
fast the model runs, and a model that is itself late (an emulator descheduled on a loaded
machine) never takes its own stall for host silence: no tick passes while it stalls. With a
wall ``clock`` (the emulator) the host must also have been silent that long on the wall clock,
so a device fast-forwarding faster than real time never blames a host that talks at wall-clock
pace (the emulator then waits for the host instead, see :meth:`Device.waiting_for_host`, and
while it waits the wall clock alone counts the silence).

Samples (one row per streamed tick, see :data:`COLUMNS`): sample index, tick, measured arm
positions [m], measured currents [A], F/T force [N] (force applied by the probe to the
skin), F/T torque [N m], flags (RobotRecord FLAG_* bits, OR-ed over the decimation window).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from skinkit.plugin.drivers import (
    FLAG_CAMERA_TRIGGER,
    FLAG_CONTACT,
    FLAG_ESTOP,
    FLAG_LIMIT,
    FLAG_SATURATED,
)
from skinkit_hardware import faults as F
from skinkit_hardware.kinematics import Geometry, forward, forward_and_jacobian
from skinkit_hardware.params import Limits, RobotParameters
from skinkit_hardware.safety import check_programme
from skinkit_hardware.skin import KelvinVoigtSkin, SkinLoad

COLUMNS = ("index", "tick", "q1", "q2", "q3", "i1", "i2", "i3", "fx", "fy", "fz", "tx", "ty", "tz", "flags")

IDLE, HOLD, HOMING, RUNNING, FAULTED = "idle", "hold", "homing", "running", "fault"


@dataclass
class Injection:
    """Faults injected into the device model for tests (all off by default).

    ``stuck_motor`` (1..3) reads a constant from ``stuck_after_s`` of run time on.
    """

    stuck_motor: int = 0
    stuck_after_s: float = 0.0


@dataclass
class Event:
    """Something the device reports besides samples.

    ``kind``: ``"home_done"`` (``q`` zero arm positions [m]), ``"run_end"``, ``"fault"``
    (``fault``), ``"refused"`` (``fault``, ``index`` of the offending setpoint).
    ``generated`` counts the samples streamed in the run.
    """

    kind: str
    fault: F.Fault | None = None
    q: tuple[float, float, float] | None = None
    generated: int = 0
    index: int = 0


class _TickContext:
    """What the control tick reads, hoisted once per :meth:`Device.advance` call into one
    slotted object: the parameters, limits and derived factors, and the device's state lists.

    The state lists are the device's own (shared, not copied): :meth:`Device.hold` at the end
    of a run zeroes ``integ`` in place, so the rest of that call's ticks see the reset (before,
    they integrated into a stale list until the call ended: when the reset took effect depended
    on the host's polling block size). ``tests/hardware/test_device_regression.py`` pins this.
    """

    __slots__ = (
        "dt", "m", "b", "k", "mg", "rest", "kf0", "droop", "mid", "half", "imax", "fpk",
        "kp", "ki", "kd", "alpha", "th_a", "cont", "cont2", "t_lo", "t_hi", "stop_lo", "stop_hi",
        "a_lo", "nlev", "lsb", "ilsb", "fres", "tres", "plen", "tip_force", "tip_lim2",
        "stuck_ticks", "sig_q", "sig_i", "skin", "so", "inj",
        "x", "v", "integ", "xf", "th", "last_raw", "same_raw",
    )  # fmt: skip

    def __init__(self, dev: Device) -> None:
        p, lim = dev.params, dev.limits
        self.dt = dt = p.dt
        self.m, self.b, self.k = p.mass_kg, p.damping_Ns_per_m, p.stiffness_N_per_m
        self.mg = p.mass_kg * p.gravity_m_s2
        self.rest = p.spring_rest_m
        self.kf0, self.droop = p.force_constant_N_per_A, p.force_constant_droop
        s_lo, s_hi = p.stroke_m
        self.mid, self.half = 0.5 * (s_lo + s_hi), 0.5 * (s_hi - s_lo)
        self.imax = p.peak_current_A
        self.fpk = lim.peak_force_N
        self.kp, self.ki, self.kd = p.kp_N_per_m, p.ki_N_per_m_s, p.kd_Ns_per_m
        self.alpha = 1.0 - math.exp(-2 * math.pi * p.derivative_filter_hz * dt)
        self.th_a = dt / p.thermal_time_constant_s
        self.cont = lim.continuous_force_N
        self.cont2 = lim.continuous_force_N**2
        self.t_lo, self.t_hi = lim.travel_m
        self.stop_lo, self.stop_hi = self.t_lo - 5e-4, self.t_hi + 5e-4
        a_lo, a_hi = p.adc_span_m
        self.a_lo = a_lo
        self.nlev = (1 << p.adc_bits) - 1
        self.lsb = (a_hi - a_lo) / self.nlev
        self.ilsb = p.current_lsb_A
        self.fres, self.tres = p.ft_force_resolution_N, p.ft_torque_resolution_Nm
        self.plen = p.probe_length_m
        self.tip_force = lim.tip_force_N
        self.tip_lim2 = lim.tip_force_N**2
        self.stuck_ticks = lim.stuck_ticks
        self.sig_q, self.sig_i = p.pot_sigma_m, p.current_noise_A
        self.skin = dev.skin
        self.so = tuple(dev.skin_origin.tolist())
        self.inj = dev.injection
        self.x, self.v, self.integ, self.xf, self.th = dev.x, dev.v, dev.integ, dev.xf, dev.th
        self.last_raw, self.same_raw = dev.last_raw, dev.same_raw


@dataclass
class Device:
    """Firmware + physics of one simulated robot. See the module docstring.

    ``clock``: wall clock [s] (monotonic) of a device that runs beside a real host (the
    emulator's is the time of its latest read of the link, so only silence it saw counts),
    used only by the watchdog; None (in-process ``sim``) counts device ticks alone.
    """

    params: RobotParameters = field(default_factory=RobotParameters)
    limits: Limits = field(default_factory=Limits)
    geometry: Geometry = field(default_factory=Geometry)
    skin: SkinLoad = field(default_factory=KelvinVoigtSkin)
    seed: int = 0
    skin_gap_m: float = 0.001
    clock: Callable[[], float] | None = None
    injection: Injection = field(default_factory=Injection)
    decimation: int = 10

    def __post_init__(self) -> None:
        p = self.params
        self.rng = np.random.default_rng(self.seed)
        self.tick = 0
        self.mode = IDLE
        self.energised = False
        # the arms rest where spring and gravity balance, clamped by the hard stops
        rest = p.spring_rest_m - p.mass_kg * p.gravity_m_s2 / p.stiffness_N_per_m
        self.x = [max(rest, self.limits.travel_m[0] - 5e-4)] * 3
        self.v = [0.0, 0.0, 0.0]
        self.integ = [0.0, 0.0, 0.0]
        self.xf = list(self.x)
        self.th = [0.0, 0.0, 0.0]
        self.setpoint = list(self.x)
        self.last_raw = [-1, -1, -1]
        self.same_raw = [0, 0, 0]
        self.tip_home = forward(np.full(3, self.geometry.home_m), self.geometry)
        self.skin_origin = self.tip_home + np.array([0.0, 0.0, self.skin_gap_m])
        self._refresh_kinematics()
        self.programme: np.ndarray | None = None
        self.prog_mode = "position"
        self.prog_rate = 1000.0
        self.trigger_period = 0
        self.run_tick0 = 0
        self.sample_index = 0
        self.generated = 0
        self.post_fault_left = -1
        self.fault: F.Fault | None = None
        self.fault_tick = -1
        self.off_tick = -1
        self.flags_acc = 0
        self.streaming = False
        self.events: list[Event] = []
        self.rows: list[tuple] = []
        self.home_target = 0.0
        self.home_speed = 0.0
        self.home_contact = 0.01
        self.last_fz = 0.0
        self.last_host_tick = 0
        self.last_host_wall = self.clock() if self.clock is not None else 0.0

    # -- time -------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        """Device time [s] since power-on."""
        return self.tick * self.params.dt

    # -- host commands ----------------------------------------------------------------
    def heartbeat(self) -> None:
        """The host is alive (every command counts as one)."""
        self.last_host_tick = self.tick
        if self.clock is not None:
            self.last_host_wall = self.clock()

    def configure(
        self, decimation: int | None = None, watchdog_s: float | None = None, tip_force_N: float | None = None
    ) -> None:
        """Streaming decimation, watchdog time and tip-force limit (a host may only lower the
        firmware's tip-force limit, never raise it)."""
        self.heartbeat()
        if tip_force_N is not None and 0 < tip_force_N < self.limits.tip_force_N:
            self.limits = Limits(**{**self.limits.__dict__, "tip_force_N": float(tip_force_N)})
        if decimation is not None:
            if not 1 <= int(decimation) <= 1000:
                raise ValueError(f"decimation must be 1..1000, got {decimation}")
            self.decimation = int(decimation)
        if watchdog_s is not None:
            self.limits = Limits(**{**self.limits.__dict__, "watchdog_s": float(watchdog_s)})

    def clear(self) -> None:
        """Leave the fault state (motors stay off until the next home or hold)."""
        self.heartbeat()
        if self.mode == FAULTED:
            self.mode = IDLE
            self.fault = None
            self.th = [0.0, 0.0, 0.0]

    def hold(self) -> None:
        """Energise and hold the present measured positions."""
        self.heartbeat()
        if self.mode == FAULTED:
            return
        self.setpoint = list(self.xf)
        # in place: a run ending inside an advance() call resets the integrator that call's
        # remaining ticks use, so the reset does not depend on the host's polling block size
        self.integ[:] = (0.0, 0.0, 0.0)
        self.energised = True
        self.mode = HOLD

    def home(self, contact_N: float = 0.01, speed_m_s: float = 0.002) -> None:
        """Go to the home pose, then rise until the tip force reaches ``contact_N``."""
        self.heartbeat()
        if self.mode == FAULTED:
            return
        self.hold()
        self.mode = HOMING
        self.home_target = self.geometry.home_m
        self.home_contact = float(contact_N)
        self.home_speed = float(speed_m_s)
        self._home_phase = 0

    def load(
        self, mode: str, rate_hz: float, setpoints: np.ndarray, trigger_period_s: float = 0.0
    ) -> Event | None:
        """Store a programme; returns a ``refused`` event (and keeps nothing) if it breaks a limit."""
        self.heartbeat()
        setpoints = np.asarray(setpoints, dtype=float)
        if not rate_hz > 0 or rate_hz > self.params.control_rate_hz:
            return self._refuse(F.Fault(F.BAD_COMMAND, value=rate_hz), 0)
        if self.mode in (RUNNING, FAULTED):
            return self._refuse(F.Fault(F.BAD_COMMAND), 0)
        bad = check_programme(mode, setpoints, rate_hz, self.limits, self.params)
        if bad is not None:
            return self._refuse(*bad)
        self.programme = setpoints
        self.prog_mode = mode
        self.prog_rate = float(rate_hz)
        dec = self.decimation
        period = (
            round(trigger_period_s * self.params.control_rate_hz / dec) * dec if trigger_period_s > 0 else 0
        )
        self.trigger_period = int(period)
        return None

    def _refuse(self, fault: F.Fault, index: int) -> Event:
        ev = Event("refused", fault=fault, index=index)
        self.events.append(ev)
        return ev

    def start(self) -> None:
        """Run the loaded programme from its first setpoint."""
        self.heartbeat()
        if self.mode == FAULTED or self.programme is None:
            self.events.append(Event("refused", fault=self.fault or F.Fault(F.BAD_COMMAND)))
            return
        if self.prog_mode == "position" and not self.energised:
            self.hold()
        self.energised = True
        self.mode = RUNNING
        self.run_tick0 = self.tick
        self.sample_index = 0
        self.generated = 0
        self.flags_acc = 0
        self.streaming = True
        self.post_fault_left = -1
        self.fault_tick = self.off_tick = -1

    def stop(self) -> None:
        """End a run early and hold position."""
        self.heartbeat()
        if self.mode == RUNNING:
            self._end_run()

    def estop(self) -> None:
        """De-energise now (host emergency stop)."""
        self._trip(F.Fault(F.ESTOP, time_s=self._run_time()))

    def disable(self) -> None:
        """De-energise without a fault (end of session)."""
        self.heartbeat()
        self.energised = False
        if self.mode != FAULTED:
            self.mode = IDLE
        self.streaming = False

    def place_arms(self, q_m: Sequence[float]) -> None:
        """Put the arms at rest at positions ``q_m`` ``(3,)`` [m] without simulating the way
        there: a fixture that starts loaded (a load cell or spring sitting on the arms)."""
        self.x = [float(q) for q in q_m]
        self.xf = list(self.x)
        self.v = [0.0, 0.0, 0.0]
        self._refresh_kinematics()

    # -- internals ----------------------------------------------------------------------
    def _run_time(self) -> float:
        return (self.tick - self.run_tick0) * self.params.dt if self.mode == RUNNING else self.time_s

    def _refresh_kinematics(self) -> None:
        q = np.array(self.x)
        # plain floats: numpy scalar arithmetic is several times slower in the tick loop
        tip, self.jac = forward_and_jacobian(q, self.geometry)
        self.tip_ref = tuple(tip.tolist())
        self.jl = tuple(self.jac.ravel().tolist())
        self.q_ref = tuple(q.tolist())

    def _end_run(self) -> None:
        self.streaming = False
        self.events.append(Event("run_end", generated=self.generated))
        self.programme = None
        self.hold()

    def _trip(self, fault: F.Fault) -> None:
        if self.mode == FAULTED:
            return
        self.energised = False
        self.fault = fault
        self.fault_tick = self.tick
        was_streaming = self.streaming
        self.mode = FAULTED
        self.flags_acc |= FLAG_ESTOP if fault.code == F.ESTOP else FLAG_LIMIT
        if was_streaming:
            self.post_fault_left = max(1, int(self.limits.post_fault_s * self.params.control_rate_hz))
        else:
            self.events.append(Event("fault", fault=fault, generated=self.generated))

    def drain(self) -> np.ndarray:
        """Samples streamed since the last call, ``(n, 15)`` (see :data:`COLUMNS`)."""
        rows, self.rows = self.rows, []
        return np.array(rows, dtype=float).reshape(-1, len(COLUMNS))

    def take_events(self) -> list[Event]:
        """The events raised since the last call, oldest first."""
        ev, self.events = self.events, []
        return ev

    def host_silence_s(self) -> float:
        """Host silence [s] as the watchdog counts it: device time since the last command and,
        with a wall ``clock``, the smaller of that and the wall time since it (module docstring)."""
        silent = (self.tick - self.last_host_tick) * self.params.dt
        if self.clock is not None:
            silent = min(silent, self.clock() - self.last_host_wall)
        return silent

    def _past_watchdog_ticks(self) -> bool:
        # integer ticks against the limit in ticks: exactly watchdog_s of silence is not past it
        return self.tick - self.last_host_tick > self.limits.watchdog_s * self.params.control_rate_hz

    def waiting_for_host(self) -> bool:
        """True once the energised device has run past the watchdog time on its own clock since
        the host's last command: a device that may outrun real time (the emulator fast-forwarding)
        stops advancing here until the host speaks or the wall clock confirms the silence and it
        trips (de-energised, it runs on to stream its post-fault samples)."""
        return self.energised and self._past_watchdog_ticks()

    def check_watchdog(self, held: bool = False) -> None:
        """De-energise when the host has been silent longer than the watchdog time: on the
        device's own clock and, with a wall ``clock``, on that one too. ``held``: the device is
        not advancing because it waits on the host (its link backed up, or a watchdog time
        ahead of it), so its ticks cannot count the silence: the wall clock alone does."""
        if not self.energised:
            return
        wd = self.limits.watchdog_s
        wall = self.clock() - self.last_host_wall if self.clock is not None else None
        wall_past = wall is not None and wall > wd
        ticks_past = self._past_watchdog_ticks()
        if not (wall_past if held else ticks_past and (wall is None or wall_past)):
            return
        # the silence both clocks agree on; held with its ticks short of it, the wall clock's
        silent = self.host_silence_s() if ticks_past else wall
        self._trip(F.Fault(F.WATCHDOG, value=silent, limit=wd, time_s=self._run_time()))

    # -- the control loop -------------------------------------------------------------
    # One control period is a fixed sequence of named steps. Their float operations and order
    # are pinned by tests/hardware/test_device_regression.py (a recorded run, bit for bit): do
    # not reorder a sum. The steps read the per-run constants and the state lists from one
    # slotted :class:`_TickContext` built per ``advance`` call, the rest from ``self``; the
    # nine calls per tick cost about 5 % of the tick's time (measured against the single loop).
    def advance(self, n_ticks: int) -> None:
        """Run ``n_ticks`` control periods (physics, control, safety, streaming)."""
        self.check_watchdog()
        c = _TickContext(self)
        noise = self.rng.standard_normal((n_ticks, 6)).tolist()
        for n in range(n_ticks):
            if self.tick % 100 == 0:
                self._refresh_kinematics()
            nz = noise[n]
            fs = self._skin_force(c)
            run_k = self.tick - self.run_tick0
            mode, sp, force_mode = self._setpoint(run_k, c.dt)
            meas, xf_prev = self._measure(c, nz, mode, run_k)
            cur, flags = self._control(c, meas, xf_prev, sp, force_mode)
            self._physics(c, fs, cur)
            fx, fy, fz, flags = self._tip_sensors(c, fs, flags)
            self.tick += 1
            self._safety(c, meas, fx, fy, fz, mode)
            self.flags_acc |= flags
            if self.streaming and (self.tick - 1 - self.run_tick0) % self.decimation == 0:
                self._stream(c, nz, cur, meas, fx, fy, fz, mode, run_k)
            if self.post_fault_left > 0:
                self._count_down_post_fault()

    def _skin_force(self, c: _TickContext) -> tuple[float, float, float]:
        """Kinematics: tip displacement from the skin origin and tip velocity through the
        linearised Jacobian, and the skin's reaction on the probe [N]."""
        j00, j01, j02, j10, j11, j12, j20, j21, j22 = self.jl
        tr, qr, so = self.tip_ref, self.q_ref, c.so
        x, v = c.x, c.v
        dq0, dq1, dq2 = x[0] - qr[0], x[1] - qr[1], x[2] - qr[2]
        u = (
            tr[0] + j00 * dq0 + j01 * dq1 + j02 * dq2 - so[0],
            tr[1] + j10 * dq0 + j11 * dq1 + j12 * dq2 - so[1],
            tr[2] + j20 * dq0 + j21 * dq1 + j22 * dq2 - so[2],
        )
        vt = (
            j00 * v[0] + j01 * v[1] + j02 * v[2],
            j10 * v[0] + j11 * v[1] + j12 * v[2],
            j20 * v[0] + j21 * v[1] + j22 * v[2],
        )
        return c.skin.reaction(u, vt, c.dt)

    def _setpoint(self, run_k: int, dt: float) -> tuple[str, list[float], bool]:
        """This tick's ``(mode, setpoint, force_mode)``: the programme interpolated at run tick
        ``run_k`` (ending the run after its last setpoint), the homing ramp, or the held setpoint."""
        mode = self.mode
        if mode == RUNNING:
            prog = self.programme
            pos = run_k * self.prog_rate * dt
            i0 = int(pos)
            if i0 < prog.shape[0] - 1:
                fr = pos - i0
                r0, r1 = prog[i0], prog[i0 + 1]
                sp = [
                    r0[0] + fr * (r1[0] - r0[0]),
                    r0[1] + fr * (r1[1] - r0[1]),
                    r0[2] + fr * (r1[2] - r0[2]),
                ]
                return mode, sp, self.prog_mode == "force"
            row = prog[-1]
            self.setpoint = list(self.xf) if self.prog_mode == "force" else [row[0], row[1], row[2]]
            self._end_run()
            return self.mode, self.setpoint, False
        if mode == HOMING:
            return mode, self._homing_setpoint(self.setpoint), False
        return mode, self.setpoint, False

    def _measure(
        self, c: _TickContext, nz: list[float], mode: str, run_k: int
    ) -> tuple[list[float], list[float]]:
        """Per axis: the position ADC reading (noise, quantisation, an injected stuck sensor), its
        repeat count, and the derivative filter. Returns measured positions [m] and the filter's
        previous values."""
        x, xf, last_raw, same_raw = c.x, c.xf, c.last_raw, c.same_raw
        sig_q, a_lo, lsb, nlev, alpha = c.sig_q, c.a_lo, c.lsb, c.nlev, c.alpha
        inj = c.inj
        stuck = inj.stuck_motor if mode == RUNNING and run_k * c.dt >= inj.stuck_after_s else 0
        meas = [0.0, 0.0, 0.0]
        xf_prev = [0.0, 0.0, 0.0]
        for i in range(3):
            raw = int(round((x[i] + sig_q * nz[i] - a_lo) / lsb))
            raw = 0 if raw < 0 else (nlev if raw > nlev else raw)
            if stuck == i + 1:
                raw = last_raw[i]
            if raw == last_raw[i]:
                same_raw[i] += 1
            else:
                same_raw[i] = 0
                last_raw[i] = raw
            qm = a_lo + raw * lsb
            meas[i] = qm
            xf_prev[i] = xf[i]
            xf[i] += alpha * (qm - xf[i])
        return meas, xf_prev

    def _control(
        self, c: _TickContext, meas: list[float], xf_prev: list[float], sp: list[float], force_mode: bool
    ) -> tuple[list[float], int]:
        """Per axis: the motor force (PID with anti-windup, or the force programme), saturated at
        the peak force and current. Returns currents [A] (zero when de-energised) and flags."""
        cur = [0.0, 0.0, 0.0]
        flags = 0
        if not self.energised:
            return cur, flags
        xf, integ = c.xf, c.integ
        kf0, droop, mid, half, imax, fpk = c.kf0, c.droop, c.mid, c.half, c.imax, c.fpk
        kp, ki, kd, mg, dt = c.kp, c.ki, c.kd, c.mg, c.dt
        for i in range(3):
            qm = meas[i]
            kfm = kf0 * (1.0 - droop * min(((qm - mid) / half) ** 2, 1.5))
            if force_mode:
                fcmd = sp[i]
            else:
                e = sp[i] - qm
                fcmd = kp * e + ki * integ[i] - kd * (xf[i] - xf_prev[i]) / dt + mg
                if abs(fcmd) < fpk:  # anti-windup: integrate only when not saturated
                    integ[i] += e * dt
            if fcmd > fpk:
                fcmd, flags = fpk, flags | FLAG_SATURATED
            elif fcmd < -fpk:
                fcmd, flags = -fpk, flags | FLAG_SATURATED
            ci = fcmd / kfm
            if ci > imax:
                ci, flags = imax, flags | FLAG_SATURATED
            elif ci < -imax:
                ci, flags = -imax, flags | FLAG_SATURATED
            cur[i] = ci
        return cur, flags

    def _physics(self, c: _TickContext, fs: tuple[float, float, float], cur: list[float]) -> None:
        """Per arm: voice-coil force, coil heating, one semi-implicit Euler step with the skin's
        force through ``J^T``, and the hard stops."""
        j00, j01, j02, j10, j11, j12, j20, j21, j22 = self.jl
        jt = (
            j00 * fs[0] + j10 * fs[1] + j20 * fs[2],
            j01 * fs[0] + j11 * fs[1] + j21 * fs[2],
            j02 * fs[0] + j12 * fs[1] + j22 * fs[2],
        )
        x, v, th = c.x, c.v, c.th
        kf0, droop, mid, half, th_a = c.kf0, c.droop, c.mid, c.half, c.th_a
        m, b, k, rest, mg, dt = c.m, c.b, c.k, c.rest, c.mg, c.dt
        stop_lo, stop_hi = c.stop_lo, c.stop_hi
        for i in range(3):
            kf = kf0 * (1.0 - droop * min(((x[i] - mid) / half) ** 2, 1.5))
            fm = kf * cur[i]
            th[i] += (fm * fm - th[i]) * th_a
            acc = (fm - b * v[i] - k * (x[i] - rest) - mg + jt[i]) / m
            v[i] += acc * dt
            x[i] += v[i] * dt
            if x[i] < stop_lo:
                x[i], v[i] = stop_lo, 0.0
            elif x[i] > stop_hi:
                x[i], v[i] = stop_hi, 0.0

    def _tip_sensors(
        self, c: _TickContext, fs: tuple[float, float, float], flags: int
    ) -> tuple[float, float, float, int]:
        """The F/T reading of the force the probe applies to the skin (``-fs``), quantised [N],
        and the contact flag added to ``flags``."""
        fres = c.fres
        fx = round(-fs[0] / fres) * fres
        fy = round(-fs[1] / fres) * fres
        fz = round(-fs[2] / fres) * fres
        self.last_fz = fz
        if fz >= self.home_contact:
            flags |= FLAG_CONTACT
        return fx, fy, fz, flags

    def _safety(self, c: _TickContext, meas: list[float], fx: float, fy: float, fz: float, mode: str) -> None:
        """Every tick: trip on the first limit broken (stuck sensor, travel, continuous force per
        motor, then tip force) and note the tick from which the current is zero."""
        if not self.energised:
            if self.off_tick < 0 and self.fault_tick >= 0:
                self.off_tick = self.tick
            return
        dt = c.dt
        tnow = (self.tick - 1 - self.run_tick0) * dt if mode == RUNNING else (self.tick - 1) * dt
        fault = self._motor_fault(c, meas, tnow)
        if fault is None and fx * fx + fy * fy + fz * fz > c.tip_lim2:
            fault = F.Fault(F.TIP_FORCE, 0, math.sqrt(fx * fx + fy * fy + fz * fz), c.tip_force, tnow)
        if fault is not None:
            self._trip(fault)
        if not self.energised:
            self.off_tick = self.tick  # the next tick computes zero current

    def _motor_fault(self, c: _TickContext, meas: list[float], tnow: float) -> F.Fault | None:
        """The first per-motor limit broken at device time ``tnow`` [s], or None."""
        t_lo, t_hi, th, same_raw = c.t_lo, c.t_hi, c.th, c.same_raw
        for i in range(3):
            if same_raw[i] >= c.stuck_ticks:
                return F.Fault(F.STUCK_SENSOR, i + 1, meas[i], time_s=tnow)
            if meas[i] < t_lo or meas[i] > t_hi:
                return F.Fault(F.TRAVEL, i + 1, meas[i], t_lo if meas[i] < t_lo else t_hi, tnow)
            if th[i] > c.cont2:
                return F.Fault(F.CONTINUOUS_FORCE, i + 1, math.sqrt(th[i]), c.cont, tnow)
        return None

    def _stream(
        self,
        c: _TickContext,
        nz: list[float],
        cur: list[float],
        meas: list[float],
        fx: float,
        fy: float,
        fz: float,
        mode: str,
        run_k: int,
    ) -> None:
        """Append one sample row (see :data:`COLUMNS`) with the flags OR-ed since the last one."""
        fl = self.flags_acc
        if self.trigger_period and mode == RUNNING and run_k % self.trigger_period == 0:
            fl |= FLAG_CAMERA_TRIGGER
        if self.mode == FAULTED:
            fl |= FLAG_ESTOP if self.fault and self.fault.code == F.ESTOP else FLAG_LIMIT
        sig_i, ilsb, plen, tres = c.sig_i, c.ilsb, c.plen, c.tres
        ci = [round((cur[i] + sig_i * nz[3 + i]) / ilsb) * ilsb for i in range(3)]
        self.rows.append(
            (
                self.sample_index,
                self.tick - 1 - self.run_tick0,
                meas[0],
                meas[1],
                meas[2],
                ci[0],
                ci[1],
                ci[2],
                fx,
                fy,
                fz,
                round(-plen * fy / tres) * tres,
                round(plen * fx / tres) * tres,
                0.0,
                fl,
            )
        )
        self.sample_index += 1
        self.generated += 1
        self.flags_acc = 0

    def _count_down_post_fault(self) -> None:
        """After a trip while streaming: stream on for ``Limits.post_fault_s``, then report the fault."""
        self.post_fault_left -= 1
        if self.post_fault_left == 0:
            self.streaming = False
            self.events.append(Event("fault", fault=self.fault, generated=self.generated))
            self.post_fault_left = -1

    def _homing_setpoint(self, sp: list[float]) -> list[float]:
        dt = self.params.dt
        if self._home_phase == 0:  # go to the home pose at 10 mm/s
            step = 0.01 * dt
            new = [s + max(-step, min(step, self.home_target - s)) for s in sp]
            if all(abs(nv - self.home_target) < 1e-12 for nv in new) and all(
                abs(xi - self.home_target) < 20e-6 for xi in self.xf
            ):
                self._home_phase = 1
            self.setpoint = new
            return new
        # approach: rise until the F/T sensor reads the contact force
        if self.last_fz >= self.home_contact:
            self.mode = HOLD
            self.setpoint = list(self.xf)
            self.events.append(Event("home_done", q=(self.xf[0], self.xf[1], self.xf[2])))
            return self.setpoint
        new = [s + self.home_speed * dt for s in sp]
        if max(new) > self.limits.travel_m[1] - 1e-4:
            self._trip(F.Fault(F.NO_CONTACT, 0, max(new), self.limits.travel_m[1], self.time_s))
            return sp
        self.setpoint = new
        return new


def run_device_until(
    device: Device, done: Callable[[list[Event]], bool], max_s: float, block_ticks: int = 100
) -> list[Event]:
    """Advance ``device`` in blocks until ``done(events)`` or ``max_s`` of device time; returns events."""
    events: list[Event] = []
    t_end = device.time_s + max_s
    while device.time_s < t_end:
        device.heartbeat()
        device.advance(block_ticks)
        events += device.take_events()
        if done(events):
            break
    return events


def wall_clock() -> float:
    """Monotonic wall time [s]: a device ``clock`` for a device run beside a host (the
    emulator's :func:`~skinkit_hardware.emulator.serve` replaces it by the time of its latest
    read of the link)."""
    return time.monotonic()
