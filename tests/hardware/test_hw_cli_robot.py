"""``skinkit robot protocols|run|emulate`` from the command line (real subprocess for emulate)."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from skinkit.cli import cli

pytestmark = pytest.mark.needs_hardware
pytest.importorskip("skinkit_hardware")

from skinkit.store import open_experiment  # noqa: E402


def test_protocols_json_lists_the_thesis_protocols() -> None:
    res = CliRunner().invoke(cli, ["robot", "protocols", "--json"])
    assert res.exit_code == 0, res.output
    items = {p["name"]: p for p in json.loads(res.stdout)["protocols"]}
    assert len([n for n in items if n.startswith("in_plane_")]) == 12
    assert {
        "preconditioning",
        "normal_indentation",
        "normal_retraction",
        "stochastic_full_scale",
        "incremental_a",
        "incremental_b",
    } <= set(items)
    oop = [p for n, p in items.items() if n.startswith("out_of_plane_")]
    assert len(oop) == 3 and all(p["parameters"]["phi"] == 45.0 for p in oop)
    ni = items["normal_indentation"]
    # Table 12: 1.5 mm peak to peak, 0.1 Hz, three periods -> 30 s
    assert ni["parameters"]["peak_to_peak"] == 1.5e-3 and ni["parameters"]["frequency"] == 0.1
    assert ni["duration_s"] == pytest.approx(30.0)


def test_run_writes_the_record_and_refuses_with_one_line(tmp_path) -> None:
    out = tmp_path / "exp.h5"
    r = CliRunner().invoke(
        cli,
        [
            "robot",
            "run",
            "in_plane_120",
            "--param",
            "frequency=1",
            "--param",
            "periods=1",
            "--out",
            str(out),
            "--json",
        ],
    )
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["samples"] == 1000
    assert open_experiment(out).read_record("in_plane_120").n_samples == 1000
    r = CliRunner().invoke(
        cli, ["robot", "run", "normal_indentation", "--param", "peak_to_peak=0.01", "--out", str(out)]
    )
    assert r.exit_code == 2
    assert "refused before motion: travel limit" in r.output
    assert "normal_indentation" not in open_experiment(out).record_names()  # nothing recorded
    r = CliRunner().invoke(cli, ["robot", "run", "nope", "--out", str(out)])
    assert r.exit_code == 2 and "unknown protocol 'nope'" in r.output
    r = CliRunner().invoke(
        cli, ["robot", "run", "normal_indentation", "--driver", "serial", "--out", str(out)]
    )
    assert r.exit_code == 2 and "no port given" in r.output


def test_run_over_serial_against_the_emulate_command(tmp_path) -> None:
    from skinkit_hardware.testing import EmulatorProcess

    out = tmp_path / "serial.h5"
    with EmulatorProcess("serial", "--speed", "0", "--baud", "0") as emu:
        r = CliRunner().invoke(
            cli,
            [
                "robot",
                "run",
                "normal_indentation",
                "--driver",
                "serial",
                "--port",
                emu.address,
                "--param",
                "frequency=1",
                "--param",
                "periods=1",
                "--out",
                str(out),
                "--json",
            ],
        )
    assert r.exit_code == 0, r.output
    assert open_experiment(out).read_record("normal_indentation").n_samples == 1000


def test_emulate_command_is_contributed_by_the_hardware_distribution() -> None:
    r = CliRunner().invoke(cli, ["robot", "emulate", "--help"])
    assert r.exit_code == 0 and "--serial" in r.output and "--can" in r.output


def test_emulate_serial_prints_the_port_it_serves() -> None:
    import os
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", "skinkit", "robot", "emulate", "--serial", "--speed", "0"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()
        assert line.startswith("serial: /dev/")
        assert os.path.exists(line.split(": ", 1)[1].strip())
    finally:
        proc.terminate()
        proc.wait(10)
        proc.stdout.close()
