"""``serial``: the robot over a serial link (pyserial), framed binary protocol with sequence
numbers and CRC-32 (``hardware/SERIAL_PROTOCOL.md``)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from skinkit.errors import OptionError
from skinkit_hardware import faults as F
from skinkit_hardware.device import Event
from skinkit_hardware.drivers.link import LinkTransport
from skinkit_hardware.host import HostDriver
from skinkit_hardware.params import RobotParameters
from skinkit_hardware.wire import serial_codec as S


class SerialTransport(LinkTransport):
    """Host side of the serial protocol on a pyserial port. Without the heartbeat thread, a
    host that stops reading goes silent (the device's watchdog then trips)."""

    def __init__(
        self,
        port: str,
        baudrate: int,
        params: RobotParameters,
        heartbeat_thread: bool = True,
        heartbeat_s: float = 0.05,
    ) -> None:
        import serial

        try:
            self.ser = serial.Serial(port, baudrate=baudrate, timeout=0.05, write_timeout=2.0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise F.DeviceFault(f"serial: cannot open port {port!r} at {baudrate} baud: {exc}") from None
        self.port = port
        self.params = params
        self.reader = S.FrameReader()
        self.send_frame = S.Sender()
        self.info: dict[str, Any] = {}
        self._start_heartbeat(heartbeat_thread, heartbeat_s, "skinkit-serial-heartbeat")

    def _write(self, data: bytes) -> None:
        import serial

        with self.lock:
            try:
                self.ser.write(data)
            except (serial.SerialException, OSError) as exc:
                raise F.DeviceFault(f"serial: link lost on {self.port} while writing: {exc}") from None
            self.last_sent = time.monotonic()

    def send(self, command: str, **args: Any) -> None:
        """Send one host ``command`` with its ``args`` as a serial frame."""
        with self.lock:
            data = S.encode_command(self.send_frame, command, **args)
        self._write(data)

    def receive(self, timeout_s: float) -> tuple[np.ndarray, list[Event]]:
        """``(samples (n, 15), events)`` received within ``timeout_s`` [s]; a heartbeat first when due."""
        import serial

        if time.monotonic() - self.last_sent > self.heartbeat_s:
            self.send("heartbeat")
        try:
            self.ser.timeout = timeout_s
            data = self.ser.read(max(1, self.ser.in_waiting))
            if self.ser.in_waiting:
                data += self.ser.read(self.ser.in_waiting)
        except (serial.SerialException, OSError) as exc:
            raise F.DeviceFault(f"serial: link lost on {self.port}: {exc}", F.Fault(F.LINK)) from None
        rows, events = [], []
        for kind, _seq, payload in self.reader.feed(data):
            if kind == S.SAMPLES:
                rows.append(S.decode_samples(payload, self.params))
            elif kind == S.EVENT:
                events.append(S.decode_event(payload))
            elif kind == S.INFO:
                import json

                self.info = json.loads(payload)
        self.stats = {
            "corrupted_frames": self.reader.corrupted,
            "frame_seq_gaps": self.reader.seq_gaps,
            "skipped_bytes": self.reader.skipped_bytes,
        }
        out = np.concatenate(rows) if rows else np.empty((0, 15))
        return out, events

    def _close_link(self) -> None:
        self.ser.close()


class SerialDriver(HostDriver):
    """``connect(port="/dev/ttyUSB0", baudrate=921600, heartbeat_thread=True, decimation=10)``."""

    name = "serial"
    #: link cost of a sample (read by ``skinkit bench robot``): bits per sample on the line, and
    #: the ``connect`` option that sets the line rate [baud]
    wire_bits_per_sample = S.WIRE_BITS_PER_SAMPLE
    line_rate_option = "baudrate"

    def _open(self, **options: Any) -> SerialTransport:
        port = options.pop("port", None)
        if not port:
            raise OptionError(
                "serial driver: no port given (e.g. --port /dev/ttyUSB0, or the "
                "port `skinkit robot emulate --serial` prints)"
            )
        baud = int(options.pop("baudrate", 921600))
        hb = bool(options.pop("heartbeat_thread", True))
        if options:
            raise OptionError(f"serial driver: unknown option(s) {sorted(options)}")
        t = SerialTransport(port, baud, self.params, heartbeat_thread=hb)
        t.handshake(f"serial: no answer from a device on {port} within 3 s (is the emulator running?)")
        return t
