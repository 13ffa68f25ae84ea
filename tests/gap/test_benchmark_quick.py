"""``skinkit gap benchmark --quick --json`` through the command line, and its figures.

The quick run is four effects at moderate magnitude on ``docs/models/invivo_quick.toml``'s
coarse in vivo case and two null sessions: about 11 minutes on the 2 cores, which would double the
suite's wall time (kept under 10 minutes), so it runs when ``SKINKIT_GAP_QUICK=1``
(``make test-gap-quick``), which CI (``.ci/run``) does after the suite; the lumped run of
``test_benchmark.py`` covers the same code in every suite. Thresholds, from the sample size:

* **attribution and localisation**: the issue claims ≥ 90 %; with four cases at 90 %, one or
  none right has probability 0.4 % — at least two must be right.
* **false alarms**: a null session raises a significant gap with probability ≤ 0.05 and is
  named on even less; both of two has probability ≤ 0.25 % — at most one.
* **magnitude and shrinkage**: at 30 detection thresholds the main parameter's relative standard
  error is about 1 %; ±15 % is over ten standard errors (as in ``test_benchmark.py``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

pytestmark = [
    pytest.mark.needs_plugins,
    pytest.mark.slow,
    pytest.mark.skipif(os.environ.get("SKINKIT_GAP_QUICK") != "1",
                       reason="the quick FE benchmark takes ~11 min on 2 cores: SKINKIT_GAP_QUICK=1 runs it"),
]


@pytest.fixture(scope="module")
def quick(tmp_path_factory: pytest.TempPathFactory) -> dict:
    # the truths on the model's mesh: the figures the thresholds below were set for
    out = subprocess.run([sys.executable, "-m", "skinkit", "gap", "benchmark", "--quick", "--shared-mesh",
                          "--json"],
                         capture_output=True, text=True, cwd=tmp_path_factory.mktemp("quick"), check=False)
    assert out.returncode == 0, out.stderr[-3000:]
    print(out.stderr)          # the run's summary (``-s`` shows it)
    return json.loads(out.stdout)


def test_quick_has_the_issues_keys_and_its_cases(quick: dict) -> None:
    for k in ("top1_accuracy", "null_false_alarm_rate", "localisation_accuracy", "magnitude_error_median",
              "shrinkage_error_median", "confusion", "cases", "wall_s"):
        assert k in quick
    assert not quick["failed"]
    kinds = [c["kind"] for c in quick["cases"]]
    assert kinds.count("null") == 2 and kinds.count("effect") >= 3
    assert sum(quick["confusion"]["none"].values()) == 2


def test_quick_figures(quick: dict) -> None:
    top1, sets = quick["top1"], quick["by_magnitude"]["moderate"]["in_reported_set"]
    assert top1["k"] + sets["k"] >= 2, (top1, sets)
    loc = quick["localisation"]
    assert loc["k"] >= min(2, loc["n"]), loc
    assert quick["null_false_alarm"]["k"] <= 1
    for c in quick["cases"]:
        v = quick["verdicts"][c["id"]]
        if "magnitude" in v:
            assert abs(v["magnitude"]["relative_error"]) <= 0.15, (c["id"], v["magnitude"])
        if "shrinkage" in v and v.get("top1"):
            assert abs(v["shrinkage"]["relative_error"]) <= 0.15, (c["id"], v["shrinkage"])
