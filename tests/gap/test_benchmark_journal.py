"""The benchmark's journal: a stopped or extended run reruns nothing it has recorded.

On the lumped preset (seconds per case): the benchmark's own run (two effects at moderate
magnitude and three null sessions, journaled; ``lumped_benchmark`` in ``conftest.py``), then the
same run asking for a fourth null session — only that one runs, the others come back from the
file as they were written.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from skinkit.bench.gap_benchmark import BenchmarkError, execution_order, run
from skinkit.bench.gap_journal import Journal, JournalError
from tests.gap._shared import BENCHMARK_NULLS, run_benchmark

# the first run is the benchmark tests' run: the same xdist group, so that one worker builds it
pytestmark = [pytest.mark.needs_plugins, pytest.mark.xdist_group("gap_benchmark")]

#: every case the shared run records: its effects' at moderate magnitude and its null sessions
RECORDED = ["force-drift/moderate/0", "null/1000", "null/1001", "null/1002", "viscoelastic/moderate/0"]


def _run(path: Path, nulls: int, lines: list[str] | None = None, **kw: object) -> dict:
    say = (lambda s: lines.append(s)) if lines is not None else None
    return run_benchmark(path, nulls, progress=say, **kw)


@pytest.fixture(scope="module")
def first(lumped_benchmark: tuple[Path, dict]) -> tuple[Path, dict]:
    return lumped_benchmark


def test_an_extended_run_reruns_nothing_recorded(first: tuple[Path, dict], tmp_path: Path) -> None:
    src, res1 = first
    assert sorted(r["id"] for r in res1["cases"]) == RECORDED
    path = tmp_path / "run.jsonl"
    path.write_bytes(src.read_bytes())
    # a crash while a line was written leaves it cut short: it is dropped, the rest kept
    with open(path, "a", encoding="utf-8") as f:
        f.write('{"case": {"id": "null/10')
    lines: list[str] = []
    res2 = _run(path, nulls=BENCHMARK_NULLS + 1, lines=lines)
    assert res1["resumed_cases"] == 0 and res2["resumed_cases"] == len(RECORDED)
    assert not any(s.startswith("calibrate") for s in lines)     # the calibration came from the file
    ran = [s for s in lines if s.startswith("case ")]
    assert len(ran) == 1 and "null/1003" in ran[0]
    by_id = {r["id"]: r for r in res2["cases"]}
    for r in res1["cases"]:                                      # the recorded cases, as they were
        assert by_id[r["id"]]["wall_s"] == r["wall_s"]
        assert by_id[r["id"]]["report"]["named"] == r["report"]["named"]
    assert res2["top1_accuracy"] == res1["top1_accuracy"]
    recs = [json.loads(s) for s in path.read_text(encoding="utf-8").splitlines()]
    assert recs[0]["journal"] == "skinkit gap benchmark"
    assert sorted(r["case"]["id"] for r in recs if "case" in r) == sorted(RECORDED + ["null/1003"])


def test_recorded_only_scores_the_journal_and_runs_nothing(first: tuple[Path, dict]) -> None:
    path, res1 = first
    size = path.stat().st_size
    lines: list[str] = []
    res = _run(path, nulls=BENCHMARK_NULLS + 2, lines=lines, recorded_only=True)
    assert path.stat().st_size == size and not any(s.startswith(("case ", "calibrate")) for s in lines)
    assert res["planned_cases"] == len(RECORDED) + 2 and len(res["cases"]) == len(RECORDED)
    assert res["null_false_alarm_rate"] == res1["null_false_alarm_rate"]
    assert res["top1_accuracy"] == res1["top1_accuracy"]
    with pytest.raises(BenchmarkError, match="--journal"):
        run(False, model="lumped", recorded_only=True)
    with pytest.raises(BenchmarkError, match="does not exist"):
        run(False, model="lumped", recorded_only=True, journal=path.parent / "none.jsonl")


def test_other_settings_or_another_file_are_refused(first: tuple[Path, dict], tmp_path: Path) -> None:
    path, _ = first
    with pytest.raises(JournalError, match="diagnose"):
        Journal(path, {"model": {}, "diagnose": {"max_effects": 0}})
    other = tmp_path / "notes.jsonl"
    other.write_text('{"a": 1}\n', encoding="utf-8")
    with pytest.raises(JournalError, match="not a skinkit gap benchmark journal"):
        Journal(other, {})
    with pytest.raises(JournalError, match="does not exist"):
        Journal(tmp_path / "no" / "such" / "run.jsonl", {})


def test_execution_order_runs_whole_seeds_longest_first() -> None:
    def case(kind: str, mag: str | None, seed: int) -> dict:
        return {"id": f"{kind}/{mag}/{seed}", "kind": kind, "magnitude": mag, "seed": seed}

    cases = [case("effect", m, s) for s in (0, 1, 2) for m in ("near", "moderate")]
    cases += [case("pair", "moderate", 0), case("null", None, 1000), case("null", None, 1001)]
    order = [c["id"] for c in execution_order(cases)]
    assert order[:3] == ["pair/moderate/0", "effect/moderate/0", "effect/near/0"]
    assert order[3:5] == ["null/None/1000", "null/None/1001"]
    assert order[5:] == ["effect/moderate/1", "effect/near/1", "effect/moderate/2", "effect/near/2"]
