"""``skinkit recover``: copy a file whose writer died into a cleanly closed one."""

from __future__ import annotations

from pathlib import Path

import click

from skinkit.cli._paths import check_out_file, staged_file
from skinkit.errors import StoreError
from skinkit.store import open_experiment
from skinkit.store import recover as recover_file


def _check_committed(file: Path) -> None:
    """Refuse a record whose committed count is negative or beyond its data (a damaged file
    would otherwise be padded with fill values and called recovered)."""
    import h5py

    with open_experiment(file) as exp:
        f = exp._f  # the open HDF5 file (a crashed writer's file opens only this way)
        for name in exp.record_names():
            g = f.get(f"records/{name}")
            if g is None or "committed" not in g:
                continue
            n = int(g["committed"][0])
            for key, ds in g.items():
                if isinstance(ds, h5py.Dataset) and key != "committed" and ds.maxshape[0] is None:
                    if not 0 <= n <= ds.shape[0]:
                        raise StoreError(str(file), f"records/{name}/committed",
                                         f"{n} committed samples, but {key} holds {ds.shape[0]}")


@click.command()
@click.argument("file", metavar="EXPERIMENT", type=click.Path(path_type=Path))
@click.argument("out", type=click.Path(path_type=Path))
def recover(file: Path, out: Path) -> None:
    """Copy experiment file EXPERIMENT, left open by a writer that died, into OUT: every committed block
    is kept, unfinished records stay marked incomplete, and OUT can be appended to again."""
    if out.exists() or out.is_symlink():
        raise StoreError(str(out), "", "already exists; choose another output file")
    check_out_file(out, "OUT")
    _check_committed(file)
    with staged_file(out) as tmp:  # OUT appears only once the copy is complete
        recover_file(file, tmp)
        with open_experiment(tmp) as exp:
            recs = exp.summary()["records"]
    for r in recs:
        state = "complete" if r["complete"] else "incomplete"
        click.echo(f"{r['protocol']}: {r['samples']} samples ({state})")
    click.echo(f"written {out}")
