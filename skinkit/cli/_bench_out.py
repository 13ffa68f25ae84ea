"""What the benchmark commands share: print the figures (text or JSON) and, with ``--page``,
write them as a Markdown results page (:mod:`skinkit.bench.results_page`)."""

from __future__ import annotations

import shlex
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import click

from skinkit import jsonio
from skinkit.cli.registry import ARGV_KEY


def emit(res: Any, as_json: bool, lines: list[str] | None = None, indent: int = 2) -> None:
    """Print ``res`` as JSON (``as_json``) or ``lines`` as text."""
    if as_json:
        click.echo(jsonio.dumps(res, indent=indent))
        return
    for line in lines or []:
        click.echo(line)


def page_option(f: Callable[..., Any]) -> Callable[..., Any]:
    """The ``--page PATH`` option (parameter ``page``), its folder checked before any work; with a
    page the solve cache (``SKINKIT_SOLVE_CACHE``) is not used."""

    def check(ctx: click.Context, param: click.Parameter, value: Path | None) -> Path | None:
        if value is not None:
            import os

            from skinkit.cli._paths import check_out_file
            from skinkit.forward.solve_cache import ENVIRONMENT

            check_out_file(value, "--page")
            # a results page states what the work costs: solves read back would understate it
            os.environ.pop(ENVIRONMENT, None)
        return value

    return click.option("--page", type=click.Path(dir_okay=False, path_type=Path), default=None,
                        callback=check, expose_value=True, is_eager=False,
                        help="also write the figures as a Markdown results page (command line, skinkit "
                             "version, machine and UTC date at the top), e.g. docs/results/NAME.md")(f)


def command_line() -> str:
    """The command line that is running, as the user typed it (``skinkit ...``)."""
    ctx = click.get_current_context()
    argv = ctx.find_root().meta.get(ARGV_KEY)
    if argv is None:  # not run through the root group: the command's own path
        return ctx.command_path
    return shlex.join(["skinkit", *argv])


def write_page(page: Path | None, title: str, res: Any, lines: Sequence[str] = (),
               tables: Sequence[tuple[Sequence[str], Sequence[Sequence[str]]]] = ()) -> None:
    """With ``page``, write the results page and say so on stderr (stdout may be JSON)."""
    if page is None:
        return
    from skinkit.bench.results_page import write

    write(page, title, command_line(), res, lines, tables)
    click.echo(f"wrote {page}", err=True)
