"""``skinkit bench cli``: the figures are there and consistent (no wall-clock assertion)."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from skinkit.cli import cli


def test_bench_cli_json():
    r = CliRunner().invoke(cli, ["bench", "cli", "--json", "--repeat", "1", "--robot-seconds", "0.5"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    for key in ("plugins_s", "robot_protocols_s", "version_s"):
        assert d[key] > 0, key
    assert d["meets_targets"]["plugins"] == (d["plugins_s"] < d["plugins_target_s"])
    rob = d["robot"]
    if "skipped" in rob:
        assert d["robot_realtime_factor"] is None
        return
    # one 0.5 s period streamed at 1 kHz: the last sample is at 0.499 s
    assert rob["device_s"] == pytest.approx(0.5, abs=2e-3) and rob["samples"] == 500
    assert d["robot_realtime_factor"] == pytest.approx(rob["device_s"] / rob["wall_s"])
