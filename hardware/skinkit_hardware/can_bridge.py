"""A loopback-only bridge that carries CAN frames between processes over TCP on 127.0.0.1.

python-can's ``virtual`` bus connects buses inside one process. To put the device emulator
in its own process, :class:`BridgeServer` (in the emulator) forwards every frame between a
local virtual channel and one TCP client, and :class:`LoopbackBus` is a python-can
interface (entry point ``can.interface`` -> ``skinkit_loopback``) that a host opens with
``can.Bus(interface="skinkit_loopback", channel="127.0.0.1:PORT")``. Only loopback
addresses are accepted; nothing is multicast.

Wire record per frame (16 bytes, little endian): arbitration id u32, dlc u8, flags u8
(bit 0 extended id), 2 pad bytes, 8 data bytes.
"""

from __future__ import annotations

import ipaddress
import select
import socket
import struct
import threading
from typing import Any

import can

from skinkit.errors import SkinkitError

RECORD = struct.Struct("<IBB2x8s")


class BridgeError(SkinkitError):
    """A non-loopback address, or a bridge that cannot be reached."""


def parse_loopback(channel: str) -> tuple[str, int]:
    """``"127.0.0.1:PORT"`` -> ``(host, port)``; refuses any address that is not loopback."""
    host, _, port = str(channel).rpartition(":")
    host = host.strip("[]") or "127.0.0.1"
    try:
        ip = ipaddress.ip_address(host if host != "localhost" else "127.0.0.1")
        port_n = int(port)
    except ValueError:
        raise BridgeError(f"CAN bridge: channel must be 'HOST:PORT' on loopback, got {channel!r}") from None
    if not ip.is_loopback:
        raise BridgeError(
            f"CAN bridge: {host} is not a loopback address (only 127.0.0.0/8 and ::1 are allowed)"
        )
    return str(ip), port_n


def pack(msg: can.Message) -> bytes:
    """One frame as a fixed-size bridge record (id, dlc, extended flag, 8 data bytes zero-padded)."""
    return RECORD.pack(
        msg.arbitration_id, msg.dlc, 1 if msg.is_extended_id else 0, bytes(msg.data).ljust(8, b"\0")
    )


def unpack(buf: bytes) -> can.Message:
    """The frame of one :func:`pack` record."""
    arb, dlc, flags, data = RECORD.unpack(buf)
    return can.Message(arbitration_id=arb, dlc=dlc, data=data[:dlc], is_extended_id=bool(flags & 1))


class LoopbackBus(can.BusABC):
    """python-can interface: a TCP client of a :class:`BridgeServer` on a loopback address."""

    def __init__(self, channel: Any = "127.0.0.1:29536", **kwargs: Any) -> None:
        host, port = parse_loopback(channel)
        try:
            self.sock = socket.create_connection((host, port), timeout=5.0)
        except OSError as exc:
            raise BridgeError(f"CAN bridge: cannot connect to {host}:{port}: {exc}") from None
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock.setblocking(False)
        self.buf = bytearray()
        self.channel_info = f"skinkit loopback bridge {host}:{port}"
        self.closed = False
        super().__init__(channel=channel, **kwargs)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if len(self.buf) < RECORD.size:
            r, _, _ = select.select([self.sock], [], [], timeout)
            if r:
                try:
                    data = self.sock.recv(65536)
                except BlockingIOError:
                    data = b"-"
                except OSError as exc:
                    raise can.CanOperationError(f"CAN bridge connection lost: {exc}") from None
                if not data:
                    raise can.CanOperationError("CAN bridge closed by the device side")
                if data != b"-":
                    self.buf += data
        if len(self.buf) >= RECORD.size:
            msg = unpack(bytes(self.buf[: RECORD.size]))
            del self.buf[: RECORD.size]
            return msg, False
        return None, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg`` to the bridge, waiting at most ``timeout`` [s] (default 5 s)."""
        data = pack(msg)
        self.sock.setblocking(True)
        try:
            self.sock.settimeout(timeout if timeout is not None else 5.0)
            self.sock.sendall(data)
        except OSError as exc:
            raise can.CanOperationError(f"CAN bridge connection lost: {exc}") from None
        finally:
            self.sock.setblocking(False)

    def shutdown(self) -> None:
        """Close the connection to the bridge (idempotent)."""
        if not self.closed:
            self.closed = True
            try:
                self.sock.close()
            except OSError:
                pass
        super().shutdown()


class BridgeServer:
    """Forwards frames between the virtual ``channel`` of this process and one TCP client."""

    def __init__(self, channel: str, host: str = "127.0.0.1", port: int = 0) -> None:
        host, _ = parse_loopback(f"{host}:{port}")
        self.listener = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
        self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.listener.bind((host, port))
        self.listener.listen(1)
        self.address = f"{host}:{self.listener.getsockname()[1]}"
        self.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, name="skinkit-can-bridge", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            r, _, _ = select.select([self.listener], [], [], 0.1)
            if not r:
                continue
            conn, _ = self.listener.accept()
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._serve(conn)

    def _serve(self, conn: socket.socket) -> None:
        # one thread per direction: a flood of samples towards the host must never delay
        # the host's heartbeats towards the device (that would trip the watchdog)
        done = threading.Event()
        up = threading.Thread(
            target=self._to_host, args=(conn, done), name="skinkit-can-bridge-up", daemon=True
        )
        up.start()
        buf = bytearray()
        try:
            while not self._stop.is_set() and not done.is_set():
                r, _, _ = select.select([conn], [], [], 0.05)
                if not r:
                    continue
                data = conn.recv(65536)
                if not data:
                    return
                buf += data
                while len(buf) >= RECORD.size:  # host -> device
                    self.bus.send(unpack(bytes(buf[: RECORD.size])))
                    del buf[: RECORD.size]
        except OSError:
            return
        finally:
            done.set()
            up.join(1.0)
            conn.close()

    def _to_host(self, conn: socket.socket, done: threading.Event) -> None:
        try:
            while not self._stop.is_set() and not done.is_set():
                msg = self.bus.recv(0.05)
                if msg is None:
                    continue
                out = bytearray(pack(msg))
                while len(out) < 64 * RECORD.size:
                    msg = self.bus.recv(0)
                    if msg is None:
                        break
                    out += pack(msg)
                conn.sendall(out)
        except OSError:
            pass
        finally:
            done.set()

    def close(self) -> None:
        """Stop forwarding, close the listening socket and the virtual bus."""
        self._stop.set()
        self.thread.join(1.0)
        self.listener.close()
        self.bus.shutdown()
