"""``skinkit plugins``: every plugin group, every plugin, its distribution and load status."""

from __future__ import annotations

import json

import click

from skinkit import registry
from skinkit.protocols import GROUPS


@click.command()
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
@click.option("--group", "groups", multiple=True, type=click.Choice(sorted(GROUPS)),
              help="Only this group (repeatable).")
def plugins(as_json: bool, groups: tuple[str, ...]) -> None:
    """List installed plugins and whether each one loads.

    Loading imports each plugin and checks it against its group's protocol; a plugin that
    fails is listed with status "error" and its message, and the others still load.
    """
    rep = registry.report(list(groups) or None)
    if as_json:
        click.echo(json.dumps({"groups": {g: [s.to_dict() for s in st] for g, st in rep.items()}},
                              indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="skinkit plugins")
    for col in ("group", "name", "distribution", "status"):
        table.add_column(col)
    for group, statuses in rep.items():
        if not statuses:
            table.add_row(group, "-", "-", "[dim]none installed[/dim]")
        for s in statuses:
            status = "[green]ok[/green]" if s.status == "ok" else f"[red]error[/red]: {s.error}"
            table.add_row(group, s.info.name, s.info.dist or "?", status)
    Console().print(table)
