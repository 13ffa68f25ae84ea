"""skinkit fit: resume after SIGKILL, failed solves during a fit, non-identifiable pairs reported,
every bad input one clear line."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli as main
from skinkit.errors import ForwardError
from skinkit.schemas import (
    Channel,
    ChannelPrediction,
    Observations,
    Parameter,
    ParameterSet,
    Prediction,
    Protocol,
    ProtocolObservations,
)

pytestmark = pytest.mark.needs_plugins

#: a small layered disc, indented 1.5 mm p-p at 0.1 Hz for one period (about 1 s per solve)
DISC = """
[model]
name = "resume-disc"

[session]
protocols = ["normal_indentation"]
[session.parameters.normal_indentation]
periods = 1

[geometry]
kind = "disc"
diameter = "20 mm"
indenter_diameter = "4 mm"
n_inner = 1
n_ring = 2

[[layers]]
name = "skin"
thickness = "1.5 mm"
elements = 1
law = "neo-hookean-enu"
[layers.parameters]
E = "40 kPa"
nu = 0.45

[[layers]]
name = "subdermal"
thickness = "3.5 mm"
elements = 1
law = "neo-hookean-enu"
[layers.parameters]
E = "8 kPa"
nu = 0.45

[indenter]
mode = "displacement"

[surface]
fit = "auto"
outside = "nearest"

[drive]
max_step = "1 s"
"""
FIT_ARGS = ["--free", "skin.E,subdermal.E", "--start", "skin.E=15 kPa", "--start", "subdermal.E=20 kPa",
            "--workers", "1", "--overwrite", "--no-model-error"]


@pytest.fixture(scope="module")
def disc_session(tmp_path_factory):
    d = tmp_path_factory.mktemp("disc")
    (d / "m.toml").write_text(DISC)
    r = CliRunner().invoke(main, ["lab", "session", str(d / "m.toml"), "--out", str(d / "s.h5"),
                                  "--truth-out", str(d / "t.json"), "--seed", "1", "--shared-mesh"])
    assert r.exit_code == 0, r.output
    return d


def _skinkit(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "skinkit", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kw)


def test_killed_fit_resumes_to_the_same_optimum(disc_session, tmp_path):
    """A fit SIGKILLed after a random number of completed evaluations, run again with --resume,
    replays those evaluations (no forward solve repeated) and ends at the optimum of the
    uninterrupted fit — bitwise, since the solves are deterministic and the optimiser retraces
    its path through the replayed values."""
    d = disc_session
    base = ["fit", str(d / "m.toml"), str(d / "s.h5"), *FIT_ARGS, "--json"]
    p = _skinkit(*base, "--out", str(tmp_path / "whole"))
    out, err = p.communicate(timeout=900)
    assert p.returncode == 0, err
    whole = json.loads(out)
    n_total = whole["n_forward"]
    assert n_total >= 3

    k = int(np.random.default_rng().integers(1, n_total))   # a random iteration
    evals = tmp_path / "killed" / "evaluations" / "start-000"
    p = _skinkit(*base, "--out", str(tmp_path / "killed"))
    while p.poll() is None and len(list(evals.glob("eval-*.npz"))) < k:
        time.sleep(0.02)
    os.kill(p.pid, signal.SIGKILL)
    p.communicate()
    done = len(list(evals.glob("eval-*.npz")))
    assert p.returncode == -signal.SIGKILL and 1 <= done < n_total + 1

    p = _skinkit(*base, "--out", str(tmp_path / "killed"), "--resume")
    out, err = p.communicate(timeout=900)
    assert p.returncode == 0, err
    resumed = json.loads(out)
    for name in ("skin.E", "subdermal.E"):
        assert resumed["parameters"][name]["value"] == whole["parameters"][name]["value"]
    assert resumed["n_replayed"] == done
    # completed evaluations are not solved again: the new solves are the rest of the path
    assert resumed["n_forward"] == n_total - done
    assert not evals.exists()   # a whole fit leaves no checkpoint behind


def test_stored_fit_is_not_overwritten_silently(disc_session, tmp_path):
    """A fit stored in the session under a name: a new fit of that name is refused before it
    starts, another --name is stored beside it, --overwrite replaces. Its fit.json in --out is
    not replaced silently either: the other name writes to its own --out."""
    from skinkit.store import open_experiment
    d = disc_session
    args = ["fit", str(d / "m.toml"), str(d / "s.h5"), "--free", "skin.E", "--out", str(tmp_path),
            "--workers", "1", "--no-model-error", "--name", "first"]
    r = CliRunner().invoke(main, [*args, "--overwrite"])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 2 and "already holds a fit" in r.output
    r = CliRunner().invoke(main, [*args[:-1], "second"])
    assert r.exit_code == 2 and f"--out {tmp_path}: already holds fit.json" in r.output
    r = CliRunner().invoke(main, [*args[:-1], "second", "--out", str(tmp_path / "second")])
    assert r.exit_code == 0, r.output
    with open_experiment(d / "s.h5") as exp:
        assert {"first", "second"} <= set(exp.fit_names())
        assert exp.read_fit("second").parameters.free_names == ["skin.E"]


def test_resume_refuses_another_fit(disc_session, tmp_path):
    d = disc_session
    r = CliRunner().invoke(main, ["fit", str(d / "m.toml"), str(d / "s.h5"), "--resume",
                                  "--out", str(tmp_path)])
    assert r.exit_code != 0 and "no checkpoint" in r.output
    (tmp_path / "checkpoint.json").write_text(json.dumps({"free": ["skin.E"]}))
    r = CliRunner().invoke(main, ["fit", str(d / "m.toml"), str(d / "s.h5"), *FIT_ARGS, "--resume",
                                  "--out", str(tmp_path)])
    assert r.exit_code != 0 and "another fit" in r.output


@pytest.mark.parametrize("args, words", [
    (["--free", "skin.E,skin.nope"], "skin.nope"),
    (["--free", "skin.E", "--bounds", "skin.E=50 kPa:10 kPa"], "inverted"),
    (["--free", "skin.E", "--bounds", "skin.E=1 kPa:10 kPa", "--start", "skin.E=40 kPa"],
     "outside its bounds"),
    (["--free", "skin.E", "--start", "skin.E=-5"], "outside its bounds"),
    (["--free", "skin.E", "--start", "subdermal.E=5"], "not a free parameter"),
    (["--free", "skin.E", "--optimiser", "levenberg-of-the-future"], "not installed"),
    (["--free", "skin.E", "--objective", "vibes"], "--objective"),
    (["--free", "skin.E", "--bounds", "skin.E=3"], "NAME=LOWER:UPPER"),
])
def test_bad_input_is_one_line(disc_session, tmp_path, args, words):
    d = disc_session
    r = CliRunner().invoke(main, ["fit", str(d / "m.toml"), str(d / "s.h5"), *args, "--out", str(tmp_path)])
    assert r.exit_code != 0
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and words in lines[0], r.output
    assert "Traceback" not in r.output


def test_session_lacking_channels_is_one_line(tmp_path):
    """A CSV record without the force the lumped model predicts."""
    csv = tmp_path / "r.csv"
    rows = (f"{0.01 * i:.2f},{0.001 * i:.4f}" for i in range(200))
    csv.write_text("time_s,displacement_mm\n" + "\n".join(rows))
    model = Path(__file__).resolve().parents[2] / "docs" / "models" / "extension_relaxation_lumped.toml"
    r = CliRunner().invoke(main, ["fit", str(model), str(csv), "--out", str(tmp_path / "o")])
    assert r.exit_code != 0
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "force" in lines[0].lower(), r.output


class _SqrtModel:
    """y = √a · t on one channel; the 'solver' fails for a < 0.5 (a region a forward model cannot
    solve: inverted elements, a violated constraint). From a = 5 the Gauss-Newton step of the
    linearisation lands at a ≈ -1.5 — inside the failing region (the bounds, -10 and 10, are far)."""

    name = "sqrt"

    def parameters(self) -> ParameterSet:
        return ParameterSet([Parameter("a", 5.0, "1", -10.0, 10.0)])

    def predict(self, params, observations, sensitivities=False):
        a = params["a"]
        if a < 0.5:
            raise ForwardError("solver", f"cannot solve at a = {a:.3g}")
        out = {}
        for po in observations:
            t = po.channels["tip_force"].time_s
            v = np.sqrt(a) * t[:, None] * np.ones((1, 3))
            d = {"a": t[:, None] * np.ones((1, 3)) / (2 * np.sqrt(a))} if sensitivities else {}
            out[po.name] = {"tip_force": ChannelPrediction(v, d)}
        return Prediction(out)


def test_failed_solve_shrinks_the_step():
    from skinkit.inverse import fit
    t = np.linspace(0, 1, 101)
    rng = np.random.default_rng(0)
    y = np.sqrt(0.6) * t[:, None] * np.ones((1, 3)) + 1e-3 * rng.standard_normal((101, 3))
    obs = Observations({"p": ProtocolObservations(Protocol("p"), {
        "tip_force": Channel("tip_force", t, y, noise=1e-3)})}, None, "test")
    r = fit(_SqrtModel(), obs, ["a"])
    failed = [h for h in r.extra["history"] if not h["solved"]]
    assert failed, "the first step should have landed where the model fails"
    assert all("cannot solve" in h["error"] for h in failed)
    # the optimum: within 4 standard errors of the truth, which the noise allows
    assert r.converged and abs(r.parameters["a"] - 0.6) < 4 * r.se["a"]
    # each solved evaluation is one forward solve; the optimum's Jacobian is reused, not re-solved
    assert r.n_forward == sum(h["solved"] for h in r.extra["history"])


def test_a_start_on_a_bound_is_solved_once():
    """scipy's trust-region reflective moves a start lying on a bound strictly inside (by ~1e-10
    of the scale) and asks for it again: the same point, not a second solve."""
    from skinkit.inverse import fit
    t = np.linspace(0, 1, 101)
    y = np.sqrt(0.6) * t[:, None] * np.ones((1, 3))
    obs = Observations({"p": ProtocolObservations(Protocol("p"), {
        "tip_force": Channel("tip_force", t, y, noise=1e-3)})}, None, "test")
    r = fit(_SqrtModel(), obs, ["a"], start={"a": 10.0})
    xs = [h["x"][0] for h in r.extra["history"]]
    assert xs[0] == 10.0 and all(abs(x - 10.0) > 1e-6 for x in xs[1:]), xs
    assert r.n_forward == sum(h["solved"] for h in r.extra["history"])


def test_k1_k2_trade_off_is_reported_not_hidden():
    """GOH skin indented only 0.3 mm p-p: the fibres stay in their quadratic range, where the
    energy k1/(2 k2) (exp(k2 E²) - 1) ≈ k1 E²/2 (1 + k2 E²/2) leaves k2 almost without effect
    and correlated with k1. Both free: the report must flag the pair, suggest fixing k2, and
    call neither identifiable (no value printed as if it were known)."""
    from skinkit.bench.coverage import invivo_spec
    from skinkit.forward import load
    from skinkit.inverse import fit, fit_json
    from skinkit.inverse.coverage import LabSessions

    spec, _ = invivo_spec()
    spec["session"]["parameters"]["normal_indentation"]["peak_to_peak"] = 3e-4
    # identifiability where the model is exact (the truth on its mesh)
    lab = LabSessions(spec, protocols=["normal_indentation"], mesh="shared")
    model = load(lab.model_spec, workers=1)
    p = model.parameters()
    start = {"skin.k1": 1.3 * p["skin.k1"], "skin.k2": 0.7 * p["skin.k2"]}
    r = fit(model, lab(0), ["skin.k1", "skin.k2"], start=start)
    j = fit_json(r)
    pairs = [pr for pr in j["identifiability"]["problems"] if pr["kind"] == "pair"]
    assert pairs and set(pairs[0]["parameters"]) == {"skin.k1", "skin.k2"}
    assert pairs[0]["fix"] == "skin.k2" and "fix skin.k2" in pairs[0]["message"]
    assert j["parameters"]["skin.k1"]["identifiable"] is False
    assert j["parameters"]["skin.k2"]["identifiable"] is False


def test_a_failed_model_error_keeps_the_plain_fit(disc_session, tmp_path):
    """The model error's refined copy refused for real by the model's size limit (set between the
    model's unknowns and its 2x refinement's): the fit is kept, written and calibrated, and says
    that its intervals are the noise's alone."""
    text = DISC + "\n[solver]\nmax_unknowns = 4000\n"   # the disc: 1,815 unknowns, refined about 8x
    (tmp_path / "m.toml").write_text(text)
    args = [a for a in FIT_ARGS if a != "--no-model-error"]
    r = CliRunner().invoke(main, ["fit", str(tmp_path / "m.toml"), str(disc_session / "s.h5"), *args,
                                  "--out", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    best = json.loads((tmp_path / "out" / "fit.json").read_text())
    assert "could not be estimated" in best["model_error_failed"]
    assert "max_unknowns" in best["model_error_failed"]
    assert "model_error" not in best
    assert "! the model's discretisation error could not be estimated" in r.output
    assert (tmp_path / "out" / "model.toml").exists()
    assert best["parameters"]["skin.E"]["se"] > 0


def test_a_fit_stopped_by_a_layers_bound_says_so(disc_session, tmp_path):
    """The model file bounds the skin's modulus below the session's truth (40 kPa): the fit ends on
    the upper bound, and fit.json and the summary say that the bound, not the data, stopped it;
    the subdermal modulus, free within the law's range, is not on a bound."""
    bounded = 'E = "20 kPa"\nnu = 0.45\n[layers.bounds]\nE = ["10 kPa", "30 kPa"]\n'
    text = DISC.replace('E = "40 kPa"\nnu = 0.45\n', bounded)
    (tmp_path / "m.toml").write_text(text)
    r = CliRunner().invoke(main, ["fit", str(tmp_path / "m.toml"), str(disc_session / "s.h5"), *FIT_ARGS,
                                  "--out", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    p = json.loads((tmp_path / "out" / "fit.json").read_text())["parameters"]
    assert (p["skin.E"]["upper"], p["skin.E"]["on_bound"]) == (30e3, "upper")
    assert p["skin.E"]["value"] == pytest.approx(30e3, rel=1e-3)
    assert p["subdermal.E"]["on_bound"] is None
    assert "! skin.E sits on its upper bound" in r.output
