"""Listing commands import only what they list: ``skinkit plugins`` reads
entry-point metadata and imports no plugin (nor numpy); ``skinkit robot protocols`` builds
no programme (no scipy). Checked on the modules a fresh interpreter has imported, not on
wall time, so the tests hold on a loaded machine."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from skinkit import registry
from skinkit.interfaces import GROUPS

_PROBE = """
import contextlib, io, json, sys
from skinkit.cli import cli
out = io.StringIO()
with contextlib.redirect_stdout(out):
    cli.main(args={args!r}, prog_name="skinkit", standalone_mode=False)
print(json.dumps({{"modules": sorted(sys.modules), "output": out.getvalue()}}))
"""


def _run(args: list[str]) -> tuple[set[str], str]:
    proc = subprocess.run([sys.executable, "-c", _PROBE.format(args=args)], capture_output=True,
                          text=True, check=True)
    data = json.loads(proc.stdout.strip().splitlines()[-1])
    return {m.split(".")[0] for m in data["modules"]} | set(data["modules"]), data["output"]


def test_group_names_match_the_interfaces():
    assert registry.GROUP_NAMES == tuple(GROUPS)


def test_plugins_listing_imports_no_plugin():
    mods, out = _run(["plugins", "--json"])
    listed = json.loads(out)["groups"]
    targets = {e["value"].split(":")[0] for entries in listed.values() for e in entries}
    assert not targets & mods, targets & mods
    assert not {"numpy", "skinkit.interfaces", "skinkit_plugins", "skinkit_hardware"} & mods
    assert all(e["status"] == registry.UNCHECKED for v in listed.values() for e in v)


def test_plugins_check_does_import(tmp_path):
    mods, out = _run(["plugins", "--json", "--check", "--group", "skinkit.optimisers"])
    entries = json.loads(out)["groups"]["skinkit.optimisers"]
    if not entries:
        pytest.skip("no optimiser plugin installed")
    assert all(e["status"] in ("ok", "error") for e in entries)
    assert {e["value"].split(":")[0] for e in entries if e["status"] == "ok"} <= mods


def test_robot_protocols_builds_no_programme():
    mods, out = _run(["robot", "protocols", "--json"])
    assert not {"scipy", "skinkit_hardware"} & mods
    listed = {p["name"]: p["duration_s"] for p in json.loads(out)["protocols"]}
    assert listed["normal_indentation"] == pytest.approx(30.0)


def test_catalogue_durations_are_those_of_the_built_programmes():
    from skinkit.acquisition import catalogue, make_protocol

    for p in catalogue():  # make_protocol builds the programme and measures it
        assert p.duration_s == make_protocol(p.name).duration_s, p.name
