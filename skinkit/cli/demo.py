"""``skinkit demo``: the main job on the embedded default (the virtual lab)."""

from __future__ import annotations

import json
from pathlib import Path

import click


@click.command()
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("demo-output"),
              show_default=True, help="Folder for the experiment file, plots and summary.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the virtual session.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def demo(out_dir: Path, seed: int, as_json: bool) -> None:
    """Run every pipeline step that exists on a virtual-lab session whose truth is known."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from skinkit.pipelines.demo import run_demo

    with Progress(TextColumn("{task.description:<28}"), BarColumn(), TimeElapsedColumn(),
                  disable=as_json) as bar:
        tasks: dict[str, int] = {}

        def progress(step: str, fraction: float) -> None:
            if step not in tasks:
                tasks[step] = bar.add_task(step, total=1.0)
            bar.update(tasks[step], completed=fraction)

        summary = run_demo(out_dir, seed=seed, progress=progress)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    rec = summary["store"]["records"][0]
    click.echo(f"experiment file: {summary['experiment_file']}")
    click.echo(f"  record {rec['protocol']!r}: {rec['samples']} samples at {rec['rate_hz']:.0f} Hz, "
               f"channels {', '.join(rec['channels'])}, complete={rec['complete']}")
    click.echo(f"truth: K={summary['truth']['K']:.4g} N/m, B={summary['truth']['B']:.4g} N s/m, "
               f"I={summary['truth']['I'] * 1e3:.4g} g")
    for p in summary["plots"]:
        click.echo(f"plot: {p}")
    click.echo(f"summary: {out_dir / 'summary.json'}")
