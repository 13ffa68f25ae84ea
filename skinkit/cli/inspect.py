"""``skinkit inspect``: what an experiment file holds."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from skinkit import jsonio
from skinkit.store import open_experiment
from skinkit.store.layout import created_text


def _jsonable(v: Any) -> Any:
    """Metadata for JSON: arrays as lists (full precision), bytes as text."""
    if hasattr(v, "tolist"):
        return v.tolist()
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    return v if isinstance(v, (int, float, str, bool, list, dict)) or v is None else str(v)


@click.command()
@click.argument("file", metavar="EXPERIMENT", type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of tables.")
def inspect(file: Path, as_json: bool) -> None:
    """Show what experiment file EXPERIMENT holds: schema version, records (protocol, samples, rate,
    channels, units, complete), cameras, image sequences, profiles, tracks and results.

    A file whose writer died is still shown; its unfinished record has complete = false.
    Tables fit the terminal's width (80 columns and up).
    """
    with open_experiment(file) as exp:
        summary = exp.summary()
        meta = exp.metadata()
    if as_json:
        summary["session"] = {k: _jsonable(v) for k, v in meta.items()}
        click.echo(jsonio.dumps(summary, indent=2))
        return
    from rich.console import Console

    _print(Console(), summary, meta)


def _print(con: Any, summary: dict[str, Any], meta: dict[str, Any]) -> None:
    """The summary as text and tables on rich console ``con`` (wrapped to its width)."""
    from rich import box
    from rich.table import Table

    from skinkit.cli.render import number, text, value

    clean = "" if summary["closed_cleanly"] else "  [yellow](writer did not close the file)[/yellow]"
    con.print(f"[bold]{text(summary['path'])}[/bold]{clean}")
    con.print(f"  schema {text(summary['schema_version'])}, written by skinkit "
              f"{text(summary['skinkit_version'])} on {text(created_text(summary['created']))}")
    for k, v in meta.items():
        con.print(f"  {text(k)}: {value(v)}")
    records = summary["records"]
    if records:
        con.print(_records_table(records))
        con.print(_channels(records))
    if summary["cameras"]:
        c = Table(title="cameras", title_justify="left", box=box.SIMPLE_HEAD, show_edge=False)
        for col in ("name", "image size [px]", "focal length [px]"):
            c.add_column(text(col), overflow="fold")
        for cam in summary["cameras"]:
            # 0.1 px of a ~1000 px focal length is what a calibration resolves
            c.add_row(text(cam["name"]), "x".join(map(str, cam["image_size"])),
                      ", ".join(number(f, 5) for f in cam["focal_px"]))
        con.print(c)
    for im in summary["images"]:
        con.print(f"images {text(im['name'])}: {im['frames']} frames x {len(im['cameras'])} cameras "
                  f"{im['image_size'][0]}x{im['image_size'][1]} {text(im['dtype'])}"
                  + ("" if im["complete"] else " [red](incomplete)[/red]"))
    for p in summary["profiles"]:
        con.print(f"profile {text(p['name'])}: {p['points']} points")
    for tr in summary["tracks"]:
        con.print(f"track {text(tr['name'])}: {tr['points']} points x {tr['frames']} frames")
    for c in summary["calibrations"]:
        con.print(f"calibration {text(c)}")
    for f in summary["fits"]:
        con.print(f"fit {text(f)}")
    for g in summary["gaps"]:
        con.print(f"gap report {text(g)}")
    for a in summary.get("attempts", []):
        con.print(f"[red]failed run[/red] {text(a['name'])}: {text(a['protocol'].get('name', '?'))} "
                  f"({text(a.get('driver', '?'))} driver, at {text(a.get('stage', '?'))}, "
                  f"{a.get('samples', 0)} samples, {text(a.get('started', '?'))}): "
                  f"{text(a.get('reason', '?'))}")


def _records_table(records: list[dict[str, Any]]) -> Any:
    """The records as a rich table: protocol, kind, samples, rate, duration, complete."""
    from rich import box
    from rich.table import Table

    from skinkit.cli.render import number, text

    t = Table(title="records", title_justify="left", box=box.SIMPLE_HEAD, show_edge=False)
    t.add_column("protocol", no_wrap=True)  # a name is not broken; the others fold
    for col in ("kind", "samples", "rate [Hz]", "duration [s]", "complete"):
        t.add_column(text(col), justify="right" if col in ("samples", "rate [Hz]",
                                                           "duration [s]") else "left",
                     overflow="fold", no_wrap=col != "complete",  # numbers stay whole
                     min_width=8 if col == "complete" else None)
    for r in records:
        rate = "?" if r["rate_hz"] is None else number(r["rate_hz"], 6)
        done = "yes" if r["complete"] else "[red]no[/red]"
        if "samples_lost" in r["extra"]:
            done += f" ({r['extra']['samples_lost']} lost)"
        t.add_row(text(r["protocol"]), text(r["kind"]), str(r["samples"]), rate,
                  number(r["duration_s"]), done)
    return t


def _channels(records: list[dict[str, Any]]) -> Any:
    """One row per channel: its unit and the records holding it (a column that folds,
    rather than one cell per record listing every channel)."""
    from rich import box
    from rich.table import Table

    from skinkit.cli.render import text

    units: dict[str, set[str]] = {}
    holders: dict[str, list[str]] = {}
    for r in records:
        for ch, unit in r["units"].items():
            units.setdefault(ch, set()).add(unit)
            holders.setdefault(ch, []).append(r["protocol"])
    t = Table(title="channels", title_justify="left", box=box.SIMPLE_HEAD, show_edge=False)
    t.add_column(text("channel [unit]"), no_wrap=True)
    t.add_column("records", overflow="fold")
    for ch, names in holders.items():
        where = "all" if len(names) == len(records) else ", ".join(names)
        t.add_row(text(f"{ch} [{', '.join(sorted(units[ch]))}]"), text(where))
    return t
