"""``skinkit report``: one self-contained HTML file with every result an experiment file holds."""

from __future__ import annotations

from pathlib import Path

import click


@click.command()
@click.argument("session", metavar="EXPERIMENT", type=click.Path(path_type=Path))
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="the HTML file to write (default: <experiment stem>-report.html in the current directory)")
@click.option("--overwrite", is_flag=True, help="replace an existing report file")
def report(session: Path, out: Path | None, overwrite: bool) -> None:
    """Write a report of experiment file EXPERIMENT: metadata, robot records, lumped fits,
    calibration, images, surface profiles, tracks, model fits (parameters ± se, correlation,
    identifiability) and gap reports, as ONE HTML file that needs nothing else (figures are
    embedded PNGs, no network).

    EXPERIMENT is only read. Sections for what the file lacks are left out and named as such in the
    contents. An existing report is not replaced without --overwrite.
    """
    import time

    from skinkit.report import write_report

    t0 = time.perf_counter()
    path = write_report(session, out, overwrite=overwrite)
    size = path.stat().st_size
    click.echo(f"wrote {path} ({size / 1e6:.2f} MB, {time.perf_counter() - t0:.1f} s)")
