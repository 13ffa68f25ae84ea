"""Settings the gap-diagnosis tests share across modules (see ``conftest.py``)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

#: the benchmark run the tests share: two effects at moderate magnitude, one seed, no pairs
BENCHMARK = {"model": "lumped", "effects": ["viscoelastic", "force-drift"], "magnitudes": ["moderate"],
             "seeds": 1, "pairs": 0, "parallel": 1}
#: its null sessions
BENCHMARK_NULLS = 3


def run_benchmark(journal: Path | None, nulls: int, progress: Callable[[str], None] | None = None,
                  **kw: object) -> dict:
    """The shared benchmark's settings with ``nulls`` null sessions, journaled to ``journal``."""
    from skinkit.bench.gap_benchmark import run

    return run(False, progress=progress, nulls=nulls, journal=journal, **BENCHMARK, **kw)
