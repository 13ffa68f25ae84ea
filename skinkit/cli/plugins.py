"""``skinkit plugins``: every plugin group, every plugin and its distribution; with
``--check``, whether each one loads."""

from __future__ import annotations

import json

import click

from skinkit import registry

#: what the listing says when it has not imported the plugins
NOT_LOADED_NOTE = ("listed from entry-point metadata, no plugin imported; "
                   "--check imports each one and checks it against its group's interface")


@click.command()
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
@click.option("--group", "groups", multiple=True, type=click.Choice(sorted(registry.GROUP_NAMES)),
              help="Only this group (repeatable).")
@click.option("--check", is_flag=True,
              help="Import every listed plugin and check it against its group's interface "
              "(slower: imports the engines); status ok or error with the message.")
def plugins(as_json: bool, groups: tuple[str, ...], check: bool) -> None:
    """List installed plugins: group, name, target and distribution.

    The listing reads entry-point metadata only, so it is fast and no plugin code runs; its
    status is "unchecked". With --check each plugin is imported and checked against its
    group's interface: one that fails is listed with status "error" and its message, and the
    others still load.
    """
    wanted = list(groups) or None
    if check:
        rep = registry.report(wanted)
    else:
        rep = {g: [registry.PluginStatus(info, registry.UNCHECKED) for info in infos]
               for g, infos in registry.listing(wanted).items()}
    if as_json:
        out = {"groups": {g: [s.to_dict() for s in st] for g, st in rep.items()},
               "checked": check}
        # plain json, strict: the listing holds only text, flags and None (skinkit.jsonio imports
        # numpy, which a listing must not)
        click.echo(json.dumps(out, indent=2, allow_nan=False))
        return
    from rich import box
    from rich.console import Console
    from rich.markup import escape as text  # not skinkit.cli.render: it imports numpy
    from rich.table import Table

    table = Table(title="skinkit plugins", box=box.SIMPLE_HEAD, show_edge=False)
    # the targets (module:attribute) are in --json; at 80 columns they would crowd the names
    for col in ("group", "name", "distribution") + (("status",) if check else ()):
        table.add_column(col, overflow="fold")
    for group, statuses in rep.items():
        if not statuses:
            table.add_row(group, "[dim]none installed[/dim]", "", *([""] if check else []))
        for k, s in enumerate(statuses):
            cells = [group if k == 0 else "", text(s.info.name), text(s.info.dist or "?")]
            if check:
                cells.append("[green]ok[/green]" if s.status == "ok"
                             else f"[red]error[/red]: {text(s.error)}")
            table.add_row(*cells)
    con = Console()
    con.print(table)
    if not check:
        con.print(f"[dim]{NOT_LOADED_NOTE}[/dim]")
