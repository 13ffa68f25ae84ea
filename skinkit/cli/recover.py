"""``skinkit recover``: copy a file whose writer died into a cleanly closed one."""

from __future__ import annotations

from pathlib import Path

import click

from skinkit.errors import StoreError
from skinkit.store import open_experiment
from skinkit.store import recover as recover_file


@click.command()
@click.argument("file", type=click.Path(path_type=Path))
@click.argument("out", type=click.Path(path_type=Path))
def recover(file: Path, out: Path) -> None:
    """Copy experiment FILE, left open by a writer that died, into OUT: every committed block
    is kept, unfinished records stay marked incomplete, and OUT can be appended to again."""
    if out.exists():
        raise StoreError(str(out), "", "already exists; choose another output file")
    recover_file(file, out)
    with open_experiment(out) as exp:
        recs = exp.summary()["records"]
    for r in recs:
        state = "complete" if r["complete"] else "incomplete"
        click.echo(f"{r['protocol']}: {r['samples']} samples ({state})")
    click.echo(f"written {out}")
