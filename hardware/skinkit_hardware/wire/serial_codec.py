"""The serial wire protocol (documented in ``hardware/SERIAL_PROTOCOL.md``).

Frame: ``A5 5A | type u8 | seq u16 | len u16 | payload | crc32 u32``, little endian; the
CRC-32 (zlib polynomial) covers type, seq, len and payload. Each direction numbers its
frames; the reader resynchronises on the next sync pattern after a bad CRC and counts it.
"""

from __future__ import annotations

import json
import struct
import zlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit_hardware import faults as F
from skinkit_hardware.device import Event
from skinkit_hardware.params import RobotParameters
from skinkit_hardware.wire.counts import counts_to_rows, rows_to_counts

SYNC = b"\xa5\x5a"
HEADER = struct.Struct("<BHH")
CRC = struct.Struct("<I")
MAX_PAYLOAD = 4096

# host -> device
HELLO, HEARTBEAT, CONFIGURE, HOME, LOAD_BEGIN, LOAD_DATA, LOAD_END = range(1, 8)
START, STOP, ESTOP, CLEAR, HOLD, DISABLE = range(8, 14)
COMMANDS = {
    "hello": HELLO,
    "heartbeat": HEARTBEAT,
    "configure": CONFIGURE,
    "home": HOME,
    "start": START,
    "stop": STOP,
    "estop": ESTOP,
    "clear": CLEAR,
    "hold": HOLD,
    "disable": DISABLE,
}
# device -> host
INFO, SAMPLES, EVENT = 0x82, 0x83, 0x84

CONFIGURE_S = struct.Struct("<Hff")
HOME_S = struct.Struct("<ff")
LOAD_BEGIN_S = struct.Struct("<BIff")
LOAD_DATA_HEAD = struct.Struct("<I")
SAMPLES_HEAD = struct.Struct("<IB")
EVENT_S = struct.Struct("<BBB3f3fII")
EVENT_KINDS = {"home_done": 1, "run_end": 2, "fault": 3, "refused": 4}
EVENT_NAMES = {v: k for k, v in EVENT_KINDS.items()}
SAMPLE_DTYPE = np.dtype(
    [
        ("tick", "<u4"),
        ("pos", "<u2", 3),
        ("cur", "<i2", 3),
        ("force", "<i2", 3),
        ("torque", "<i2", 3),
        ("flags", "<u2"),
    ]
)
SAMPLES_PER_FRAME = 32
#: bytes of a SAMPLES frame besides its samples: sync, header, samples head, CRC
SAMPLES_FRAME_OVERHEAD = len(SYNC) + HEADER.size + SAMPLES_HEAD.size + CRC.size
#: bits a streamed sample costs on the line [bit]: 8N1 sends 10 bits per byte, and a full
#: frame shares its overhead among SAMPLES_PER_FRAME samples
WIRE_BITS_PER_SAMPLE = 10 * (SAMPLE_DTYPE.itemsize + SAMPLES_FRAME_OVERHEAD / SAMPLES_PER_FRAME)
SETPOINTS_PER_FRAME = 64
POSITION_UNIT_M = 1e-9
FORCE_UNIT_N = 1e-6


def frame(kind: int, seq: int, payload: bytes = b"") -> bytes:
    """One frame of ``kind`` with sequence number ``seq`` (mod 65536)."""
    body = HEADER.pack(kind, seq & 0xFFFF, len(payload)) + payload
    return SYNC + body + CRC.pack(zlib.crc32(body))


@dataclass
class FrameReader:
    """Incremental frame decoder: ``feed(bytes)`` -> list of ``(kind, seq, payload)``."""

    buf: bytearray = field(default_factory=bytearray)
    corrupted: int = 0
    skipped_bytes: int = 0
    seq_gaps: int = 0
    _next_seq: int | None = None

    def feed(self, data: bytes) -> list[tuple[int, int, bytes]]:
        """Append ``data``: the complete frames ``[(kind, seq, payload)]``, corrupt ones skipped (counted)."""
        self.buf += data
        out = []
        buf = self.buf
        while True:
            i = buf.find(SYNC)
            if i < 0:
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                self.skipped_bytes += len(buf) - keep
                del buf[: len(buf) - keep]
                break
            if i:
                self.skipped_bytes += i
                del buf[:i]
            if len(buf) < 2 + HEADER.size:
                break
            kind, seq, n = HEADER.unpack_from(buf, 2)
            if n > MAX_PAYLOAD:
                self.corrupted += 1
                del buf[:2]
                continue
            end = 2 + HEADER.size + n + CRC.size
            if len(buf) < end:
                break
            body = bytes(buf[2 : end - CRC.size])
            (crc,) = CRC.unpack_from(buf, end - CRC.size)
            if zlib.crc32(body) != crc:
                self.corrupted += 1
                del buf[:2]  # resynchronise on the next sync pattern
                continue
            del buf[:end]
            if self._next_seq is not None and seq != self._next_seq:
                self.seq_gaps += (seq - self._next_seq) & 0xFFFF
            self._next_seq = (seq + 1) & 0xFFFF
            out.append((kind, seq, body[HEADER.size :]))
        return out


class Sender:
    """Numbers frames in one direction."""

    def __init__(self) -> None:
        self.seq = 0

    def __call__(self, kind: int, payload: bytes = b"") -> bytes:
        """The frame of ``kind`` with ``payload``, numbered with the next sequence number."""
        f = frame(kind, self.seq, payload)
        self.seq = (self.seq + 1) & 0xFFFF
        return f


# -- host -> device encoding -------------------------------------------------------------
def encode_command(send: Sender, command: str, **args: Any) -> bytes:
    """Bytes for one host command (``load`` becomes LOAD_BEGIN, LOAD_DATA..., LOAD_END)."""
    if command == "configure":
        return send(
            CONFIGURE,
            CONFIGURE_S.pack(
                int(args.get("decimation", 10)),
                float(args.get("watchdog_s", 0.5)),
                float(args.get("tip_force_N", 0.0)),
            ),
        )
    if command == "home":
        return send(
            HOME, HOME_S.pack(float(args.get("contact_N", 0.01)), float(args.get("speed_m_s", 0.002)))
        )
    if command == "load":
        mode = args["mode"]
        sp = np.asarray(args["setpoints"], dtype=float)
        unit = POSITION_UNIT_M if mode == "position" else FORCE_UNIT_N
        data = np.rint(sp / unit).astype("<i4")
        out = [
            send(
                LOAD_BEGIN,
                LOAD_BEGIN_S.pack(
                    0 if mode == "position" else 1,
                    sp.shape[0],
                    float(args["rate_hz"]),
                    float(args.get("trigger_period_s", 0.0)),
                ),
            )
        ]
        for off in range(0, sp.shape[0], SETPOINTS_PER_FRAME):
            chunk = data[off : off + SETPOINTS_PER_FRAME]
            out.append(send(LOAD_DATA, LOAD_DATA_HEAD.pack(off) + chunk.tobytes()))
        out.append(send(LOAD_END, CRC.pack(zlib.crc32(data.tobytes()))))
        return b"".join(out)
    if command in COMMANDS:
        return send(COMMANDS[command])
    raise F.DeviceFault(f"serial protocol: unknown command {command!r}")


# -- device -> host encoding -------------------------------------------------------------
def encode_samples(send: Sender, rows: np.ndarray, p: RobotParameters) -> list[tuple[int, bytes]]:
    """``[(n_samples, frame)]`` for device rows ``(n, 15)``, up to 32 samples a frame."""
    out = []
    c = rows_to_counts(rows, p)
    for off in range(0, rows.shape[0], SAMPLES_PER_FRAME):
        sl = slice(off, off + SAMPLES_PER_FRAME)
        a = np.empty(c["index"][sl].shape[0], SAMPLE_DTYPE)
        a["tick"], a["pos"], a["cur"] = c["tick"][sl], c["pos"][sl], c["cur"][sl]
        a["force"], a["torque"], a["flags"] = c["force"][sl], c["torque"][sl], c["flags"][sl]
        out.append((a.size, send(SAMPLES, SAMPLES_HEAD.pack(int(c["index"][off]), a.size) + a.tobytes())))
    return out


def decode_samples(payload: bytes, p: RobotParameters) -> np.ndarray:
    """The sample rows ``(n, 15)`` [SI] of one samples frame's payload."""
    first, n = SAMPLES_HEAD.unpack_from(payload)
    a = np.frombuffer(payload, SAMPLE_DTYPE, count=n, offset=SAMPLES_HEAD.size)
    c = {
        "index": first + np.arange(n),
        "tick": a["tick"].astype(np.int64),
        "pos": a["pos"].astype(np.int64),
        "cur": a["cur"].astype(np.int64),
        "force": a["force"].astype(np.int64),
        "torque": a["torque"].astype(np.int64),
        "flags": a["flags"].astype(np.int64),
    }
    return counts_to_rows(c, p)


def encode_event(send: Sender, ev: Event) -> bytes:
    """The frame of event ``ev``."""
    f = ev.fault or F.Fault(0)
    q = ev.q or (0.0, 0.0, 0.0)
    return send(
        EVENT,
        EVENT_S.pack(
            EVENT_KINDS[ev.kind], f.code, f.motor, f.value, f.limit, f.time_s, *q, ev.generated, ev.index
        ),
    )


def decode_event(payload: bytes) -> Event:
    """The event of one event frame's payload."""
    kind, code, motor, value, limit, t, q1, q2, q3, generated, index = EVENT_S.unpack(payload)
    name = EVENT_NAMES.get(kind, "fault")
    fault = F.Fault(code, motor, value, limit, t) if code else None
    return Event(
        name, fault=fault, q=(q1, q2, q3) if name == "home_done" else None, generated=generated, index=index
    )


def encode_info(send: Sender, info: dict[str, Any]) -> bytes:
    """The device information frame of ``info`` (JSON)."""
    return send(INFO, json.dumps(info).encode())
