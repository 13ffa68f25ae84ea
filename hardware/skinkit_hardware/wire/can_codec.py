"""The CAN wire protocol, read from ``skinkit_robot.dbc`` with cantools (documented in
``hardware/CAN_PROTOCOL.md``). Classic CAN, 11-bit identifiers, 8-byte frames.

A sample travels as five frames (position, current, force, torque, tick+flags) sharing a
16-bit sample index; the tick frame is sent last and completes the sample. A sample missing
any frame is discarded and counted as lost by the host, like a dropped one.
"""

from __future__ import annotations

import zlib
from functools import lru_cache
from importlib.resources import files
from typing import Any

import can
import cantools
import numpy as np

from skinkit_hardware import faults as F
from skinkit_hardware.device import Event
from skinkit_hardware.params import RobotParameters
from skinkit_hardware.wire.counts import counts_to_rows, rows_to_counts

COMMAND_CODES = {
    "hello": 1,
    "heartbeat": 2,
    "start": 8,
    "stop": 9,
    "estop": 10,
    "clear": 11,
    "hold": 12,
    "disable": 13,
}
COMMAND_NAMES = {v: k for k, v in COMMAND_CODES.items()}
EVENT_KINDS = {"home_done": 1, "run_end": 2, "fault": 3, "refused": 4}
EVENT_NAMES = {v: k for k, v in EVENT_KINDS.items()}
POSITION_UNIT_M = 5e-7
FORCE_UNIT_N = 1e-3
FRAME_BITS = 125  # 8-byte standard frame: 111 bits + worst-case-ish bit stuffing
#: the frames of one sample, the tick frame (which completes it) last
SAMPLE_FRAMES = ("ROBOT_SAMPLE_POSITION", "ROBOT_SAMPLE_CURRENT", "ROBOT_SAMPLE_FORCE",
                 "ROBOT_SAMPLE_TORQUE", "ROBOT_SAMPLE_TICK")
#: bits a streamed sample costs on the bus [bit]
WIRE_BITS_PER_SAMPLE = len(SAMPLE_FRAMES) * FRAME_BITS


@lru_cache(maxsize=1)
def database() -> cantools.database.can.Database:
    """The protocol's DBC, shipped with the package."""
    return cantools.database.load_string(
        files("skinkit_hardware").joinpath("skinkit_robot.dbc").read_text(), database_format="dbc"
    )


def _msg(name: str):  # noqa: ANN202
    return database().get_message_by_name(name)


def frame(name: str, **signals: Any) -> can.Message:
    """The CAN frame of message ``name`` with raw (unscaled) ``signals``."""
    m = _msg(name)
    return can.Message(arbitration_id=m.frame_id, data=m.encode(signals, scaling=False), is_extended_id=False)


def decode(msg: can.Message) -> tuple[str, dict[str, Any]] | None:
    """``(message name, raw signals)`` or None for a frame this protocol does not define."""
    try:
        m = database().get_message_by_frame_id(msg.arbitration_id)
    except KeyError:
        return None
    try:
        return m.name, m.decode(bytes(msg.data), scaling=False, decode_choices=False)
    except Exception:  # noqa: BLE001 - a malformed frame is counted, never fatal
        return None


# -- host -> device -----------------------------------------------------------------------
def encode_command(command: str, **args: Any) -> list[can.Message]:
    """The frames of one host ``command`` (a programme upload is several); :class:`DeviceFault` if unknown."""
    if command == "configure":
        return [
            frame(
                "HOST_CONFIGURE",
                Decimation=int(args.get("decimation", 10)),
                Watchdog=int(round(float(args.get("watchdog_s", 0.5)) * 1000)),
                TipForceLimit=int(round(float(args.get("tip_force_N", 0.0)) * 1000)),
            )
        ]
    if command == "home":
        return [
            frame(
                "HOST_HOME",
                ContactForce=int(round(float(args.get("contact_N", 0.01)) * 1e4)),
                Speed=int(round(float(args.get("speed_m_s", 0.002)) * 1e6)),
            )
        ]
    if command == "load":
        mode = args["mode"]
        sp = np.asarray(args["setpoints"], dtype=float)
        unit = POSITION_UNIT_M if mode == "position" else FORCE_UNIT_N
        raw = np.rint(sp / unit)
        if np.abs(raw).max() > 32767:
            raise F.DeviceFault(f"CAN protocol: setpoint {np.abs(sp).max():.4g} out of the 16-bit range")
        raw = raw.astype("<i2")
        out = [
            frame(
                "HOST_LOAD_BEGIN",
                Mode=0 if mode == "position" else 1,
                Count=sp.shape[0],
                Rate=int(round(float(args["rate_hz"]))),
                TriggerPeriod=int(round(float(args.get("trigger_period_s", 0.0)) * 1000)),
            )
        ]
        out += [
            frame(
                "HOST_LOAD_DATA",
                Index=i & 0xFFFF,
                Setpoint1=int(r[0]),
                Setpoint2=int(r[1]),
                Setpoint3=int(r[2]),
            )
            for i, r in enumerate(raw.tolist())
        ]
        out.append(frame("HOST_LOAD_END", Count=sp.shape[0], Checksum=zlib.crc32(raw.tobytes())))
        return out
    if command in COMMAND_CODES:
        return [frame("HOST_CMD", Command=COMMAND_CODES[command])]
    raise F.DeviceFault(f"CAN protocol: unknown command {command!r}")


class CommandAssembler:
    """Device side: frames -> ``(command, args)`` (reassembles programme uploads)."""

    def __init__(self) -> None:
        self.load: dict[str, Any] | None = None

    def feed(self, name: str, s: dict[str, Any]) -> tuple[str, dict[str, Any]] | None:
        """Feed one decoded frame; the ``(command, args)`` it completes, or None."""
        if name == "HOST_CMD":
            cmd = COMMAND_NAMES.get(int(s["Command"]))
            return (cmd, {}) if cmd else None
        if name == "HOST_CONFIGURE":
            return "configure", {
                "decimation": int(s["Decimation"]),
                "watchdog_s": s["Watchdog"] / 1000,
                "tip_force_N": s["TipForceLimit"] / 1000,
            }
        if name == "HOST_HOME":
            return "home", {"contact_N": s["ContactForce"] / 1e4, "speed_m_s": s["Speed"] / 1e6}
        if name == "HOST_LOAD_BEGIN":
            n = int(s["Count"])
            self.load = {
                "mode": "position" if s["Mode"] == 0 else "force",
                "n": n,
                "rate_hz": float(s["Rate"]),
                "trigger_period_s": s["TriggerPeriod"] / 1000,
                "data": np.zeros((n, 3), "<i2"),
                "next": 0,
            }
            return "heartbeat", {}
        if name == "HOST_LOAD_DATA" and self.load is not None:
            ld = self.load
            i = ld["next"]
            if i < ld["n"] and (i & 0xFFFF) == s["Index"]:
                ld["data"][i] = (s["Setpoint1"], s["Setpoint2"], s["Setpoint3"])
                ld["next"] = i + 1
            else:
                ld["bad"] = True
            return "heartbeat", {}
        if name == "HOST_LOAD_END" and self.load is not None:
            ld, self.load = self.load, None
            if ld.get("bad") or ld["next"] != ld["n"] or zlib.crc32(ld["data"].tobytes()) != s["Checksum"]:
                return "load_corrupt", {}
            unit = POSITION_UNIT_M if ld["mode"] == "position" else FORCE_UNIT_N
            return "load", {
                "mode": ld["mode"],
                "rate_hz": ld["rate_hz"],
                "setpoints": ld["data"].astype(float) * unit,
                "trigger_period_s": ld["trigger_period_s"],
            }
        return None


# -- device -> host -----------------------------------------------------------------------
def encode_samples(rows: np.ndarray, p: RobotParameters) -> list[list[can.Message]]:
    """Per sample, its five frames (tick frame last)."""
    c = rows_to_counts(rows, p)
    out = []
    for k in range(rows.shape[0]):
        i = int(c["index"][k]) & 0xFFFF
        pos, cur, fo, to = (c[n][k].tolist() for n in ("pos", "cur", "force", "torque"))
        out.append(
            [
                frame("ROBOT_SAMPLE_POSITION", Index=i, Position1=pos[0], Position2=pos[1], Position3=pos[2]),
                frame("ROBOT_SAMPLE_CURRENT", Index=i, Current1=cur[0], Current2=cur[1], Current3=cur[2]),
                frame("ROBOT_SAMPLE_FORCE", Index=i, ForceX=fo[0], ForceY=fo[1], ForceZ=fo[2]),
                frame("ROBOT_SAMPLE_TORQUE", Index=i, TorqueX=to[0], TorqueY=to[1], TorqueZ=to[2]),
                frame("ROBOT_SAMPLE_TICK", Index=i, Tick=int(c["tick"][k]), Flags=int(c["flags"][k])),
            ]
        )
    return out


def encode_event(ev: Event, p: RobotParameters) -> list[can.Message]:
    """The frames of event ``ev`` (value, time, then position when it has one)."""
    f = ev.fault or F.Fault(0)
    out = [
        frame("ROBOT_EVENT_VALUE", Value=f.value, Limit=f.limit),
        frame("ROBOT_EVENT_TIME", Time=f.time_s, Index=ev.index),
    ]
    if ev.q is not None:
        lo, hi = p.adc_span_m
        lsb = (hi - lo) / ((1 << p.adc_bits) - 1)
        q = [int(round((x - lo) / lsb)) for x in ev.q]
        out.append(frame("ROBOT_HOME_POSITION", Position1=q[0], Position2=q[1], Position3=q[2]))
    out.append(
        frame("ROBOT_EVENT", Kind=EVENT_KINDS[ev.kind], Code=f.code, Motor=f.motor, Generated=ev.generated)
    )
    return out


def encode_info(info: dict[str, Any]) -> list[can.Message]:
    """The device information frame of ``info``."""
    return [
        frame(
            "ROBOT_INFO",
            ControlRate=int(info["control_rate_hz"]),
            Decimation=int(info["decimation"]),
            Firmware=1,
        )
    ]


class SampleAssembler:
    """Host side: frames -> complete sample rows and events; unwraps the 16-bit index."""

    PARTS = {
        "ROBOT_SAMPLE_POSITION": "pos",
        "ROBOT_SAMPLE_CURRENT": "cur",
        "ROBOT_SAMPLE_FORCE": "force",
        "ROBOT_SAMPLE_TORQUE": "torque",
    }

    def __init__(self, p: RobotParameters) -> None:
        self.p = p
        self.pending: dict[int, dict[str, Any]] = {}
        self.incomplete = 0
        self.base = 0  # unwrapped index of the last completed sample
        self.last16 = -1
        self.event_parts: dict[str, Any] = {}
        self.info: dict[str, Any] = {}

    def reset(self) -> None:
        """Forget partial samples and the index unwrapping (a new run)."""
        self.pending.clear()
        self.base, self.last16 = 0, -1

    def feed(self, msgs: list[can.Message]) -> tuple[np.ndarray, list[Event]]:
        """The complete sample rows ``(n, 15)`` and the events in ``msgs``."""
        rows: dict[str, list] = {k: [] for k in ("index", "tick", "pos", "cur", "force", "torque", "flags")}
        events = []
        for msg in msgs:
            d = decode(msg)
            if d is None:
                continue
            name, s = d
            part = self.PARTS.get(name)
            if part is not None:
                keys = [k for k in s if k != "Index"]
                self.pending.setdefault(int(s["Index"]), {})[part] = [s[k] for k in keys]
            elif name == "ROBOT_SAMPLE_TICK":
                i16 = int(s["Index"])
                got = self.pending.pop(i16, {})
                idx = self._unwrap(i16)
                if len(got) == 4:
                    rows["index"].append(idx)
                    rows["tick"].append(int(s["Tick"]))
                    rows["flags"].append(int(s["Flags"]))
                    for k in ("pos", "cur", "force", "torque"):
                        rows[k].append(got[k])
                else:
                    self.incomplete += 1
                if len(self.pending) > 64:  # parts whose tick frame was lost
                    self.pending.clear()
            elif name in ("ROBOT_EVENT_VALUE", "ROBOT_EVENT_TIME", "ROBOT_HOME_POSITION"):
                self.event_parts[name] = s
            elif name == "ROBOT_EVENT":
                events.append(self._event(s))
            elif name == "ROBOT_INFO":
                self.info = {"control_rate_hz": s["ControlRate"], "decimation": s["Decimation"]}
        if rows["index"]:
            c = {k: np.asarray(v, dtype=np.int64) for k, v in rows.items()}
            return counts_to_rows(c, self.p), events
        return np.empty((0, 15)), events

    def _unwrap(self, i16: int) -> int:
        if self.last16 < 0:
            idx = i16
        else:
            idx = self.base + ((i16 - self.last16) & 0xFFFF)
        self.base, self.last16 = idx, i16
        return idx

    def _event(self, s: dict[str, Any]) -> Event:
        v = self.event_parts.pop("ROBOT_EVENT_VALUE", {"Value": float("nan"), "Limit": float("nan")})
        t = self.event_parts.pop("ROBOT_EVENT_TIME", {"Time": float("nan"), "Index": 0})
        hp = self.event_parts.pop("ROBOT_HOME_POSITION", None)
        kind = EVENT_NAMES.get(int(s["Kind"]), "fault")
        code = int(s["Code"])
        fault = (
            F.Fault(code, int(s["Motor"]), float(v["Value"]), float(v["Limit"]), float(t["Time"]))
            if code
            else None
        )
        q = None
        if hp is not None:
            lo, hi = self.p.adc_span_m
            lsb = (hi - lo) / ((1 << self.p.adc_bits) - 1)
            q = tuple(lo + hp[f"Position{i}"] * lsb for i in (1, 2, 3))
        if kind == "run_end" or kind == "fault":
            self.reset()
        return Event(kind, fault=fault, q=q, generated=int(s["Generated"]), index=int(t["Index"]))
