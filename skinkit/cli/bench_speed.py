"""``skinkit bench store | robot | sysid | fem | vision | cli``: how fast skinkit is beside a peer.

Each command runs :mod:`skinkit.bench`'s plain functions and prints their figures (JSON with
``--json``); the benchmark modules are imported only when a command runs.
"""

from __future__ import annotations

from typing import Any

import click

from skinkit import jsonio
from skinkit.cli._types import FiniteFloat


def emit(res: Any, as_json: bool, lines: list[str] | None = None, indent: int = 2) -> None:
    """Print ``res`` as JSON (``as_json``) or ``lines`` as text."""
    if as_json:
        click.echo(jsonio.dumps(res, indent=indent))
        return
    for line in lines or []:
        click.echo(line)


@click.command("store")
@click.option("--blocks", type=click.IntRange(1, 100_000), default=200, show_default=True,
              help="Number of blocks.")
@click.option("--block", type=click.IntRange(1, 1_000_000), default=1000, show_default=True,
              help="Samples per block.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def bench_store(blocks: int, block: int, as_json: bool) -> None:
    """Crash-safe record appending (skinkit) against plain h5py appending, same blocks."""
    from skinkit.bench import store

    res = store.run(blocks, block)
    emit(res, as_json, None if as_json else store.summary_lines(res))


@click.command("sysid")
@click.option("--repeat", type=click.IntRange(1, 20), default=3, show_default=True,
              help="Runs per timing (the fastest is reported).")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True)
@click.option("--threads", type=click.IntRange(0, 256), default=1, show_default=True,
              help="BLAS threads for both sides (0: library default; 1 avoids "
              "oversubscription on a shared machine).")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def bench_sysid(repeat: int, seed: int, threads: int, as_json: bool) -> None:
    """Wiener identification time (target < 0.5 s) and IRF by Toeplitz/SVD vs plain least
    squares on the full Toeplitz data matrix, same 5 s, 2 kHz record."""
    from skinkit.bench import sysid

    res = sysid.run_limited(repeat=repeat, seed=seed, threads=threads)
    emit(res, as_json, None if as_json else sysid.summary_lines(res))


@click.command("fem")
@click.option("--n", type=click.IntRange(1, 30), default=7, show_default=True,
              help="elements per side (7 -> 10,125 dofs)")
@click.option("--linear", default="auto", show_default=True, help="linear solver: auto, pardiso, splu")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
def bench_fem(n: int, linear: str, as_json: bool) -> None:
    """Seconds per Newton iteration, skinkit against sfepy, same mesh and law."""
    from skinkit.bench import fem

    res = fem.run(n, linear)
    emit(res, as_json, None if as_json else fem.summary_lines(res))


@click.command("robot")
@click.option("--duration", type=FiniteFloat(0.1, 600.0), default=3.0, show_default=True,
              help="device seconds per configuration")
@click.option("--json", "as_json", is_flag=True)
def bench_robot(duration: float, as_json: bool) -> None:
    """Sustained sample rate over serial (115200, 921600 baud) and CAN (500k, 1M bit/s); one
    configuration per link offers more than the link carries, to show losses being counted."""
    from skinkit.bench import robot

    res = robot.run(duration)
    if as_json:
        emit(res, True, indent=1)
        return
    from rich.console import Console
    from rich.table import Table

    t = Table(title="robot link throughput (emulator in real time, 10 kHz control loop)")
    cols, rows = robot.table_rows(res)
    for col in cols:
        t.add_column(col)
    for r in rows:
        t.add_row(*r)
    Console().print(t)


@click.command("vision")
@click.option("--trials", type=click.IntRange(1, 100_000), default=100, show_default=True,
              help="number of subsets")
@click.option("--subset", "subset_px", type=click.IntRange(8, 1024), default=64, show_default=True,
              help="subset side [px]")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True)
def bench_vision(trials: int, subset_px: int, seed: int) -> None:
    """Subpixel error (bias, noise) and subsets/s: pcc and gn vs OpenCV and scikit-image."""
    from rich.console import Console
    from rich.table import Table

    from skinkit.bench import vision

    rows = vision.compare(trials, subset_px, seed)
    table = Table(title=f"{trials} subsets of {subset_px} px, speckle translation, 1 % noise, 8 bit")
    for col in vision.COLUMNS:
        table.add_column(col, justify="left" if col == "method" else "right")
    for r in vision.table_rows(rows):
        table.add_row(*r)
    Console(width=140).print(table)
    for line in vision.ratio_lines(rows):
        click.echo(line)


@click.command("cli")
@click.option("--repeat", default=3, show_default=True, type=click.IntRange(1),
              help="runs per command; the best is reported")
@click.option("--robot-seconds", default=2.0, show_default=True, type=FiniteFloat(0.1),
              help="simulated length of the robot run [s]")
@click.option("--json", "as_json", is_flag=True)
def bench_cli(repeat: int, robot_seconds: float, as_json: bool) -> None:
    """Wall time of `skinkit plugins` and `skinkit robot protocols` (fresh interpreter, best
    of --repeat) and the simulated robot's real-time factor; targets < 1 s and >= 1."""
    from skinkit.bench import cli as bench_cli_figures

    res = bench_cli_figures.run(repeat, robot_seconds)
    if as_json:
        emit(res, True, indent=1)
        return
    from rich.console import Console
    from rich.table import Table

    def mark(ok: bool | None) -> str:
        return "-" if ok is None else ("[green]yes[/green]" if ok else "[red]no[/red]")

    t = Table(title="command-line speed")
    for col in ("figure", "measured", "target", "met"):
        t.add_column(col)
    for figure, measured, target, met in bench_cli_figures.table_rows(res):
        t.add_row(figure, measured, target, mark(met) if target else "")
    con = Console()
    con.print(t)
    for line in bench_cli_figures.context_lines(res):
        con.print(line)
