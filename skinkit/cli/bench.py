"""``skinkit bench``: side-by-side benchmarks against peer implementations, run in one process.

Each benchmark reports ratios against a peer on the same input; none of them is a test.
"""

from __future__ import annotations

import importlib

import click

#: benchmark name -> "module:command"
_BENCHES: dict[str, str] = {
    "store": "skinkit.bench.store:bench_store",
    "robot": "skinkit.bench.robot:bench_robot",
    "sysid": "skinkit.bench.sysid:bench_sysid",
    "fem": "skinkit.bench.fem:bench_fem",
    "vision": "skinkit.bench.vision:bench_vision",
    "forward": "skinkit.bench.forward:bench_forward",
    "fit": "skinkit.bench.fit:bench_fit",
    "fit-invivo": "skinkit.bench.fit_invivo:bench_fit_invivo",
    "coverage": "skinkit.bench.coverage:bench_coverage",
    "cli": "skinkit.bench.cli:bench_cli",
}


class _LazyBench(click.Group):
    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(_BENCHES)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in _BENCHES:
            return None
        module, attr = _BENCHES[name].split(":")
        return getattr(importlib.import_module(module), attr)


@click.group(cls=_LazyBench)
def bench() -> None:
    """Run a side-by-side benchmark (skinkit against a peer, same input, one process)."""
