"""``skinkit inspect``: what an experiment file holds."""

from __future__ import annotations

import json
from pathlib import Path

import click

from skinkit.store import open_experiment


@click.command()
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of tables.")
def inspect(file: Path, as_json: bool) -> None:
    """Show what experiment FILE holds: schema version, records (protocol, samples, rate,
    channels, units, complete), cameras, image sequences, profiles, tracks and results.

    A file whose writer died is still shown; its unfinished record has complete = false.
    """
    with open_experiment(file) as exp:
        summary = exp.summary()
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    con = Console()
    clean = "" if summary["closed_cleanly"] else "  [yellow](writer did not close the file)[/yellow]"
    con.print(f"[bold]{summary['path']}[/bold]  schema {summary['schema_version']}, "
              f"written by skinkit {summary['skinkit_version']} on {summary['created']}{clean}")
    for k, v in summary["session"].items():
        con.print(f"  {k}: {v}")
    t = Table(title="records")
    t.add_column("protocol", no_wrap=True)
    for col in ("kind", "samples", "rate [Hz]", "duration [s]", "channels [unit]", "complete"):
        t.add_column(col)
    for r in summary["records"]:
        chans = ", ".join(f"{c} [{u}]" for c, u in r["units"].items())
        rate = "?" if r["rate_hz"] is None else f"{r['rate_hz']:.6g}"
        done = "yes" if r["complete"] else "[red]no[/red]"
        if "samples_lost" in r["extra"]:
            done += f" ({r['extra']['samples_lost']} lost)"
        t.add_row(r["protocol"], str(r["kind"]), str(r["samples"]), rate, f"{r['duration_s']:.4g}",
                  chans, done)
    con.print(t)
    if summary["cameras"]:
        c = Table(title="cameras")
        for col in ("name", "image size [px]", "focal [px]"):
            c.add_column(col)
        for cam in summary["cameras"]:
            c.add_row(cam["name"], "x".join(map(str, cam["image_size"])),
                      ", ".join(f"{f:.1f}" for f in cam["focal_px"]))
        con.print(c)
    for im in summary["images"]:
        con.print(f"images {im['name']}: {im['frames']} frames x {len(im['cameras'])} cameras "
                  f"{im['image_size'][0]}x{im['image_size'][1]} {im['dtype']}"
                  + ("" if im["complete"] else " [red](incomplete)[/red]"))
    for p in summary["profiles"]:
        con.print(f"profile {p['name']}: {p['points']} points")
    for tr in summary["tracks"]:
        con.print(f"track {tr['name']}: {tr['points']} points x {tr['frames']} frames")
    for c in summary["calibrations"]:
        con.print(f"calibration {c}")
    for f in summary["fits"]:
        con.print(f"fit {f}")
    for g in summary["gaps"]:
        con.print(f"gap report {g}")
