"""Fixtures the gap-diagnosis tests share.

The withheld-effect benchmark on the lumped preset is the most expensive thing here (two
magnitude calibrations and five diagnoses). It runs once, writing its journal, and both the
benchmark's scoring tests and the journal's resume tests read that run; their modules are in
the ``gap_benchmark`` xdist group so that one worker builds it.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.gap._shared import BENCHMARK_NULLS, run_benchmark


@pytest.fixture(scope="session")
def lumped_benchmark(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """``(journal, result)`` of the shared benchmark run; the journal must not be appended to
    (a test that extends the run copies it first)."""
    path = tmp_path_factory.mktemp("gap_benchmark") / "run.jsonl"
    return path, run_benchmark(path, BENCHMARK_NULLS)
