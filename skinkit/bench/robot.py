"""``skinkit bench robot``: sustained sample rate over each robot link, losses counted.

For each link (serial at a stated baud rate, CAN at a stated bit rate) the device emulator
runs in real time in its own process (started through ``skinkit robot emulate``, so the
core imports no hardware code) and streams a normal indentation at a chosen decimation of
its 10 kHz control loop. The device's control loop never waits for the link: samples go
into its bounded transmit buffer and a full buffer drops them with their indices consumed,
so the host counts every loss. The peer figure is the link's theoretical sample capacity, the
line rate over the bits a sample costs on the wire as the driver declares them (its
``wire_bits_per_sample``; ``line_rate_option`` names the ``connect`` option that sets the
rate); the ratio is sustained / min(offered, capacity). A driver that does not declare its
wire cost gets capacity "unknown" and the ratio sustained / offered.
The device buffer is set to 8 KiB so that a link slower than the offered rate shows
counted losses within a few seconds rather than a long drain. "Sustained" is samples
received per second of host wall time, from the start command to the end of the run; the
emulator's real-time factor (device seconds per wall second) is reported beside it, since
on a loaded machine the Python device model itself can fall behind real time, which lowers
the offered rate; the ratio uses the offered rate scaled by that factor.
"""

from __future__ import annotations

import subprocess
import sys
import time
from typing import Any

from skinkit.errors import SkinkitError


def link_capacity_hz(driver: Any, line_rate: float) -> float | None:
    """Samples per second a link at ``line_rate`` [bit/s or baud] carries for ``driver``, from
    the bits per sample it declares (``wire_bits_per_sample``); None when it declares none."""
    bits = getattr(driver, "wire_bits_per_sample", None)
    if isinstance(bits, bool) or not isinstance(bits, (int, float)) or not bits > 0:
        return None
    return line_rate / float(bits)


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
    driver = registry.create("skinkit.drivers", link)
    capacity = link_capacity_hz(driver, rate_param)
    opts: dict[str, Any] = {"decimation": decimation}
    rate_option = getattr(driver, "line_rate_option", None)
    if isinstance(rate_option, str) and rate_option:
        opts[rate_option] = rate_param
    proc, opts["port"] = _emulator(link, ["--baud" if link == "serial" else "--bitrate", str(rate_param)])
    try:
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
        # a driver's own accounting of the run, when it keeps one (skinkit-hardware's do)
        stats = getattr(driver, "last_run", None)
        driver.disconnect()
    finally:
        proc.terminate()
        proc.wait(5)
    rt = min(1.0, t_dev / max(wall, 1e-9))
    peer = offered * rt if capacity is None else min(offered * rt, capacity)
    return {
        "link": link,
        "rate": rate_param,
        "unit": "baud" if link == "serial" else "bit/s",
        "offered_hz": offered,
        "capacity_hz": capacity,
        "sustained_hz": n / max(wall, 1e-9),
        "received": n,
        "lost": getattr(stats, "lost", None),
        "generated": getattr(stats, "generated", None),
        "device_s": t_dev,
        "wall_s": wall,
        "realtime_factor": t_dev / max(wall, 1e-9),
        "ratio": (n / max(wall, 1e-9)) / peer,
    }


#: (link, line rate [baud or bit/s], offered sample rate [Hz]): one configuration per link
#: offers more than the link carries, to show losses being counted
CONFIGS: tuple[tuple[str, int, float], ...] = (
    ("serial", 115_200, 500.0),
    ("serial", 921_600, 1000.0),
    ("serial", 921_600, 2000.0),
    ("can", 500_000, 500.0),
    ("can", 1_000_000, 1000.0),
    ("can", 1_000_000, 2000.0),
)


def run(duration_s: float = 3.0) -> dict[str, Any]:
    """Every configuration of :data:`CONFIGS` for ``duration_s`` device seconds:
    ``{"robot_links": [measure(...), ...]}``."""
    return {"robot_links": [measure(link, rate, hz, duration_s) for link, rate, hz in CONFIGS]}


def table_rows(res: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    """Column titles and one row of text per configuration, for a table of :func:`run`'s figures."""
    cols = ["link", "rate", "offered Hz", "capacity Hz", "sustained Hz", "real-time", "lost", "ratio"]
    rows = [[r["link"], f"{r['rate']} {r['unit']}", f"{r['offered_hz']:.0f}",
             "unknown" if r["capacity_hz"] is None else f"{r['capacity_hz']:.0f}",
             f"{r['sustained_hz']:.0f}", f"{r['realtime_factor']:.2f}",
             "unknown" if r["lost"] is None else f"{r['lost']}/{r['generated']}", f"{r['ratio']:.2f}"]
            for r in res["robot_links"]]
    return cols, rows
