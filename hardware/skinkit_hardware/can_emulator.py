"""Device side of the CAN protocol for the emulator: a python-can bus (virtual, bridged to
other processes over loopback TCP), a bounded transmit queue paced at the bus bit rate, and
frame drop/corruption injection (a corrupted CAN frame fails its CRC in the receiver's
controller and is discarded, so it is counted separately but behaves like a drop)."""

from __future__ import annotations

import time
import uuid
from collections import deque
from typing import Any

import can
import numpy as np

from skinkit_hardware.device import Event
from skinkit_hardware.params import RobotParameters
from skinkit_hardware.wire import can_codec as C


class CanLinkServer:
    """``port`` > 0 or 0 (any free port) serves the loopback bridge; ``port`` None keeps the
    bus in-process on the virtual ``channel`` (tests)."""

    def __init__(
        self,
        port: int | None,
        bitrate: int,
        buffer_bytes: int,
        drop_rate: float,
        corrupt_rate: float,
        rng: np.random.Generator,
        params: RobotParameters,
        channel: str | None = None,
    ) -> None:
        self.channel = channel or f"skinkit-{uuid.uuid4().hex[:8]}"
        self.bus = can.Bus(interface="virtual", channel=self.channel, receive_own_messages=False)
        self.bridge = None
        self.address = f"virtual {self.channel}"
        if port is not None:
            from skinkit_hardware.can_bridge import BridgeServer

            self.bridge = BridgeServer(self.channel, "127.0.0.1", port)
            self.address = self.bridge.address
        self.bitrate = bitrate
        self.capacity = max(16, buffer_bytes // 16)  # frames
        self.drop_rate, self.corrupt_rate = drop_rate, corrupt_rate
        self.rng = rng
        self.params = params
        self.asm = C.CommandAssembler()
        self.tx: deque[can.Message] = deque()
        self.credit = 0.0
        self.t_last = time.monotonic()
        self.dropped = self.corrupted = self.overflow = 0

    def backlog(self) -> float:
        """Fraction of the transmit queue in use."""
        return len(self.tx) / self.capacity

    def poll(self, timeout: float) -> list[tuple[str, dict[str, Any]]]:
        """The host commands ``[(command, args)]`` received within ``timeout`` [s]."""
        out = []
        msg = self.bus.recv(timeout)
        while msg is not None:
            d = C.decode(msg)
            if d is not None:
                cmd = self.asm.feed(*d)
                if cmd is not None:
                    out.append(cmd)
            msg = self.bus.recv(0)
        return out

    def samples(self, rows: np.ndarray) -> None:
        """Queue the frames of sample ``rows`` ``(n, 15)``; a sample that does not fit is lost (counted)."""
        for frames in C.encode_samples(rows, self.params):
            if len(self.tx) + len(frames) > self.capacity:
                self.overflow += 1  # the index is consumed: the host sees the gap
                continue
            for f in frames:
                if self.drop_rate and self.rng.random() < self.drop_rate:
                    self.dropped += 1
                    continue
                if self.corrupt_rate and self.rng.random() < self.corrupt_rate:
                    self.corrupted += 1
                    continue
                self.tx.append(f)

    def event(self, ev: Event) -> None:
        """Queue the frames of event ``ev`` (never dropped on purpose)."""
        self.tx.extend(C.encode_event(ev, self.params))

    def info(self, info: dict[str, Any]) -> None:
        """Queue the device information frame of ``info``."""
        self.tx.extend(C.encode_info(info))

    def flush(self) -> None:
        """Send as many queued frames as the bit rate allows since the last flush (all at rate 0)."""
        now = time.monotonic()
        if self.bitrate > 0:
            self.credit = min(self.credit + (now - self.t_last) * self.bitrate / C.FRAME_BITS, 256.0)
            n = int(self.credit)
        else:
            n = len(self.tx)
        self.t_last = now
        sent = 0
        while self.tx and sent < n:
            self.bus.send(self.tx.popleft())
            sent += 1
        if self.bitrate > 0:
            self.credit -= sent

    def close(self) -> None:
        """Stop the bridge, if any, and the virtual bus."""
        if self.bridge is not None:
            self.bridge.close()
        self.bus.shutdown()
