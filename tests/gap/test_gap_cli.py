"""``skinkit gap diagnose``: the JSON shape pinned by the issue, the report
stored in the experiment file and written to --out, and bad inputs as one line with exit status 2.

The session is a virtual-lab experiment file (``skinkit.lab.session.make_session``) of a lumped
element with a relaxation term the model lacks, read exactly as a real session is.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from skinkit.cli import cli as main

pytestmark = pytest.mark.needs_plugins

MODEL = """
[model]
kind = "lumped"
name = "gap-cli"
[lumped]
test = "indentation"
family = "quasi-static"
axis = "-z"
drive = "tip_position"
elastic = "exponential"
[lumped.parameters]
a = "15 mN"
b = 800.0
[session]
protocols = ["preconditioning", "normal_indentation"]
[session.parameters.preconditioning]
hold = 15.0
[session.parameters.normal_indentation]
periods = 2
"""
TRUTH_EFFECT = """
[[effects]]
name = "viscoelastic"
g1 = 0.3
tau1 = "3 s"
"""


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> Path:
    from skinkit.lab.session import make_session

    d = tmp_path_factory.mktemp("gapcli")
    (d / "m.toml").write_text(MODEL)
    (d / "truth.toml").write_text(MODEL + TRUTH_EFFECT)
    make_session(str(d / "truth.toml"), d / "s.h5", d / "t.json", seed=4)
    return d


def _is_num(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def check_shape(d: dict) -> None:
    """Exactly the issue's pinned keys and types (others may be added)."""
    assert {"model", "session", "fit", "gap", "candidates", "named", "shrinkage"} <= set(d)
    assert isinstance(d["model"], str) and isinstance(d["session"], str)
    f = d["fit"]
    assert {"parameters", "chi2_per_dof", "n_forward"} <= set(f)
    assert all(isinstance(k, str) and _is_num(v) for k, v in f["parameters"].items())
    assert _is_num(f["chi2_per_dof"]) and isinstance(f["n_forward"], int)
    g = d["gap"]
    assert isinstance(g["significant"], bool) and _is_num(g["chi2_per_dof"])
    for c in g["cells"]:
        assert c["axis"] in ("protocol", "channel", "phase", "region", "frequency")
        assert isinstance(c["label"], str) and isinstance(c["significant"], bool)
        assert all(_is_num(c[k]) for k in ("share", "chi2_per_dof", "p_value"))
    for c in d["candidates"]:
        assert isinstance(c["effect"], str) and _is_num(c["score"]) and _is_num(c["p_value"])
        assert isinstance(c["refitted"], bool)
        for k in ("delta_aic", "shrinkage"):
            assert c[k] is None or _is_num(c[k])
        assert c["parameters"] is None or all(
            {"value", "se"} <= set(v) and _is_num(v["value"]) for v in c["parameters"].values())
        assert isinstance(c["not_separable_from"], list)
    assert isinstance(d["named"], list) and all(isinstance(e, str) for e in d["named"])
    s = d["shrinkage"]
    assert _is_num(s["overall"]) and (s["held_out"] is None or _is_num(s["held_out"]))
    for c in s["cells"]:
        assert {"axis", "label", "before", "after"} <= set(c)


def test_json_shape_store_and_out(files):
    d = files
    # three candidates, two refitted: the shape of refitted and of scored-only candidates. Naming
    # among every installed effect is test_diagnose's (the same model and truth, the Python API);
    # the default candidate set through the command line is test_verdict's real record
    args = ["gap", "diagnose", str(d / "m.toml"), str(d / "s.h5"), "--holdout", "normal_indentation",
            "--effects", "viscoelastic,force-drift,force-offset", "--candidates", "2",
            "--out", str(d / "out"), "--json"]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    check_shape(out)
    assert out["named"][:1] == ["viscoelastic"] and out["candidates"][0]["effect"] == "viscoelastic"
    assert out["stored_as"] == "gap-gap-cli"
    written = json.loads((d / "out" / "gap.json").read_text())
    assert written["named"] == out["named"] and written["candidates"] == out["candidates"]
    from skinkit.store import open_experiment
    with open_experiment(d / "s.h5") as exp:
        assert exp.read_gap("gap-gap-cli")["named"] == out["named"]
    # a stored report is never replaced silently, and the refusal comes before any fit
    r = CliRunner().invoke(main, args[:-1])
    assert r.exit_code == 2 and "already holds a gap report named 'gap-gap-cli'" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    # ... nor the report written to --out, under another name
    r = CliRunner().invoke(main, [*args[:-1], "--name", "other"])
    assert r.exit_code == 2 and f"--out {d / 'out'}: already holds gap.json" in r.stderr
    assert json.loads((d / "out" / "gap.json").read_text()) == written


def test_plain_verdict(files):
    d = files
    r = CliRunner().invoke(main, ["gap", "diagnose", str(d / "m.toml"), str(d / "s.h5"), "--name", "plain",
                                  "--effects", "viscoelastic,force-drift", "--max-effects", "1"])
    assert r.exit_code == 0, r.output
    assert "`viscoelastic` is a cause" in r.stdout and "Significant gap" in r.stdout
    assert "calibrating gap-cli" in r.stderr          # progress goes to stderr


def test_until_keeps_the_first_seconds(files):
    """--until diagnoses only the session's first seconds: the first protocol (the 15 s hold of a
    ramp-and-hold, recorded at 1 kHz) cut at 5 s keeps about a third of its samples, and the
    degrees of freedom of the protocol cell say so."""
    d = files
    base = ["gap", "diagnose", str(d / "m.toml"), str(d / "s.h5"), "--effects", "viscoelastic",
            "--max-effects", "0", "--json"]
    full = json.loads(CliRunner().invoke(main, [*base, "--name", "u1"]).stdout)
    cut = json.loads(CliRunner().invoke(main, [*base, "--name", "u2", "--until", "5"]).stdout)
    n = {c["label"]: c for c in full["gap"]["cells"] if c["axis"] == "protocol"}
    m = {c["label"]: c for c in cut["gap"]["cells"] if c["axis"] == "protocol"}
    assert set(m) <= set(n) and "preconditioning" in m
    assert m["preconditioning"]["n"] < 0.5 * n["preconditioning"]["n"]
    r = CliRunner().invoke(main, [*base, "--until", "0"])
    assert r.exit_code == 2 and "--until" in r.stderr


@pytest.mark.parametrize("extra, message", [
    (["--effects", "prestress"], "'prestress': does not apply to a 'lumped' model"),
    (["--effects", "no-such-effect"], "'no-such-effect': no such effect is installed"),
    (["--free", ","], "no free parameter"),
])
def test_bad_input_is_one_line(files, extra, message):
    d = files
    r = CliRunner().invoke(main, ["gap", "diagnose", str(d / "m.toml"), str(d / "s.h5"), "--name", "bad",
                                  *extra])
    assert r.exit_code == 2 and message in r.stderr, r.output
    assert len([ln for ln in r.stderr.splitlines() if ln.startswith("error:")]) == 1
    assert "Traceback" not in r.output


def test_session_lacking_channels(tmp_path):
    """A CSV record of displacement alone, and a force-driven model: the session lacks the
    channel that drives it."""
    (tmp_path / "m.toml").write_text(MODEL.replace('drive = "tip_position"', 'drive = "tip_force"'))
    csv = tmp_path / "r.csv"
    csv.write_text("time_s,displacement_mm\n" + "".join(f"{0.01 * i},{0.001 * i}\n" for i in range(200)))
    r = CliRunner().invoke(main, ["gap", "diagnose", str(tmp_path / "m.toml"), str(csv)])
    assert r.exit_code == 2 and "has no 'tip_force' channel to drive the model" in r.stderr, r.output
    assert len(r.stderr.strip().splitlines()) == 1
