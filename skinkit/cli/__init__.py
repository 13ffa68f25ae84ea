"""The ``skinkit`` command line: a thin layer over :mod:`skinkit.pipelines` and the engines.

Commands are imported lazily through one registry (:mod:`skinkit.cli.registry`): every group
is a table ``{name: "module:attribute"}`` plus the entry points of ``skinkit.commands``
(top level) or ``skinkit.commands.<group>``, so that ``skinkit --help`` stays fast and a broken
optional part cannot stop the rest.

Positional arguments follow one order and keep one meaning per name:

- ``EXPERIMENT`` is an experiment file (HDF5 session); a command that imports into or writes
  an experiment takes it FIRST, then what it reads (``import-csv EXPERIMENT CSV_FILE``,
  ``import-tracks EXPERIMENT CSV_FILE``, ``import-extensometer EXPERIMENT FOLDER``,
  ``import-calibration EXPERIMENT FILES...``). The old source-first order of ``import-csv``
  and ``import-extensometer`` still works for one release when it is evident (the file given
  as the experiment is not HDF5 and the other is): the two are swapped and one
  ``warning: ... deprecated order ...`` line goes to stderr.
- ``MODEL_FILE SESSION``: a model description, then what it is compared with (an experiment
  file or a CSV record).
- A renamed command keeps its old name for one release, hidden, after a one-line warning
  (``skinkit profile`` is now ``skinkit profile-likelihood``; ``skinkit vision profile``, a
  surface profile, is another thing).

Every :class:`skinkit.errors.SkinkitError` and every usage error ends the command with a
one-line message on stderr and exit status 2; any other exception is a bug and ends it with
one line and exit status 3 (``--debug`` or ``SKINKIT_DEBUG=1`` shows the traceback); Ctrl-C
ends it with status 130.

Progress goes to stderr (:mod:`skinkit.cli._progress`): a bar with the ETA on a terminal, plain
lines at least every 10 s in a log. Every group and command the registry hands out takes
``-q/--quiet`` and ``-v/--verbose``, so both ``skinkit --quiet CMD`` and ``skinkit CMD --quiet``
work (the registry adds them once: :class:`skinkit.cli.registry.LazyGroup`).
"""

from __future__ import annotations

import sys
from typing import Any

import click

from skinkit import __version__
from skinkit.cli.registry import ARGV_KEY, COMMANDS_GROUP, LazyGroup
from skinkit.errors import SkinkitError

__all__ = ["COMMANDS_GROUP", "EXIT_INTERNAL", "EXIT_INTERRUPTED", "cli", "main"]

#: the top-level commands: name -> "module:attribute" (imported when the command is looked up)
COMMANDS: dict[str, str] = {
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
    "profile-likelihood": "skinkit.cli.grid:profile",
    "select": "skinkit.cli.select:select",
    "design": "skinkit.cli.design:design",
    "lab": "skinkit.cli.lab:lab",
    "gap": "skinkit.cli.gap:gap",
    "report": "skinkit.cli.report:report",
    "export": "skinkit.cli.export:export",
}
#: old top-level names kept for one release (hidden; a one-line warning, then they run)
ALIASES: dict[str, str] = {"profile": "profile-likelihood"}

#: exit status of an unexpected exception (a bug), distinct from 2 (bad input)
EXIT_INTERNAL = 3
#: exit status after Ctrl-C (128 + SIGINT, as a shell reports it)
EXIT_INTERRUPTED = 130


class _RootGroup(LazyGroup):
    """The top level: the registry's commands, and the one-line error contract."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        # kept for the pages a command writes, which name the exact command line
        ctx.meta[ARGV_KEY] = list(args)
        return super().parse_args(ctx, args)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except SkinkitError as exc:
            _fail(ctx, str(exc), 2)
        except click.exceptions.NoArgsIsHelpError:
            raise  # the help text, as click shows it
        except click.UsageError as exc:
            # one line, naming the option, instead of click's usage block
            where = exc.ctx.command_path if exc.ctx is not None else "skinkit"
            _fail(ctx, f"{exc.format_message()} (see '{where} --help')", exc.exit_code)
        except (click.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except KeyboardInterrupt:
            _fail(ctx, "interrupted", EXIT_INTERRUPTED)
        except BrokenPipeError:  # the reader went away (``skinkit ... | head``): stop quietly
            ctx.exit(1)
        except OSError as exc:
            if exc.filename is None or _debug(ctx):
                _internal(ctx, exc)
            # a path the user gave that cannot be read or written is bad input, not a bug
            _fail(ctx, f"{exc.filename}: {exc.strerror or exc}", 2)
        except Exception as exc:
            _internal(ctx, exc)


def _debug(ctx: click.Context) -> bool:
    return bool(ctx.find_root().params.get("debug"))


def _fail(ctx: click.Context, message: str, status: int) -> None:
    click.echo(f"error: {' '.join(message.split())}", err=True)
    ctx.exit(status)


def _internal(ctx: click.Context, exc: BaseException) -> None:
    """An exception no check anticipated: one line and exit 3, or the traceback with --debug."""
    if _debug(ctx):
        raise exc
    _fail(ctx, f"internal error in skinkit: {type(exc).__name__}: {exc} — please report it; run "
          "with --debug (or SKINKIT_DEBUG=1) for the traceback", EXIT_INTERNAL)


@click.group(cls=_RootGroup, table=COMMANDS, entry_group=COMMANDS_GROUP, aliases=ALIASES,
             context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="skinkit")
@click.option("--debug", is_flag=True, envvar="SKINKIT_DEBUG",
              help="show the Python traceback of an internal error (env SKINKIT_DEBUG=1)")
def cli(debug: bool) -> None:
    """skinkit: measurements of living skin to mechanical models, and the sim-to-real gap.

    Exit status: 0 success, 2 bad input (one line on stderr naming what is wrong),
    3 internal error (a bug: please report it), 130 interrupted.

    Progress goes to stderr: a bar on a terminal, a plain line at least every 10 s in a log.
    -q/--quiet and -v/--verbose also work after any command's name.
    """


def main(argv: list[str] | None = None) -> None:
    """Console entry point."""
    cli.main(args=argv if argv is not None else sys.argv[1:], prog_name="skinkit")
