"""``can``: the robot on a CAN bus through python-can's bus abstraction, so any python-can
interface works (``socketcan``, ``pcan``, ``virtual``, ``skinkit_loopback`` to reach the
emulator in another process). Messages are defined in ``skinkit_robot.dbc``."""

from __future__ import annotations

import time
from typing import Any

import can
import numpy as np

from skinkit.errors import OptionError
from skinkit_hardware import faults as F
from skinkit_hardware.device import Event
from skinkit_hardware.drivers.link import LinkTransport
from skinkit_hardware.host import HostDriver
from skinkit_hardware.params import RobotParameters
from skinkit_hardware.wire import can_codec as C


class CanTransport(LinkTransport):
    """Host side of the CAN protocol on a python-can bus."""

    def __init__(
        self,
        bus: can.BusABC,
        params: RobotParameters,
        heartbeat_thread: bool = True,
        heartbeat_s: float = 0.05,
    ) -> None:
        self.bus = bus
        self.asm = C.SampleAssembler(params)
        self._start_heartbeat(heartbeat_thread, heartbeat_s, "skinkit-can-heartbeat")

    @property
    def info(self) -> dict[str, Any]:
        """The device information the robot sent (rates, firmware)."""
        return self.asm.info

    def send(self, command: str, **args: Any) -> None:
        """Send one host ``command`` with its ``args`` as CAN frames (DeviceFault if the bus fails)."""
        msgs = C.encode_command(command, **args)
        with self.lock:
            try:
                for m in msgs:
                    self.bus.send(m, timeout=2.0)
            except (can.CanError, OSError) as exc:
                raise F.DeviceFault(
                    f"can: link lost while sending {command}: {exc}", F.Fault(F.LINK)
                ) from None
            self.last_sent = time.monotonic()

    def receive(self, timeout_s: float) -> tuple[np.ndarray, list[Event]]:
        """``(samples (n, 15), events)`` received within ``timeout_s`` [s]; a heartbeat first when due."""
        if time.monotonic() - self.last_sent > self.heartbeat_s:
            self.send("heartbeat")
        msgs = []
        try:
            msg = self.bus.recv(timeout_s)
            while msg is not None and len(msgs) < 20000:  # drain what has arrived
                msgs.append(msg)
                msg = self.bus.recv(0)
        except (can.CanError, OSError) as exc:
            raise F.DeviceFault(f"can: link lost: {exc}", F.Fault(F.LINK)) from None
        rows, events = self.asm.feed(msgs)
        self.stats = {"corrupted_frames": 0, "incomplete_samples": self.asm.incomplete}
        return rows, events

    def _close_link(self) -> None:
        self.bus.shutdown()


class CanDriver(HostDriver):
    """``connect(interface="skinkit_loopback", channel="127.0.0.1:PORT", bitrate=1_000_000,
    heartbeat_thread=True, decimation=10)``, or ``port="INTERFACE:CHANNEL"`` (CLI form), or
    ``bus=`` an open python-can bus."""

    name = "can"
    #: link cost of a sample (read by ``skinkit bench robot``): bits per sample on the bus, and
    #: the ``connect`` option that sets the bit rate [bit/s]
    wire_bits_per_sample = C.WIRE_BITS_PER_SAMPLE
    line_rate_option = "bitrate"

    def _open(self, **options: Any) -> CanTransport:
        bus = options.pop("bus", None)
        port = options.pop("port", None)
        interface = options.pop("interface", None)
        channel = options.pop("channel", None)
        bitrate = int(options.pop("bitrate", 1_000_000))
        hb = bool(options.pop("heartbeat_thread", True))
        if options:
            raise OptionError(f"can driver: unknown option(s) {sorted(options)}")
        if bus is None:
            if port:
                interface, _, channel = str(port).partition(":")
                if not channel:
                    raise F.DeviceFault(
                        f"can driver: --port must be INTERFACE:CHANNEL (e.g. "
                        f"skinkit_loopback:127.0.0.1:29536 or socketcan:can0), got {port!r}"
                    )
            if not interface or channel is None:
                raise F.DeviceFault("can driver: give interface and channel (or --port INTERFACE:CHANNEL)")
            try:
                bus = can.Bus(interface=interface, channel=channel, bitrate=bitrate)
            except Exception as exc:  # noqa: BLE001 - python-can interfaces raise many types
                raise F.DeviceFault(
                    f"can: cannot open {interface}:{channel} at {bitrate} bit/s: {exc}"
                ) from None
        t = CanTransport(bus, self.params, heartbeat_thread=hb)
        t.handshake(f"can: no answer from a device on {interface}:{channel} within 3 s")
        return t
