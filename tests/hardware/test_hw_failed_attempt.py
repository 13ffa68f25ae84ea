"""A robot run that fails before (or while) recording still leaves the experiment file with
the protocol, the attempt and the reason, and the CLI says it in one line.
The serial driver runs against a real pseudo-terminal: one nobody answers on, and the
emulator process killed as the run starts."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.needs_hardware
pytest.importorskip("skinkit_hardware")

from skinkit_hardware.testing import EmulatorProcess  # noqa: E402

from skinkit.store import open_experiment  # noqa: E402


def _skinkit(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "skinkit", *args], capture_output=True, text=True,
                          timeout=300)


def _one_error(r: subprocess.CompletedProcess, *words: str) -> str:
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def test_driver_that_cannot_connect_leaves_the_attempt_and_a_retry_still_records(tmp_path) -> None:
    out = tmp_path / "s.h5"
    master, slave = os.openpty()  # a serial line with no device behind it
    try:
        port = os.ttyname(slave)
        line = _one_error(_skinkit("robot", "run", "normal_indentation", "--driver", "serial",
                                   "--port", port, "--out", str(out)), "no answer", port)
    finally:
        os.close(master)
        os.close(slave)
    with open_experiment(out) as exp:
        assert exp.record_names() == []
        (a,) = exp.attempts()
    assert a["protocol"]["name"] == "normal_indentation" and a["driver"] == "serial"
    assert a["stage"] == "connect" and a["samples"] == 0 and a["record"] is None
    assert a["reason"] in line and a["options"] == {"port": port} and a["started"]
    shown = _skinkit("inspect", str(out))
    assert shown.returncode == 0 and "failed run 0001: normal_indentation" in shown.stdout
    # the failed attempt does not block the protocol: a later run into the same file records it
    ok = _skinkit("robot", "run", "normal_indentation", "--param", "periods=1", "--param", "frequency=2",
                  "--out", str(out), "--json")
    assert ok.returncode == 0, ok.stderr
    with open_experiment(out) as exp:
        assert exp.record_names() == ["normal_indentation"]
        assert exp.record_info("normal_indentation")["complete"] is True
        assert [x["name"] for x in exp.attempts()] == ["0001"]


def test_device_killed_as_the_run_starts_leaves_the_attempt(tmp_path) -> None:
    """The emulator is killed the moment the run opens its record, i.e. while the long
    programme is uploaded (before the first sample) or at the latest within its first samples;
    either way the file holds the attempt, and exactly the samples received."""
    out = tmp_path / "k.h5"
    with EmulatorProcess("serial", "--speed", "1", "--baud", "0") as emu:
        p = subprocess.Popen([sys.executable, "-m", "skinkit", "robot", "run", "incremental_a",
                              "--driver", "serial", "--port", emu.address, "--out", str(out), "--json"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            while not out.exists() and p.poll() is None:
                time.sleep(0.001)
            emu.kill()
            stdout, stderr = p.communicate(timeout=300)
        finally:
            if p.poll() is None:
                p.kill()
                p.wait()
    line = _one_error(subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr), "serial")
    assert stdout == ""
    with open_experiment(out) as exp:
        (a,) = exp.attempts()
        names = exp.record_names()
        kept = exp.record_info("incremental_a") if names else None
    assert a["protocol"]["name"] == "incremental_a" and a["stage"] == "run"
    assert a["reason"] in line and a["error"] == "DeviceFault"
    assert a["link"]["received"] == a["samples"]
    if a["samples"] == 0:         # failed during the upload: no empty record left behind
        assert names == [] and a["record"] is None
    else:                         # the first samples arrived first: kept, marked incomplete
        assert names == ["incremental_a"] and kept["samples"] == a["samples"]
        assert kept["complete"] is False
