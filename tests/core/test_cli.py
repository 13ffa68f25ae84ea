"""The skinkit command line: help everywhere, JSON shapes, one-line errors with exit status 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.protocols import GROUPS
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
    data = json.loads(res.output)
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
    data = json.loads(res.output)
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
    res = runner.invoke(cli, ["import-csv", str(csv), str(exp), "--axis", "x"])
    assert res.exit_code == 0, res.output
    assert "imported 3 samples" in res.output
    data = json.loads(runner.invoke(cli, ["inspect", str(exp), "--json"]).output)
    assert data["records"][0]["protocol"] == "ext"
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,force_N\n0,1\n1,oops\n")
    res = runner.invoke(cli, ["import-csv", str(bad), str(exp)])
    assert res.exit_code == 2 and "line 3" in res.output and "'oops' is not a number" in res.output


def test_demo_runs(tmp_path):
    res = CliRunner().invoke(cli, ["demo", "--out", str(tmp_path / "d"), "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    samples = {r["protocol"]: r["samples"] for r in data["store"]["records"]}
    assert samples["stochastic_linear"] == samples["stochastic_wiener"] == 10000
    assert all(r["complete"] for r in data["store"]["records"])
    assert data["store"]["fits"] == ["linear", "wiener"]
    # 5 s at 2 kHz with 30 dB noise: the sysid tests show errors below ~1 %; 3 % is the
    # acceptance bound of issue 4 for K, B, I and 5 % for C1, C2.
    assert all(abs(e) < 3.0 for e in data["linear_error_pct"].values()), data["linear_error_pct"]
    assert abs(data["wiener_error_pct"]["C1"]) < 5.0 and abs(data["wiener_error_pct"]["C2"]) < 5.0
    assert data["wiener"]["vaf_wiener_pct"] > data["wiener"]["vaf_linear_pct"]
    for plot in data["plots"]:
        assert Path(plot).stat().st_size > 10_000
    rob = data["robot"]
    if "skipped" not in rob:
        # Position control to the Table 12 amplitude; 30 s at 1 kHz, no sample lost in-process.
        assert rob["samples"] == samples["normal_indentation"] == 30000 and rob["lost"] == 0
        assert abs(rob["tip_travel_pp_m"][2] - 1.5e-3) < 0.05e-3
    fem = data["fem"]
    if "skipped" not in fem:
        w, wo = fem["with_prestretch"], fem["without_prestretch"]
        # Force control: the solved tip force is the prescribed 20 mN to solver tolerance.
        assert abs(w["tip_force_N"][2] + 0.02) < 1e-9 and abs(wo["tip_force_N"][2] + 0.02) < 1e-9
        # In-plane tension adds a membrane stiffness to the out-of-plane response.
        assert 0 < -w["tip_displacement_m"][2] < -wo["tip_displacement_m"][2]
        assert Path(w["paraview"]).exists()
        for v in (w, wo):  # one count: the demo reports what the FE run's own summary says
            fe = json.loads((Path(v["paraview"]).parent / "summary.json").read_text())
            assert v["newton_iterations"] == fe["newton_iterations"]
    vis = data["vision"]
    if "skipped" in vis:
        assert "skinkit.profilers:patchwork" in vis["skipped"] or "skinkit.trackers:gn" in vis["skipped"]
    else:
        assert data["store"]["cameras"] and data["store"]["profiles"][0]["points"] == vis["profile_points"]
        assert vis["reprojection_rms_px"] < 0.3  # the thesis's rig reached 0.2 px on real optics
        # Issue 5's bounds: 20 um 3D error over the field, no profile outlier beyond 100 um.
        assert vis["profile_error_um"]["rms"] <= 20 and vis["profile_error_um"]["max"] <= 100
        assert vis["track_error_um"]["rms"] <= 20 and vis["tracked_fraction"] > 0.9


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
