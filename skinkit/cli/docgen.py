"""Generate the CLI reference (docs/cli.md) from the commands themselves, so it stays true.

``python -m skinkit.cli.docgen > docs/cli.md``
"""

from __future__ import annotations

import click

from skinkit.cli import cli


def _walk(cmd: click.Command, ctx: click.Context, path: list[str]) -> list[str]:
    out = [f"{'#' * min(len(path) + 1, 4)} `{' '.join(path)}`", "", "```text",
           cmd.get_help(ctx).rstrip(), "```", ""]
    if isinstance(cmd, click.Group):
        for name in cmd.list_commands(ctx):
            sub = cmd.get_command(ctx, name)
            if sub is not None:
                out += _walk(sub, click.Context(sub, info_name=name, parent=ctx), [*path, name])
    return out


def render() -> str:
    """The whole reference as Markdown."""
    ctx = click.Context(cli, info_name="skinkit", terminal_width=100, max_content_width=100)
    head = ["# CLI reference", "",
            "Generated from the commands by `python -m skinkit.cli.docgen > docs/cli.md`; "
            "a test checks that it is current.", "",
            "Every command exits with status 2 and a one-line `error: ...` on bad input "
            "(a file, an option, a device reply).", ""]
    return "\n".join(head + _walk(cli, ctx, ["skinkit"])) + "\n"


if __name__ == "__main__":
    click.echo(render(), nl=False)
