"""The skinkit command line: help everywhere, JSON shapes, one-line errors with exit status 2."""

from __future__ import annotations

import json
import subprocess
import sys

import click
import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.interfaces import GROUPS
from skinkit.schemas import Protocol, RobotRecord
from skinkit.store import create_experiment


def _all_commands(group: click.Group, ctx: click.Context, prefix: tuple[str, ...] = ()):
    for name in group.list_commands(ctx):
        cmd = group.get_command(ctx, name)
        yield (*prefix, name), cmd
        if isinstance(cmd, click.Group):
            yield from _all_commands(cmd, click.Context(cmd, parent=ctx), (*prefix, name))


def test_help_on_every_command():
    runner = CliRunner()
    assert runner.invoke(cli, ["--help"]).exit_code == 0
    ctx = click.Context(cli)
    seen = 0
    for path, _ in _all_commands(cli, ctx):
        res = runner.invoke(cli, [*path, "--help"])
        assert res.exit_code == 0, (path, res.output)
        assert "Usage:" in res.output
        seen += 1
    assert seen >= 4


@pytest.mark.parametrize(("args", "statuses"), [([], {"unchecked"}), (["--check"], {"ok", "error"})])
def test_plugins_json_has_all_groups(args, statuses):
    res = CliRunner().invoke(cli, ["plugins", "--json", *args])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert set(data["groups"]) == set(GROUPS) and data["checked"] == bool(args)
    for entries in data["groups"].values():
        for e in entries:
            assert set(e) >= {"name", "dist", "value", "status", "error"}
            assert e["status"] in statuses


def test_plugins_table():
    res = CliRunner().invoke(cli, ["plugins"])
    assert res.exit_code == 0 and "skinkit.laws" in res.output


def test_inspect_json_shape(tmp_path):
    path = tmp_path / "s.h5"
    with create_experiment(path) as exp:
        n = 200
        exp.write_record(RobotRecord(time_s=np.arange(n) / 500.0, tip_force=np.zeros((n, 3)),
                                     protocol=Protocol("normal_indentation")))
    res = CliRunner().invoke(cli, ["inspect", str(path), "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["schema_version"] == "1.0" and data["cameras"] == []
    (rec,) = data["records"]
    assert rec["protocol"] == "normal_indentation" and rec["samples"] == 200
    assert rec["rate_hz"] == pytest.approx(500.0) and rec["channels"] == ["tip_force"]
    assert rec["complete"] is True
    res = CliRunner().invoke(cli, ["inspect", str(path)])
    assert res.exit_code == 0 and "normal_indentation" in res.output


@pytest.mark.parametrize("content,needle", [
    (b"", "not an HDF5 file"),
    (b"time_s,force_N\n0,1\n", "not an HDF5 file"),
])
def test_inspect_bad_file_one_line_exit_2(tmp_path, content, needle):
    p = tmp_path / "bad.h5"
    p.write_bytes(content)
    proc = subprocess.run([sys.executable, "-m", "skinkit", "inspect", str(p)], capture_output=True,
                          text=True)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and needle in proc.stderr and proc.stderr.startswith("error: ")
    assert "Traceback" not in proc.stderr


def test_import_csv_then_inspect(tmp_path):
    csv = tmp_path / "ext.csv"
    csv.write_text("time_s,displacement_mm,force_N\n0,0,-0.077\n0.01,0.1,0.02\n0.02,0.2,0.05\n")
    exp = tmp_path / "e.h5"
    runner = CliRunner()
    res = runner.invoke(cli, ["import-csv", str(exp), str(csv), "--axis", "x"])
    assert res.exit_code == 0, res.output
    assert "imported 3 samples" in res.output
    data = json.loads(runner.invoke(cli, ["inspect", str(exp), "--json"]).stdout)
    assert data["records"][0]["protocol"] == "ext"
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,force_N\n0,1\n1,oops\n")
    res = runner.invoke(cli, ["import-csv", str(exp), str(bad)])
    assert res.exit_code == 2 and "line 3" in res.output and "'oops' is not a number" in res.output


@pytest.mark.needs_plugins
def test_demo_refuses_an_out_that_is_a_file(tmp_path):
    """The chain itself is tested end to end in tests/pipelines/test_chain.py (its quick variant);
    here only what the command checks before any work."""
    f = tmp_path / "taken"
    f.write_text("x")
    res = CliRunner().invoke(cli, ["demo", "--out", str(f)])
    assert res.exit_code == 2 and "--out" in res.output and "not a folder" in res.output
    assert f.read_text() == "x"


def test_demo_refuses_two_truth_meshes(tmp_path):
    res = CliRunner().invoke(cli, ["demo", "--out", str(tmp_path / "d"), "--shared-mesh",
                                   "--extrapolated-truth"])
    assert res.exit_code == 2 and "--extrapolated-truth" in res.output and "--shared-mesh" in res.output
    assert not (tmp_path / "d").exists()


def test_recover_after_a_crash(tmp_path):
    crashed = tmp_path / "crashed.h5"
    code = ("import os, numpy as np\n"
            "from skinkit.schemas import Protocol, RobotRecord\n"
            "from skinkit.store import create_experiment\n"
            f"exp = create_experiment({str(crashed)!r})\n"
            "w = exp.record_writer(Protocol('p'), ['tip_force'], 100.0).__enter__()\n"
            "w.append(RobotRecord(time_s=np.arange(50) / 100, tip_force=np.ones((50, 3))))\n"
            "os._exit(1)  # die without closing anything\n")
    subprocess.run([sys.executable, "-c", code], check=False)
    out = tmp_path / "ok.h5"
    res = CliRunner().invoke(cli, ["recover", str(crashed), str(out)])
    assert res.exit_code == 0, res.output
    assert "p: 50 samples (incomplete)" in res.output
    res = CliRunner().invoke(cli, ["recover", str(crashed), str(out)])
    assert res.exit_code == 2 and "already exists" in res.output
