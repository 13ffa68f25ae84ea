"""Run the device emulator as a child process (tests, benchmarks, ``skinkit robot emulate``)."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from typing import Any

from skinkit_hardware.faults import DeviceFault


class EmulatorProcess:
    """``with EmulatorProcess("serial", "--speed", "0") as emu: emu.address`` -- the port
    (serial) or ``interface channel`` (CAN) the emulator announced. ``kill()`` ends it
    abruptly (fault injection); leaving the block terminates it."""

    def __init__(self, link: str, *args: str, startup_s: float = 60.0) -> None:
        self.link = link
        self.args = [sys.executable, "-m", "skinkit_hardware.emulator", link, *args]
        self.startup_s = startup_s
        self.proc: subprocess.Popen[str] | None = None
        self.address = ""

    def __enter__(self) -> EmulatorProcess:
        self.proc = subprocess.Popen(self.args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        t_end = time.monotonic() + self.startup_s
        line = ""
        while time.monotonic() < t_end:
            line = self.proc.stdout.readline()
            if line or self.proc.poll() is not None:
                break
        if not line.startswith(f"{self.link}: "):
            err = self.proc.stderr.read() if self.proc.poll() is not None else ""
            self.kill()
            raise DeviceFault(f"emulator did not start: {line.strip() or err.strip()[-300:]}")
        self.address = line.split(": ", 1)[1].strip()
        return self

    def kill(self) -> None:
        """Kill the emulator process if it is still running and wait for it."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(5)

    def __exit__(self, *exc: object) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        if self.proc is not None:
            for stream in (self.proc.stdout, self.proc.stderr):
                if stream:
                    stream.close()


def kill_after_samples(driver: Any, emu: EmulatorProcess, n: int = 200,
                       timeout_s: float = 30.0) -> threading.Thread:
    """Kill the emulator once ``driver`` has received ``n`` samples of its current run
    (or after ``timeout_s`` [s]): fault injection at a known point of a protocol."""

    def watch() -> None:
        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end:
            st = driver.last_run
            if st is not None and st.received >= n:
                break
            time.sleep(0.01)
        emu.kill()

    th = threading.Thread(target=watch, daemon=True)
    th.start()
    return th
