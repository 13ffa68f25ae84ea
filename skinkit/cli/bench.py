"""``skinkit bench``: side-by-side benchmarks against peer implementations, run in one process.

Each benchmark reports ratios against a peer on the same input; none of them is a test. The
measuring lives in :mod:`skinkit.bench` (plain functions returning JSON-ready dicts); the
commands here parse options and print. Other distributions add benchmarks through the
entry-point group ``skinkit.commands.bench``.
"""

from __future__ import annotations

import click

from skinkit.cli.registry import LazyGroup

#: benchmark name -> "module:command"
BENCHES: dict[str, str] = {
    "store": "skinkit.cli.bench_speed:bench_store",
    "robot": "skinkit.cli.bench_speed:bench_robot",
    "sysid": "skinkit.cli.bench_speed:bench_sysid",
    "fem": "skinkit.cli.bench_speed:bench_fem",
    "vision": "skinkit.cli.bench_speed:bench_vision",
    "cli": "skinkit.cli.bench_speed:bench_cli",
    "forward": "skinkit.cli.bench_ident:bench_forward",
    "fit": "skinkit.cli.bench_ident:bench_fit",
    "fit-invivo": "skinkit.cli.bench_ident:bench_fit_invivo",
    "coverage": "skinkit.cli.bench_ident:bench_coverage",
    "mesh-nulls": "skinkit.cli.bench_ident:bench_mesh_nulls",
    "mesh-error": "skinkit.cli.bench_ident:bench_mesh_error",
    "diagnose": "skinkit.cli.bench_ident:bench_diagnose",
    "scar": "skinkit.cli.bench_ident:bench_scar",
}


@click.group("bench", cls=LazyGroup, table=BENCHES)
def bench() -> None:
    """Run a side-by-side benchmark (skinkit against a peer, same input, one process)."""
    _no_solve_cache()


def _no_solve_cache() -> None:
    """Benchmarks measure solves: a solve cache named in the environment is not used by them
    (nor by the worker processes they start)."""
    import os

    from skinkit.forward.solve_cache import ENVIRONMENT
    os.environ.pop(ENVIRONMENT, None)
