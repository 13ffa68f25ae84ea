"""``skinkit bench fem`` without a peer (sfepy or NGSolve not installed) or with a peer that fails
(sfepy inverting an element: "warp violation") reports skinkit's figures and says why the peer
has none, naming the extra that installs it, instead of ending in an internal error."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

import pytest
from click.testing import CliRunner

from skinkit.bench import fem
from skinkit.cli import cli
from skinkit.fem.mesh import block_mesh

# the smallest block (one element): the figures are not the point, the report is
_NO_PEERS = ("import sys; sys.modules['sfepy'] = None; sys.modules['ngsolve'] = None\n"  # imports fail
             "from skinkit.cli import main; main(sys.argv[1:])")


def test_without_the_peers_skinkit_is_measured_and_the_extra_named():
    for as_json in ([], ["--json"]):
        r = subprocess.run([sys.executable, "-c", _NO_PEERS, "bench", "fem", "--n", "1", *as_json],
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        assert "internal error" not in r.stderr and "Traceback" not in r.stderr
        if as_json:
            res = json.loads(r.stdout)
            assert res["skinkit_s_per_newton"] > 0 and res["sfepy_s_per_newton"] is None
            assert res["peer_error"] == "sfepy is not installed (pip install 'skinkit[bench]')"
            ng = res["peers"]["ngsolve"]
            assert ng["status"] == "not installed" and ng["s_per_newton"] is None
            assert ng["error"] == "ngsolve is not installed (pip install 'skinkit[bench]')"
        else:
            assert "skinkit " in r.stdout and "s/iteration" in r.stdout
            assert "sfepy   no figures: sfepy is not installed (pip install 'skinkit[bench]')" in r.stdout
            assert "ngsolve no figures: ngsolve is not installed (pip install 'skinkit[bench]')" in r.stdout


def test_a_failing_peer_is_reported_with_skinkits_figures(monkeypatch, tmp_path):
    def warp(mesh):
        raise ValueError("warp violation!")

    monkeypatch.setattr(fem, "run_sfepy", warp)
    page = tmp_path / "fem.md"
    r = CliRunner().invoke(cli, ["bench", "fem", "--n", "1", "--peer", "sfepy", "--page", str(page)])
    assert r.exit_code == 0, r.output
    lines = r.stdout.splitlines()
    assert lines[1].startswith("skinkit ") and "s/iteration" in lines[1]
    assert lines[2] == "sfepy   no figures: sfepy failed: ValueError: warp violation!"
    assert lines[-1].startswith("threads: OMP_NUM_THREADS=")
    assert "warp violation" in page.read_text()
    r = CliRunner().invoke(cli, ["bench", "fem", "--n", "1", "--peer", "sfepy", "--json"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.stdout)
    assert res["peer_error"] == "sfepy failed: ValueError: warp violation!" and res["speedup"] is None
    assert res["peers"]["sfepy"]["status"] == "failed" and list(res["peers"]) == ["sfepy"]


@pytest.mark.skipif(importlib.util.find_spec("sfepy") is None, reason="sfepy is not installed")
def test_sfepys_own_failure_on_the_larger_block_is_an_exception_reported_as_failed():
    # at 10 x 10 x 10 sfepy's one load step inverts an element: its C terms raise a ValueError
    # ("warp violation"), so the peer runs in this process and the bench goes on
    sk = {"mesh": block_mesh((1.0, 1.0, 1.0), (10, 10, 10))}
    entry, out = fem._peer_entry("sfepy", sk, fem.run_sfepy)
    assert out is None and entry["status"] == "failed" and entry["s_per_newton"] is None
    assert entry["error"].startswith("sfepy failed: ValueError:") and "warp violation" in entry["error"]
