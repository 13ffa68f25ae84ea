"""``skinkit bench store | robot | sysid | fem | vision | cli``: how fast skinkit is beside a peer.

Each command runs :mod:`skinkit.bench`'s plain functions and prints their figures (JSON with
``--json``; a Markdown results page with ``--page``); the benchmark modules are imported only
when a command runs.
"""

from __future__ import annotations

from pathlib import Path

import click

from skinkit.cli._bench_out import emit, page_option, write_page
from skinkit.cli._types import FiniteFloat


@click.command("store")
@click.option("--blocks", type=click.IntRange(1, 100_000), default=200, show_default=True,
              help="Number of blocks.")
@click.option("--block", type=click.IntRange(1, 1_000_000), default=1000, show_default=True,
              help="Samples per block.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@page_option
def bench_store(blocks: int, block: int, as_json: bool, page: Path | None) -> None:
    """Crash-safe record appending (skinkit) against plain h5py appending, same blocks."""
    from skinkit.bench import store

    res = store.run(blocks, block)
    lines = store.summary_lines(res)
    emit(res, as_json, lines)
    write_page(page, "Crash-safe record appending against plain h5py", res, lines)


@click.command("sysid")
@click.option("--repeat", type=click.IntRange(1, 20), default=3, show_default=True,
              help="Runs per timing (the fastest is reported).")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True)
@click.option("--threads", type=click.IntRange(0, 256), default=1, show_default=True,
              help="BLAS threads for both sides (0: library default; 1 avoids "
              "oversubscription on a shared machine).")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@page_option
def bench_sysid(repeat: int, seed: int, threads: int, as_json: bool, page: Path | None) -> None:
    """Wiener identification time (target < 0.5 s) and IRF by Toeplitz/SVD vs plain least
    squares on the full Toeplitz data matrix, same 5 s, 2 kHz record."""
    from skinkit.bench import sysid

    res = sysid.run_limited(repeat=repeat, seed=seed, threads=threads)
    lines = sysid.summary_lines(res)
    emit(res, as_json, lines)
    write_page(page, "Wiener identification and IRF against plain least squares", res, lines)


def _sizes(ctx: click.Context, param: click.Parameter, value: tuple[str, ...]) -> list[int]:
    """``--n 7 --n 10`` or ``--n 7,10``: the block sizes, each 1 to 30, in the order given."""
    out: list[int] = []
    for item in value:
        for part in item.split(","):
            if not part.strip():
                continue
            try:
                n = int(part)
            except ValueError:
                raise click.BadParameter(f"{part.strip()!r} is not a whole number") from None
            if not 1 <= n <= 30:
                raise click.BadParameter(f"{n} is not in the range 1 to 30")
            out.append(n)
    if not out:
        raise click.BadParameter("give at least one size")
    return out


@click.command("fem")
@click.option("--n", "sizes", multiple=True, default=("7",), show_default=True, callback=_sizes,
              help="elements per side (7 -> 10,125 dofs, 10 -> 27,783); repeat it or give a "
                   "comma-separated list for several sizes, one row each")
@click.option("--linear", default="auto", show_default=True, help="linear solver: auto, pardiso, splu")
@click.option("--peer", "peers", multiple=True, type=click.Choice(["sfepy", "ngsolve"]),
              help="peers to run beside skinkit (repeatable; default: all)")
@click.option("--repeat", type=click.IntRange(1, 20), default=1, show_default=True,
              help="solves per code and size; the fastest is reported")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
@page_option
def bench_fem(sizes: list[int], linear: str, peers: tuple[str, ...], repeat: int, as_json: bool,
              page: Path | None) -> None:
    """Seconds per load step and per Newton iteration, skinkit against sfepy and NGSolve.

    Peers that are not installed (pip install 'skinkit[bench]') or that fail are named with
    the reason beside skinkit's figures. Run with OMP_NUM_THREADS=1 to compare one thread each."""
    from skinkit.bench import fem

    res = fem.run_sizes(sizes, linear, peers or tuple(fem.PEERS), repeat=repeat)
    lines = fem.summary_lines(res)
    emit(res, as_json, lines)
    write_page(page, "Seconds per step and per Newton iteration against sfepy and NGSolve", res, lines,
               tables=[(fem.COLUMNS, fem.table_rows(res))])


@click.command("robot")
@click.option("--duration", type=FiniteFloat(0.1, 600.0), default=3.0, show_default=True,
              help="device seconds per configuration")
@click.option("--json", "as_json", is_flag=True)
@page_option
def bench_robot(duration: float, as_json: bool, page: Path | None) -> None:
    """Sustained sample rate over serial (115200, 921600 baud) and CAN (500k, 1M bit/s); one
    configuration per link offers more than the link carries, to show losses being counted."""
    from skinkit.bench import robot

    res = robot.run(duration)
    cols, rows = robot.table_rows(res)
    write_page(page, "Robot link throughput (emulator in real time, 10 kHz control loop)", res,
               tables=[(cols, rows)])
    if as_json:
        emit(res, True, indent=1)
        return
    from rich.console import Console
    from rich.table import Table

    t = Table(title="robot link throughput (emulator in real time, 10 kHz control loop)")
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
@page_option
def bench_vision(trials: int, subset_px: int, seed: int, page: Path | None) -> None:
    """Subpixel error (bias, noise) and subsets/s: pcc and gn vs OpenCV and scikit-image."""
    from rich.console import Console
    from rich.table import Table

    from skinkit.bench import vision

    rows = vision.compare(trials, subset_px, seed)
    title = f"{trials} subsets of {subset_px} px, speckle translation, 1 % noise, 8 bit"
    table = Table(title=title)
    for col in vision.COLUMNS:
        table.add_column(col, justify="left" if col == "method" else "right")
    cells = vision.table_rows(rows)
    for r in cells:
        table.add_row(*r)
    Console(width=140).print(table)
    ratios = vision.ratio_lines(rows)
    for line in ratios:
        click.echo(line)
    write_page(page, f"Subpixel tracking: {title}", {"methods": rows}, ratios,
               tables=[(vision.COLUMNS, cells)])


@click.command("cli")
@click.option("--repeat", default=3, show_default=True, type=click.IntRange(1),
              help="runs per command; the best is reported")
@click.option("--robot-seconds", default=2.0, show_default=True, type=FiniteFloat(0.1),
              help="simulated length of the robot run [s]")
@click.option("--json", "as_json", is_flag=True)
@page_option
def bench_cli(repeat: int, robot_seconds: float, as_json: bool, page: Path | None) -> None:
    """Wall time of `skinkit plugins` and `skinkit robot protocols` (fresh interpreter, best
    of --repeat) and the simulated robot's real-time factor; targets < 1 s and >= 1."""
    from skinkit.bench import cli as figures

    res = figures.run(repeat, robot_seconds)
    rows = figures.table_rows(res)

    def met(ok: bool | None, target: str, markup: bool) -> str:
        if not target:
            return ""
        if ok is None:
            return "-"
        if markup:
            return "[green]yes[/green]" if ok else "[red]no[/red]"
        return "yes" if ok else "no"

    cols = ("figure", "measured", "target", "met")
    write_page(page, "Command-line speed", res, figures.context_lines(res),
               tables=[(cols, [(f, m, t, met(ok, t, False)) for f, m, t, ok in rows])])
    if as_json:
        emit(res, True, indent=1)
        return
    from rich.console import Console
    from rich.table import Table

    t = Table(title="command-line speed")
    for col in cols:
        t.add_column(col)
    for figure, measured, target, ok in rows:
        t.add_row(figure, measured, target, met(ok, target, True))
    con = Console()
    con.print(t)
    for line in figures.context_lines(res):
        con.print(line)
