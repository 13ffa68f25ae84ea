"""The ``skinkit`` command line: a thin layer over :mod:`skinkit.pipelines` and the engines.

Commands are imported lazily (``_COMMANDS`` maps a name to ``module:attribute``) so that
``skinkit --help`` stays fast and a broken optional part cannot stop the rest.
Every :class:`skinkit.errors.SkinkitError` ends the command with a one-line message on
stderr and exit status 2.
"""

from __future__ import annotations

import importlib
import sys
from importlib.metadata import entry_points
from typing import Any

import click

from skinkit import __version__
from skinkit.errors import SkinkitError

_COMMANDS: dict[str, str] = {
    "plugins": "skinkit.cli.plugins:plugins",
    "inspect": "skinkit.cli.inspect:inspect",
    "import-csv": "skinkit.cli.import_csv:import_csv",
    "import-extensometer": "skinkit.cli.import_extensometer:import_extensometer_cmd",
    "import-images": "skinkit.cli.import_vision:import_images",
    "import-calibration": "skinkit.cli.import_vision:import_calibration",
    "import-tracks": "skinkit.cli.import_vision:import_tracks",
    "recover": "skinkit.cli.recover:recover",
    "demo": "skinkit.cli.demo:demo",
    "bench": "skinkit.cli.bench:bench",
    "robot": "skinkit.cli.robot:robot",
    "solve": "skinkit.cli.fem:solve",
    "verify": "skinkit.cli.fem:verify",
    "convergence": "skinkit.cli.fem:convergence",
    "sysid": "skinkit.cli.sysid:sysid",
    "vision": "skinkit.cli.vision:vision",
    "predict": "skinkit.cli.predict:predict",
    "effects": "skinkit.cli.effects:effects",
    "fit": "skinkit.cli.fit:fit",
    "grid": "skinkit.cli.grid:grid",
    "profile": "skinkit.cli.grid:profile",
    "select": "skinkit.cli.select:select",
    "design": "skinkit.cli.design:design",
    "lab": "skinkit.cli.lab:lab",
    "gap": "skinkit.cli.gap:gap",
}


#: entry-point group through which other distributions add commands (e.g. ``skinkit robot``)
COMMANDS_GROUP = "skinkit.commands"


def _extension_commands() -> dict[str, Any]:
    return {ep.name: ep for ep in entry_points(group=COMMANDS_GROUP)}


class _LazyGroup(click.Group):
    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(set(super().list_commands(ctx)) | set(_COMMANDS) | set(_extension_commands()))

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name in _COMMANDS:
            module, attr = _COMMANDS[name].split(":")
            return getattr(importlib.import_module(module), attr)
        ext = _extension_commands().get(name)
        if ext is not None:
            try:
                return ext.load()
            except Exception as exc:  # a broken extension must not break the other commands
                dist = ext.dist.name if ext.dist is not None else "?"
                raise click.ClickException(
                    f"command {name!r} from {dist} ({ext.value}) failed to import: "
                    f"{type(exc).__name__}: {exc}") from exc
        return super().get_command(ctx, name)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except SkinkitError as exc:
            click.echo(f"error: {exc}", err=True)
            ctx.exit(2)


@click.group(cls=_LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="skinkit")
def cli() -> None:
    """skinkit: measurements of living skin to mechanical models, and the sim-to-real gap."""


def main(argv: list[str] | None = None) -> None:
    """Console entry point."""
    cli.main(args=argv if argv is not None else sys.argv[1:], prog_name="skinkit")
