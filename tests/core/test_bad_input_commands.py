"""Bad options of robot run / emulate, recover, import-csv, sysid and bench:
one ``error:`` line naming the option, exit 2, nothing written, no file changed."""

from __future__ import annotations

import socket

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.schemas import Protocol, RobotRecord
from skinkit.store import create_experiment
from tests.core._cli import one_error


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


def _tree(root) -> dict:
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in sorted(root.rglob("*"))}


@pytest.mark.needs_plugins
@pytest.mark.parametrize(("args", "needles"), [
    (["--param", "setpoint_rate=1e9"], ["setpoints", "over the limit"]),
    (["--param", "frequency=1e-9"], ["setpoints", "over the limit"]),
    (["--param", "frequency=inf"], ["frequency"]),
    (["--param", "peak_to_peak=1"], ["travel limit"]),
    (["--option", "seed=abc"], ["--option seed=abc", "whole number"]),
    (["--option", "decimation=0"], ["--option decimation=0", "[1, 1000]"]),
    (["--option", "decimation=-2"], ["--option decimation=-2"]),
    (["--contact-force", "-1"], ["'--contact-force'"]),
    (["--contact-force", "0"], ["'--contact-force'"]),
    (["--driver", "serial", "--port", "/dev/null", "--option", "baudrate=-5"], ["baudrate"]),
])
def test_robot_run_refuses_and_leaves_no_file(tmp_path, args, needles):
    out = tmp_path / "r.h5"
    one_error(_run("robot", "run", "normal_indentation", *args, "--out", str(out)), *needles)
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.needs_plugins
def test_robot_run_refusal_keeps_existing_file(tmp_path):
    out = tmp_path / "r.h5"
    assert _run("robot", "run", "preconditioning", "--param", "hold=0.2", "--out", str(out),
                "--json").exit_code == 0
    before = _tree(tmp_path)
    one_error(_run("robot", "run", "normal_indentation", "--param", "peak_to_peak=1",
                    "--out", str(out)), "travel limit")
    one_error(_run("robot", "run", "preconditioning", "--out", str(out)), "already holds")
    assert _tree(tmp_path) == before


@pytest.mark.needs_plugins
@pytest.mark.parametrize(("args", "option"), [
    (["--port", "70000"], "'--port'"), (["--port", "-1"], "'--port'"),
    (["--baud", "-1"], "'--baud'"), (["--bitrate", "-3"], "'--bitrate'"),
    (["--speed", "-1"], "'--speed'"), (["--buffer-bytes", "-5"], "'--buffer-bytes'"),
    (["--skin", "rubber"], "'--skin'"),
])
def test_robot_emulate_options_out_of_range(args, option):
    one_error(_run("robot", "emulate", *args), option)


@pytest.mark.needs_plugins
def test_robot_emulate_busy_can_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        one_error(_run("robot", "emulate", "--can", "--port", str(port)), f"--port {port}", "in use")


def _experiment(path, n=400):
    with create_experiment(path) as exp:
        exp.write_record(RobotRecord(time_s=np.arange(n) / 500.0, tip_force=np.zeros((n, 3)),
                                     protocol=Protocol("normal_indentation")))
    return path


def test_recover_into_missing_folder_or_onto_a_file(tmp_path):
    src = _experiment(tmp_path / "a.h5")
    one_error(_run("recover", str(src), str(tmp_path / "missing" / "b.h5")), "OUT", "does not exist")
    one_error(_run("recover", str(src), str(src / "b.h5")), "OUT")
    one_error(_run("recover", str(src), str(src)), "already exists")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.h5"]
    ok = _run("recover", str(src), str(tmp_path / "b.h5"))
    assert ok.exit_code == 0, ok.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.h5", "b.h5"]


def test_recover_refuses_an_impossible_committed_count(tmp_path):
    import h5py
    src = _experiment(tmp_path / "a.h5")
    with h5py.File(src, "a") as f:
        f["records/normal_indentation/committed"][0] = 10**9
    one_error(_run("recover", str(src), str(tmp_path / "b.h5")), "committed")
    assert not (tmp_path / "b.h5").exists()


@pytest.mark.parametrize("name", ["../evil", "a/b", "..", "x\\y", " "])
def test_import_csv_refuses_path_like_record_names(tmp_path, name):
    csv = tmp_path / "r.csv"
    csv.write_text("time_s,force_N\n0,0\n0.01,1\n0.02,2\n")
    exp = _experiment(tmp_path / "e.h5")
    before = _tree(tmp_path)
    one_error(_run("import-csv", str(exp), str(csv), "--protocol", name), "--protocol")
    one_error(_run("import-csv", str(tmp_path / "new.h5"), str(csv), "--protocol", name), "--protocol")
    assert _tree(tmp_path) == before


def test_import_csv_bad_csv_creates_no_experiment(tmp_path):
    csv = tmp_path / "r.csv"
    csv.write_text("time_s,force_N\n0,0\n0.01,oops\n")
    one_error(_run("import-csv", str(tmp_path / "new.h5"), str(csv)), "oops")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv"]


@pytest.mark.parametrize(("args", "option"), [
    (["--robot-mass", "-1"], "'--robot-mass'"), (["--robot-mass", "nan"], "'--robot-mass'"),
    (["--robot-damping", "inf"], "'--robot-damping'"), (["--robot-stiffness", "-5"], "'--robot-stiffness'"),
    (["--memory", "0"], "'--memory'"), (["--memory", "nan"], "'--memory'"),
    (["--probe-radius", "-1"], "'--probe-radius'"),
])
def test_sysid_physical_options(tmp_path, args, option):
    rec = _experiment(tmp_path / "a.h5")
    one_error(_run("sysid", str(rec), *args), option)


@pytest.mark.parametrize(("args", "option"), [
    (["store", "--blocks", "0"], "'--blocks'"), (["store", "--block", "-1"], "'--block'"),
    (["fem", "--n", "0"], "'--n'"), (["robot", "--duration", "-1"], "'--duration'"),
    (["vision", "--trials", "0"], "'--trials'"), (["vision", "--subset", "-4"], "'--subset'"),
    (["sysid", "--repeat", "0"], "'--repeat'"), (["fit", "--seed", "-1"], "'--seed'"),
    (["coverage", "--mesh", "own", "--truth-factor", "1"], "'--truth-factor'"),
    (["coverage", "--truth-factor", "3"], "--truth-factor"),
    (["coverage", "--mesh", "extrapolated", "--truth-factor", "2"], "--truth-factor"),
    (["coverage", "--mesh", "nope"], "'--mesh'"),
])
def test_bench_bad_counts(args, option):
    one_error(_run("bench", *args), option)
