"""``skinkit bench cli``: how fast the listing commands answer, and how fast the simulated
robot runs against real time.

``plugins_s`` and ``robot_protocols_s`` are the wall times of ``skinkit plugins`` and
``skinkit robot protocols`` in a fresh interpreter (a subprocess: start-up and imports are
what a user waits for), best of ``--repeat``. ``robot_realtime_factor`` is simulated
seconds per wall second of the ``sim`` driver (skinkit-hardware) running a short normal
indentation (one 1.5 mm sinusoid of ``--robot-seconds``) after homing, in this process;
above 1 the simulation runs faster than the robot would. The targets are
``plugins_s < 1`` and ``robot_realtime_factor >= 1``; the figures depend on the machine's
load (reported) and on whether Python may cache bytecode (without a cache every start-up
compiles every module it imports).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from typing import Any

#: the targets: a listing answers within a second; the simulated robot keeps up with real time
PLUGINS_TARGET_S = 1.0
REALTIME_TARGET = 1.0


def command_wall_s(args: list[str], repeat: int = 3) -> float:
    """Best wall time [s] of ``python -m skinkit ARGS`` in a fresh interpreter over ``repeat``
    runs (output discarded; a failing command raises :class:`SkinkitError`)."""
    from skinkit.errors import SkinkitError

    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "skinkit", *args], capture_output=True,
                              text=True)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            tail = (proc.stderr.strip().splitlines() or ["no message"])[-1]
            raise SkinkitError(f"bench cli: skinkit {' '.join(args)} failed ({tail})")
        best = min(best, wall)
    return best


def robot_realtime_factor(seconds: float = 2.0, skin: str = "kelvin-voigt") -> dict[str, Any]:
    """Simulated seconds per wall second of the ``sim`` driver over a ``seconds``-long normal
    indentation (homing not counted). Returns the factor, the device and wall seconds and the
    samples, or ``{"skipped": reason}`` without the driver plugin."""
    from skinkit import registry
    from skinkit.acquisition import make_protocol

    if "sim" not in registry.names("skinkit.drivers"):
        return {"skipped": "needs the driver plugin skinkit.drivers:sim (skinkit-hardware)"}
    driver = registry.create("skinkit.drivers", "sim")
    driver.connect(skin=skin)
    try:
        driver.home()
        proto = make_protocol("normal_indentation", frequency=1.0 / seconds, periods=1)
        samples, device_s = 0, 0.0
        t0 = time.perf_counter()
        for block in driver.run(proto):
            samples += block.n_samples
            device_s = float(block.time_s[-1])
        wall = time.perf_counter() - t0
    finally:
        driver.disconnect()
    return {"factor": device_s / wall, "device_s": device_s, "wall_s": wall, "samples": samples,
            "skin": skin}


def run(repeat: int = 3, robot_seconds: float = 2.0) -> dict[str, Any]:
    """All figures as a JSON-ready dict (see the module docstring)."""
    plugins_s = command_wall_s(["plugins"], repeat)
    protocols_s = command_wall_s(["robot", "protocols"], repeat)
    version_s = command_wall_s(["--version"], repeat)
    robot = robot_realtime_factor(robot_seconds)
    rtf = robot.get("factor")
    return {
        "plugins_s": plugins_s,
        "robot_protocols_s": protocols_s,
        "version_s": version_s,
        "plugins_target_s": PLUGINS_TARGET_S,
        "robot_realtime_factor": rtf,
        "robot_realtime_target": REALTIME_TARGET,
        "robot": robot,
        "meets_targets": {"plugins": plugins_s < PLUGINS_TARGET_S,
                          "robot": None if rtf is None else rtf >= REALTIME_TARGET},
        "repeat": repeat,
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "cpu_count": os.cpu_count(),
        "bytecode_cache": not sys.dont_write_bytecode,
    }


def table_rows(res: dict[str, Any]) -> list[tuple[str, str, str, bool | None]]:
    """(figure, measured, target, met) per row of a table of :func:`run`'s figures."""
    rtf = res["robot_realtime_factor"]
    return [("skinkit plugins", f"{res['plugins_s']:.2f} s", f"< {PLUGINS_TARGET_S:g} s",
             res["meets_targets"]["plugins"]),
            ("skinkit robot protocols", f"{res['robot_protocols_s']:.2f} s", "", None),
            ("skinkit --version (start-up)", f"{res['version_s']:.2f} s", "", None),
            ("sim robot real-time factor", "-" if rtf is None else f"{rtf:.2f}", f">= {REALTIME_TARGET:g}",
             res["meets_targets"]["robot"])]


def context_lines(res: dict[str, Any]) -> list[str]:
    """What the figures depend on: the machine's load, the bytecode cache, a skipped robot run."""
    load = res["load_average_1min"]
    cache = "on" if res["bytecode_cache"] else "off (every start-up compiles what it imports)"
    out = [("" if load is None else f"load average {load:.1f} on {res['cpu_count']} CPUs; ")
           + f"bytecode cache {cache}"]
    if "skipped" in res["robot"]:
        out.append(f"robot: skipped ({res['robot']['skipped']})")
    return out
