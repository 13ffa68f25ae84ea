"""``skinkit bench robot``: sustained sample rate over each robot link, losses counted.

For each link (serial at a stated baud rate, CAN at a stated bit rate) the device emulator
runs in real time in its own process (started through ``skinkit robot emulate``, so the
core imports no hardware code) and streams a normal indentation at a chosen decimation of
its 10 kHz control loop. The device's control loop never waits for the link: samples go
into its bounded transmit buffer and a full buffer drops them with their indices consumed,
so the host counts every loss. The peer figure is the link's theoretical sample capacity
(serial: 10 bits per byte, 30-byte samples in 32-sample frames of 16 bytes overhead; CAN:
five 8-byte frames of ~125 bits per sample); the ratio is sustained / min(offered, capacity).
The device buffer is set to 8 KiB so that a link slower than the offered rate shows
counted losses within a few seconds rather than a long drain. "Sustained" is samples
received per second of host wall time, from the start command to the end of the run; the
emulator's real-time factor (device seconds per wall second) is reported beside it, since
on a loaded machine the Python device model itself can fall behind real time, which lowers
the offered rate; the ratio uses the offered rate scaled by that factor.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from typing import Any

import click

from skinkit.cli._types import FiniteFloat
from skinkit.errors import SkinkitError

SERIAL_SAMPLE_BYTES = 30 + 16 / 32
CAN_SAMPLE_BITS = 5 * 125


def _emulator(link: str, speed_arg: list[str]) -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "skinkit",
            "robot",
            "emulate",
            f"--{link}",
            "--speed",
            "1",
            "--buffer-bytes",
            "8192",
            *speed_arg,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    line = proc.stdout.readline()
    if not line.startswith(f"{link}: "):
        proc.kill()
        raise SkinkitError(
            f"bench robot: the {link} emulator did not start ({line.strip() or proc.stderr.read()[-200:]})"
        )
    return proc, line.split(": ", 1)[1].strip()


def measure(link: str, rate_param: int, stream_hz: float, duration_s: float) -> dict[str, Any]:
    """Run one link configuration; returns offered, capacity and sustained rates and losses."""
    from skinkit import registry
    from skinkit.acquisition import make_protocol

    decimation = max(1, int(round(10_000 / stream_hz)))
    offered = 10_000 / decimation
    if link == "serial":
        proc, port = _emulator("serial", ["--baud", str(rate_param)])
        capacity = rate_param / 10 / SERIAL_SAMPLE_BYTES
    else:
        proc, port = _emulator("can", ["--bitrate", str(rate_param)])
        capacity = rate_param / CAN_SAMPLE_BITS
    try:
        driver = registry.create("skinkit.drivers", link)
        opts: dict[str, Any] = {"port": port, "decimation": decimation}
        if link == "serial":
            opts["baudrate"] = rate_param
        else:
            opts["bitrate"] = rate_param
        driver.connect(**opts)
        driver.home()
        proto = make_protocol("normal_indentation", frequency=1.0 / duration_s, periods=1)
        t0 = time.monotonic()
        n = 0
        t_dev = 0.0
        for block in driver.run(proto):
            n += block.n_samples
            t_dev = float(block.time_s[-1])
        wall = time.monotonic() - t0
        stats = driver.last_run
        driver.disconnect()
    finally:
        proc.terminate()
        proc.wait(5)
    return {
        "link": link,
        "rate": rate_param,
        "unit": "baud" if link == "serial" else "bit/s",
        "offered_hz": offered,
        "capacity_hz": capacity,
        "sustained_hz": n / max(wall, 1e-9),
        "received": n,
        "lost": stats.lost,
        "generated": stats.generated,
        "device_s": t_dev,
        "wall_s": wall,
        "realtime_factor": t_dev / max(wall, 1e-9),
        "ratio": (n / max(wall, 1e-9)) / min(offered * min(1.0, t_dev / max(wall, 1e-9)), capacity),
    }


@click.command("robot")
@click.option("--duration", type=FiniteFloat(0.1, 600.0), default=3.0, show_default=True,
              help="device seconds per configuration")
@click.option("--json", "as_json", is_flag=True)
def bench_robot(duration: float, as_json: bool) -> None:
    """Sustained sample rate over serial (115200, 921600 baud) and CAN (500k, 1M bit/s); one
    configuration per link offers more than the link carries, to show losses being counted."""
    configs = [
        ("serial", 115_200, 500.0),
        ("serial", 921_600, 1000.0),
        ("serial", 921_600, 2000.0),
        ("can", 500_000, 500.0),
        ("can", 1_000_000, 1000.0),
        ("can", 1_000_000, 2000.0),
    ]
    rows = [measure(link, rate, hz, duration) for link, rate, hz in configs]
    if as_json:
        click.echo(json.dumps({"robot_links": rows}, indent=1))
        return
    from rich.console import Console
    from rich.table import Table

    t = Table(title="robot link throughput (emulator in real time, 10 kHz control loop)")
    for col in ("link", "rate", "offered Hz", "capacity Hz", "sustained Hz", "real-time", "lost", "ratio"):
        t.add_column(col)
    for r in rows:
        t.add_row(
            r["link"],
            f"{r['rate']} {r['unit']}",
            f"{r['offered_hz']:.0f}",
            f"{r['capacity_hz']:.0f}",
            f"{r['sustained_hz']:.0f}",
            f"{r['realtime_factor']:.2f}",
            f"{r['lost']}/{r['generated']}",
            f"{r['ratio']:.2f}",
        )
    Console().print(t)
