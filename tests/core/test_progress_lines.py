"""Progress in a log: with stderr not a terminal, long commands write plain ``progress:`` lines
(stage, fraction, elapsed, ETA) at least every heartbeat, also through silent steps; ``--quiet``
writes none; stdout keeps only the result; an interrupted run ends its worker pool cleanly.

The commands run as subprocesses on a tiny finite-element model (one or two protocols, 72
elements) with the heartbeat shortened (``SKINKIT_PROGRESS_INTERVAL``) so that short runs show
several lines; the demo's progress plumbing is checked with a fake slow chain.
"""

from __future__ import annotations

import copy
import io
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.cli._progress import HEARTBEAT_S, INTERVAL_ENV, Progress
from tests.lab.test_lab_session import FE_SPEC

from ._model_files import to_toml

#: the longest gap [s] allowed between two progress lines (the heartbeat is 10 s)
MAX_GAP_S = 15.0
LINE = re.compile(r"^progress: (?P<stage>.*?)(?: +(?P<pct>\d+) %)?"
                  r"  elapsed (?P<h>\d+):(?P<m>\d\d):(?P<s>\d\d)  ETA (?P<eta>\S+)")


def _spec(protocols: list[str]) -> dict:
    spec = copy.deepcopy(FE_SPEC)
    spec.pop("effects")
    spec["session"] = {"protocols": protocols,
                       "parameters": {p: {"periods": 1, "camera_rate": 0.5} for p in protocols}}
    spec["drive"] = {"max_step": "5 s"}
    return spec


def _env(interval: float = 1.0) -> dict[str, str]:
    return dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
                **{INTERVAL_ENV: str(interval)})


def _run(args: list[str], folder: Path, name: str, interval: float = 1.0
         ) -> tuple[subprocess.CompletedProcess, str, float]:
    """``skinkit ARGS`` with stderr to a file (not a terminal) and a heartbeat of ``interval`` [s]:
    the process, its stderr, its seconds."""
    err = folder / f"{name}.err"
    t0 = time.monotonic()
    with err.open("w") as f:
        p = subprocess.run([sys.executable, "-m", "skinkit", *args], stdout=subprocess.PIPE, stderr=f,
                           text=True, env=_env(interval), cwd=folder, timeout=300)
    return p, err.read_text(), time.monotonic() - t0


def _lines(stderr: str) -> list[tuple[str, int | None, float]]:
    """(stage, percent or None, elapsed [s]) of every progress line."""
    out = []
    for line in stderr.splitlines():
        m = LINE.match(line)
        if m:
            out.append((m["stage"], None if m["pct"] is None else int(m["pct"]),
                        3600 * int(m["h"]) + 60 * int(m["m"]) + int(m["s"])))
    return out


def _check_gaps(stderr: str, wall_s: float) -> list[tuple[str, int | None, float]]:
    lines = _lines(stderr)
    assert lines, stderr
    times = [0.0] + [t for _, _, t in lines]
    gaps = [b - a for a, b in zip(times, times[1:], strict=False)]
    assert max(gaps) <= MAX_GAP_S, (gaps, stderr)
    # nor a silent end: the last line is at most one gap before the process ended
    assert wall_s - times[-1] <= MAX_GAP_S, (wall_s, stderr)
    assert "done in" in stderr.splitlines()[-1], stderr
    return lines


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("progress")
    (d / "one.toml").write_text(to_toml(_spec(["normal_indentation"])))
    (d / "two.toml").write_text(to_toml(_spec(["normal_indentation", "in_plane_090"])))
    return d


@pytest.fixture(scope="module")
def session(folder) -> tuple[Path, str, float]:
    # a heartbeat of 0.1 s: the tiny truth solves in about a second, and the log must show it advance
    p, err, wall = _run(["lab", "session", "one.toml", "--out", "s.h5", "--truth-out", "t.json",
                         "--seed", "1", "--shared-mesh"], folder, "lab", interval=0.1)
    assert p.returncode == 0, err
    return folder / "s.h5", err, wall


@pytest.mark.needs_plugins
def test_lab_session_truth_solve_advances_in_the_log(session):
    _, err, wall = session
    lines = _check_gaps(err, wall)
    truth = [pct for stage, pct, _ in lines if stage == "truth model"]
    assert truth and max(p or 0 for p in truth) > 0, err    # the solve moves the bar, not 0 % throughout
    assert [s for s, _, _ in lines][-1] == "write session", err


@pytest.mark.needs_plugins
def test_fe_predict_reports_its_solve_and_quiet_reports_nothing(folder, session):
    # a heartbeat of 0.1 s: the prediction itself takes about a second
    p, err, wall = _run(["predict", "one.toml", "s.h5", "--workers", "1", "--json"], folder, "predict",
                        interval=0.1)
    assert p.returncode == 0, err
    assert p.stdout.lstrip().startswith("{")     # stdout is the JSON alone
    lines = _check_gaps(err, wall)
    assert any(stage == "predict" and (pct or 0) > 0 for stage, pct, _ in lines), err
    # a short prediction (the first 4 s) under a heartbeat short enough to have written lines
    q, qerr, _ = _run(["--quiet", "predict", "one.toml", "s.h5", "--workers", "1", "--until", "4"], folder,
                      "quiet", interval=0.1)
    assert q.returncode == 0 and "chi2/sample" in q.stdout, qerr
    assert qerr == "", qerr


@pytest.mark.needs_plugins
def test_effects_visibility_reports_each_prediction(folder, session):
    # a heartbeat of 0.1 s: each of the three predictions takes about a second, so every one is
    # named by some line (at 1 s a prediction that ends within a second of the last line is not)
    p, err, wall = _run(["effects", "visibility", "one.toml", "--session", "s.h5", "--effects", "prestress",
                         "--workers", "1"], folder, "visibility", interval=0.1)
    assert p.returncode == 0, err
    assert "prestress" in p.stdout and "progress" not in p.stdout
    lines = _check_gaps(err, wall)
    pcts = [pct for stage, pct, _ in lines if stage == "effect visibility" and pct is not None]
    assert pcts == sorted(pcts) and pcts[-1] >= 50, err
    assert "prestress at its typical magnitude" in err, err


@pytest.mark.needs_plugins
def test_interrupted_visibility_shuts_its_pool_down(folder):
    """SIGINT while two worker processes solve: exit 130 at once, one line, no leaked semaphore."""
    err = folder / "sigint.err"
    with err.open("w") as f:
        p = subprocess.Popen([sys.executable, "-m", "skinkit", "effects", "visibility", "two.toml",
                              "--effects", "prestress", "--workers", "2"], stdout=subprocess.DEVNULL,
                             stderr=f, env=_env(0.5), cwd=folder,
                             # a shell may start a background job with SIGINT ignored
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        try:
            deadline = time.monotonic() + 120
            while "protocols solved" not in err.read_text() and time.monotonic() < deadline:
                time.sleep(0.2)
            p.send_signal(signal.SIGINT)
            t0 = time.monotonic()
            rc = p.wait(timeout=30)
            stopped = time.monotonic() - t0
        finally:
            p.kill()
    time.sleep(1.0)   # the resource tracker reports leaks as it ends, after the process
    text = err.read_text()
    assert rc == 130, text
    assert stopped < 10, (stopped, text)
    assert text.splitlines()[-1] == "error: interrupted", text
    assert "leaked" not in text and "Traceback" not in text, text


class _Clocked(io.StringIO):
    """A log that notes when each line was written [s, monotonic]."""

    def __init__(self) -> None:
        super().__init__()
        self.stamps: list[float] = []

    def write(self, s: str) -> int:
        self.stamps += [time.monotonic()] * s.count("\n")
        return super().write(s)


def test_heartbeat_writes_through_a_silent_step():
    assert HEARTBEAT_S <= 10
    log = _Clocked()
    with Progress(mode="normal", stream=log, tty=False, interval=0.2) as bar:
        bar.update("slow step", 0.0)
        time.sleep(1.3)                          # reports nothing for 1.3 s
        bar.update("slow step", 0.5, "half")
        time.sleep(0.5)
    lines = log.getvalue().splitlines()
    assert len(lines) >= 7, lines
    gaps = [b - a for a, b in zip(log.stamps, log.stamps[1:], strict=False)]
    assert max(gaps) < 0.2 + 0.25, gaps
    assert any(" 50 %" in line and "half" in line and "ETA 0:00:0" in line for line in lines), lines
    assert lines[-1].startswith("progress: done in"), lines


def test_a_run_shorter_than_the_heartbeat_writes_nothing():
    """A quick command's result, or its one-line error, stays alone in the log."""
    log = io.StringIO()
    with pytest.raises(RuntimeError), Progress(mode="normal", stream=log, tty=False, interval=5) as bar:
        bar.update("a", 0.1)
        bar.update("b", None, "x")
        raise RuntimeError("bad input")
    assert log.getvalue() == ""


def test_quiet_and_verbose():
    log = io.StringIO()
    with Progress(mode="quiet", stream=log, tty=False, interval=0.05) as bar:
        bar.update("a", 0.5, "x")
        time.sleep(0.2)
    assert log.getvalue() == ""
    with Progress(mode="verbose", stream=log, tty=False, interval=5) as bar:
        bar.update("a", 0.5, "first")
        bar.update("b", None)
    text = log.getvalue()
    assert "a: first" in text and "stage times: a " in text, text


def test_demo_progress_goes_to_stderr_through_a_silent_step(monkeypatch, tmp_path):
    """The demo's chain reports through the heartbeat: a fake chain with a silent 1.2 s step."""
    from skinkit.pipelines import chain

    def fake_chain(out_dir, progress, **kwargs):
        progress("acquire: truth model", 0.0)
        time.sleep(1.5)
        progress("acquire: truth model", 1.0)
        progress("gap: ranking candidates", 0.5)
        progress("gap: done", 1.0)
        return {"diagnose": {}, "table": [], "times_s": {"acquire": 1.2}, "experiment_file": "s.h5",
                "truth_file": "t.json", "report": "r.html"}

    monkeypatch.setattr(chain, "run_chain", fake_chain)
    monkeypatch.setattr(chain, "missing_plugins", lambda: [])
    monkeypatch.setenv(INTERVAL_ENV, "0.25")
    r = CliRunner().invoke(cli, ["demo", "--out", str(tmp_path / "d"), "--json"])
    assert r.exit_code == 0, r.output
    assert r.stdout.lstrip().startswith("{") and "progress" not in r.stdout
    lines = _lines(r.stderr)
    assert len([s for s, _, _ in lines if s == "acquire: truth model"]) >= 4, r.stderr
    assert "gap" in [s for s, _, _ in lines] and "ranking candidates" in r.stderr, r.stderr
    quiet = CliRunner().invoke(cli, ["demo", "--quiet", "--out", str(tmp_path / "d"), "--json"])
    assert quiet.exit_code == 0 and quiet.stderr == "", quiet.output
