"""The device emulator: a separate process that runs the device model behind the real wire
protocols, so the serial and CAN drivers are tested end to end over an OS link.

``python -m skinkit_hardware.emulator serial`` opens a pseudo-terminal pair and prints
``serial: /dev/pts/N``; ``... can`` serves the CAN protocol over the loopback bridge and
prints ``can: skinkit_loopback 127.0.0.1:PORT``. Options inject faults (dropped and
corrupted frames, a stuck sensor) and set the link speed (baud rate, CAN bit rate) and the
real-time factor.

Watchdog on the device's own clock: the device counts its control ticks since the host's
last command (see :mod:`skinkit_hardware.device`). The link is read before every burst of
at most 5 x 10 ms of device time, and no tick passes while this process is descheduled, so
a slow or starved emulator (a loaded machine) never takes its own stall for host silence;
what the watchdog protects -- at most ``watchdog_s`` of motion after the host's last word --
holds at any speed. At ``--speed 1`` device time never runs ahead of the wall clock by more
than one burst, so a host silent for the watchdog time trips it as the firmware would; a
device that would run ahead (``--speed 0``, or above 1) waits for the host once it is a
watchdog time past the host's last word (never more than one 10 ms step past it), and trips
when the wall clock agrees.

Control loop independence: the device advances on its own clock and puts decimated samples
into a bounded transmit buffer (``--buffer-bytes``, the device's memory); the link drains
it at its own speed. A full buffer drops samples, but their indices are still consumed, so
the host counts every loss. With ``--speed 0`` the model runs as fast as the link drains it
(back-pressure, for tests); with ``--speed 1`` it runs in real time and the link must keep up.
"""

from __future__ import annotations

import argparse
import os
import select
import sys
import time
import tty
import zlib
from typing import Any

import numpy as np

from skinkit_hardware.device import HOMING, RUNNING, Device, Event, Injection, wall_clock
from skinkit_hardware.params import RobotParameters
from skinkit_hardware.skin import make_skin
from skinkit_hardware.wire import serial_codec as S


class LinkStats:
    """What the serial link did: samples sent and lost to overflow, frames dropped and corrupted."""

    def __init__(self) -> None:
        self.sent_samples = 0
        self.overflow_samples = 0
        self.dropped_frames = 0
        self.corrupted_frames = 0


class SerialLinkServer:
    """Device side of the serial protocol on the master end of a pty."""

    def __init__(
        self,
        baud: int,
        buffer_bytes: int,
        drop_rate: float,
        corrupt_rate: float,
        rng: np.random.Generator,
        params: RobotParameters,
    ) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.port = os.ttyname(self.slave)
        self.baud = baud
        self.capacity = buffer_bytes
        self.drop_rate, self.corrupt_rate = drop_rate, corrupt_rate
        self.rng = rng
        self.params = params
        self.reader = S.FrameReader()
        self.send = S.Sender()
        self.tx = bytearray()
        self.credit = 0.0
        self.t_last = time.monotonic()
        self.stats = LinkStats()
        self._load: dict[str, Any] | None = None

    def backlog(self) -> float:
        """Fraction of the transmit buffer in use."""
        return len(self.tx) / self.capacity

    def poll(self, timeout: float) -> list[tuple[str, dict[str, Any]]]:
        """The host commands ``[(command, args)]`` read within ``timeout`` [s]."""
        r, _, _ = select.select([self.master], [], [], timeout)
        if not r:
            return []
        try:
            data = os.read(self.master, 65536)
        except (BlockingIOError, OSError):
            return []
        out = []
        for kind, _seq, payload in self.reader.feed(data):
            cmd = self._command(kind, payload)
            if cmd is not None:
                out.append(cmd)
        return out

    def _command(self, kind: int, payload: bytes) -> tuple[str, dict[str, Any]] | None:
        names = {v: k for k, v in S.COMMANDS.items()}
        if kind == S.CONFIGURE:
            dec, wd, tip = S.CONFIGURE_S.unpack(payload)
            return "configure", {"decimation": dec, "watchdog_s": wd, "tip_force_N": tip}
        if kind == S.HOME:
            c, v = S.HOME_S.unpack(payload)
            return "home", {"contact_N": c, "speed_m_s": v}
        if kind == S.LOAD_BEGIN:
            mode, n, rate, trig = S.LOAD_BEGIN_S.unpack(payload)
            self._load = {
                "mode": "position" if mode == 0 else "force",
                "n": n,
                "rate_hz": rate,
                "trigger_period_s": trig,
                "data": np.zeros((n, 3), "<i4"),
                "got": 0,
            }
            return "heartbeat", {}
        if kind == S.LOAD_DATA and self._load is not None:
            (off,) = S.LOAD_DATA_HEAD.unpack_from(payload)
            chunk = np.frombuffer(payload, "<i4", offset=S.LOAD_DATA_HEAD.size).reshape(-1, 3)
            self._load["data"][off : off + chunk.shape[0]] = chunk
            self._load["got"] += chunk.shape[0]
            return "heartbeat", {}
        if kind == S.LOAD_END and self._load is not None:
            ld, self._load = self._load, None
            (crc,) = S.CRC.unpack(payload)
            if ld["got"] != ld["n"] or zlib.crc32(ld["data"].tobytes()) != crc:
                return "load_corrupt", {}
            unit = S.POSITION_UNIT_M if ld["mode"] == "position" else S.FORCE_UNIT_N
            return "load", {
                "mode": ld["mode"],
                "rate_hz": ld["rate_hz"],
                "setpoints": ld["data"] * unit,
                "trigger_period_s": ld["trigger_period_s"],
            }
        if kind == S.HELLO:
            return "hello", {}
        if kind in names:
            return names[kind], {}
        return None

    def _queue(self, data: bytes) -> None:
        if self.drop_rate and self.rng.random() < self.drop_rate:
            self.stats.dropped_frames += 1
            return
        if self.corrupt_rate and self.rng.random() < self.corrupt_rate:
            b = bytearray(data)
            b[int(self.rng.integers(2, len(b)))] ^= 0x10  # a flipped bit past the sync
            data = bytes(b)
            self.stats.corrupted_frames += 1
        self.tx += data

    def samples(self, rows: np.ndarray) -> None:
        """Queue the frames of sample ``rows`` ``(n, 15)``; frames that do not fit are lost (counted)."""
        for n, f in S.encode_samples(self.send, rows, self.params):
            if len(self.tx) + len(f) > self.capacity:
                self.stats.overflow_samples += n  # indices consumed: the host sees the gap
                continue
            self.stats.sent_samples += n
            self._queue(f)

    def event(self, ev: Event) -> None:
        """Queue the frame of event ``ev``."""
        self.tx += S.encode_event(self.send, ev)  # events are never dropped on purpose

    def info(self, info: dict[str, Any]) -> None:
        """Queue the device information frame of ``info``."""
        self.tx += S.encode_info(self.send, info)

    def flush(self) -> None:
        """Write as many queued bytes as the baud rate allows since the last flush (all at baud 0)."""
        now = time.monotonic()
        if self.baud > 0:
            self.credit = min(self.credit + (now - self.t_last) * self.baud / 10.0, 4096.0)
            n = int(self.credit)
        else:
            n = len(self.tx)
        self.t_last = now
        if not self.tx or n <= 0:
            return
        try:
            written = os.write(self.master, bytes(self.tx[:n]))
        except (BlockingIOError, OSError):
            written = 0
        del self.tx[:written]
        if self.baud > 0:
            self.credit -= written

    def close(self) -> None:
        """Close both ends of the pty."""
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


class LinkReadClock:
    """The device's wall clock in the emulator: the monotonic time [s] of the latest read of
    the link. Host silence on it is the time between the read that last heard the host and the
    latest read, so only silence the emulator saw counts, never its own stall between reads."""

    def __init__(self) -> None:
        self.t = time.monotonic()

    def mark(self) -> None:
        """Record a read of the link now."""
        self.t = time.monotonic()

    def __call__(self) -> float:
        """The monotonic time [s] of the latest read."""
        return self.t


def apply_command(device: Device, link: Any, cmd: str, args: dict[str, Any]) -> None:
    """Carry out one host command on ``device`` (every command is also a heartbeat)."""
    device.heartbeat()
    if cmd == "hello":
        link.info(
            {
                "control_rate_hz": device.params.control_rate_hz,
                "decimation": device.decimation,
                "limits": device.limits.to_dict(),
                "firmware": "skinkit-emulator 1",
            }
        )
    elif cmd == "load":
        device.load(**args)
    elif cmd == "load_corrupt":
        from skinkit_hardware import faults as F

        device.events.append(Event("refused", fault=F.Fault(F.BAD_COMMAND)))
    elif cmd == "configure":
        device.configure(**args)
    elif cmd != "heartbeat":
        getattr(device, cmd)(**args)


def serve(
    device: Device,
    link: Any,
    speed: float,
    announce: str | None,
    max_s: float | None = None,
    stop: Any = None,
) -> None:
    """Run ``device`` behind ``link`` until killed, ``max_s`` of wall time, or ``stop.is_set()``."""
    if announce:
        print(announce, flush=True)
    rate = device.params.control_rate_hz
    reads = LinkReadClock()
    device.clock = reads  # beside a real host: its silence is confirmed on the wall clock too
    t0 = time.monotonic()
    wall_ref, tick_ref = t0, device.tick
    chunk = 100  # ticks per physics step: 10 ms of device time
    while (max_s is None or time.monotonic() - t0 < max_s) and not (stop is not None and stop.is_set()):
        active = device.mode in (RUNNING, HOMING) or device.post_fault_left > 0
        commands = link.poll(0.0 if active else 0.005)
        reads.mark()
        # commands (heartbeats) are read before the device advances; the watchdog counts device
        # ticks, so a descheduled emulator never blames the host for its own stall (module doc)
        for cmd, args in commands:
            apply_command(device, link, cmd, args)
        now = time.monotonic()
        active = device.mode in (RUNNING, HOMING) or device.post_fault_left > 0
        if device.waiting_for_host():
            # a full watchdog time of device time since the host's last word: wait for the
            # host rather than outrun it; trips once the wall clock agrees it is silent
            device.check_watchdog(held=True)
            wall_ref, tick_ref = now, device.tick
        elif speed <= 0 and active:
            # as fast as the link drains: back-pressure instead of artificial losses
            if link.backlog() < 0.5:
                device.advance(chunk)
            else:
                device.check_watchdog(held=True)  # the host does not read: wall clock alone
            wall_ref, tick_ref = now, device.tick
        else:
            factor = speed if speed > 0 else 1.0  # idle at real time even when fast-forwarding
            due = int((now - wall_ref) * rate * factor) - (device.tick - tick_ref)
            steps = 0
            while due >= chunk and steps < 5 and not device.waiting_for_host():
                device.advance(chunk)
                due -= chunk
                steps += 1
            if steps == 5:  # cannot keep up: the device time falls behind, as a slow CPU would
                wall_ref, tick_ref = now, device.tick
        rows = device.drain()
        if rows.shape[0]:
            link.samples(rows)
        for ev in device.take_events():
            link.event(ev)
        link.flush()


def build_device(args: argparse.Namespace) -> Device:
    """The emulated device the command line describes (skin, seed, injected faults), on the wall clock."""
    inj = Injection(stuck_motor=args.stuck_motor, stuck_after_s=args.stuck_after)
    return Device(skin=make_skin(args.skin), seed=args.seed, clock=wall_clock, injection=inj)


def main(argv: list[str] | None = None) -> int:
    """``python -m skinkit_hardware.emulator``: serve a device on a serial or CAN link; the exit code."""
    ap = argparse.ArgumentParser(
        prog="python -m skinkit_hardware.emulator",
        description="Emulate the microrobot behind its serial or CAN protocol.",
    )
    ap.add_argument("link", choices=["serial", "can"])
    ap.add_argument(
        "--baud", type=int, default=921600, help="serial: bytes drained at baud/10 per s (0: unlimited)"
    )
    ap.add_argument("--bitrate", type=int, default=1_000_000, help="CAN: bit rate (0: unlimited)")
    ap.add_argument("--port", type=int, default=0, help="CAN bridge TCP port on 127.0.0.1 (0: any free)")
    ap.add_argument(
        "--speed", type=float, default=1.0, help="real-time factor; 0 = as fast as the link drains"
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skin", default="kelvin-voigt")
    ap.add_argument("--buffer-bytes", type=int, default=65536, help="device transmit buffer")
    ap.add_argument("--drop-rate", type=float, default=0.0, help="fraction of sample frames dropped")
    ap.add_argument("--corrupt-rate", type=float, default=0.0, help="fraction of sample frames corrupted")
    ap.add_argument("--stuck-motor", type=int, default=0)
    ap.add_argument("--stuck-after", type=float, default=0.0, help="run time [s] when the sensor sticks")
    ap.add_argument("--max-s", type=float, default=None, help="exit after this many seconds")
    args = ap.parse_args(argv)
    device = build_device(args)
    rng = np.random.default_rng(args.seed + 1)
    if args.link == "serial":
        link = SerialLinkServer(
            args.baud, args.buffer_bytes, args.drop_rate, args.corrupt_rate, rng, device.params
        )
        announce = f"serial: {link.port}"
    else:
        from skinkit_hardware.can_emulator import CanLinkServer

        link = CanLinkServer(
            args.port, args.bitrate, args.buffer_bytes, args.drop_rate, args.corrupt_rate, rng, device.params
        )
        announce = f"can: skinkit_loopback:{link.address}"
    try:
        serve(device, link, args.speed, announce, args.max_s)
    except KeyboardInterrupt:
        pass
    finally:
        link.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
