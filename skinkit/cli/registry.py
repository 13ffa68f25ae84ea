"""One lazy command registry for every group of the ``skinkit`` command line.

A group is a :class:`LazyGroup` made from a table ``{name: "module:attribute"}`` of its own
commands and from the entry points of its entry-point group: ``skinkit.commands`` for the top
level, ``skinkit.commands.<group>`` for a group (``skinkit.commands.bench``,
``skinkit.commands.gap``, ``skinkit.commands.robot``, ...), so another distribution can add a
command to any group. A command's module is imported only when the command is looked up, so
``skinkit --help`` and ``skinkit plugins`` import no engine. An extension that fails to import
shows as a one-line error when it is run and does not stop the other commands.

Every group and every command it hands out takes ``-q/--quiet`` and ``-v/--verbose``
(:func:`skinkit.cli._progress.add_output_options`): the flags are added here, once, so that
``skinkit --quiet CMD`` and ``skinkit CMD --quiet`` both work for any command, an extension's too.
Every text option and argument of a command it hands out refuses an empty value
(:func:`refuse_empty_text`): ``''`` is never taken as the default or as "nothing".
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Callable, Mapping
from importlib.metadata import EntryPoint, entry_points
from typing import Any

import click

from skinkit.cli._progress import add_output_options

#: entry-point group through which other distributions add top-level commands; a group ``G``
#: takes sub-commands from ``skinkit.commands.G``
COMMANDS_GROUP = "skinkit.commands"
#: key of the root context's ``meta`` holding the arguments the command line was given
ARGV_KEY = "skinkit.argv"


def entry_point_group(*path: str) -> str:
    """The entry-point group of the command group at ``path`` (() for the top level)."""
    return ".".join([COMMANDS_GROUP, *path])


def extension_entry_points(group: str) -> dict[str, EntryPoint]:
    """Installed entry points of ``group``, by command name (read from metadata, none imported)."""
    return {ep.name: ep for ep in entry_points(group=group)}


def load_target(target: str) -> click.Command:
    """Import ``"module:attribute"`` and return the attribute (a click command)."""
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def _refusing_empty(param: click.Parameter) -> Callable[..., Any]:
    """The click callback of ``param``: its own (whose more precise refusal wins), then the
    refusal of an empty value naming ``param``."""
    own = param.callback

    def callback(ctx: click.Context, p: click.Parameter, value: Any) -> Any:
        out = own(ctx, p, value) if own is not None else value
        given = value if isinstance(value, tuple) else (value,)
        if any(isinstance(v, str) and v == "" for v in given):
            hint = ", or leave the option out for its default" if isinstance(p, click.Option) else ""
            raise click.BadParameter(f"an empty value; give one{hint}", ctx=ctx, param=p)
        return out

    callback.refuses_empty = True  # type: ignore[attr-defined]
    return callback


def refuse_empty_text(cmd: click.Command) -> click.Command:
    """Make every text option and argument of ``cmd`` (not a group's) refuse ``''`` while the
    command line is parsed, before any work: an empty name, list or choice would otherwise be
    taken as the default, as "none", or fail later on a message that does not name the option.
    Idempotent; returns ``cmd``."""
    if isinstance(cmd, click.Group):
        return cmd
    for p in cmd.params:
        if (isinstance(p.type, click.types.StringParamType) and not getattr(p, "is_flag", False)
                and not getattr(p.callback, "refuses_empty", False)):
            p.callback = _refusing_empty(p)
    return cmd


def _broken(name: str, ep: EntryPoint, exc: Exception) -> click.Command:
    """A stand-in for an extension command that failed to import: listed, and refused with one
    line when run."""
    dist = ep.dist.name if ep.dist is not None else "?"
    message = (f"command {name!r} from {dist} ({ep.value}) failed to import: "
               f"{type(exc).__name__}: {exc}")

    def refuse() -> None:
        raise click.ClickException(message)

    return click.Command(name, callback=refuse, help=message, short_help="(failed to import)",
                         add_help_option=False, context_settings={"ignore_unknown_options": True,
                                                                  "allow_extra_args": True})


def deprecated_alias(old: str, target: click.Command, old_path: str, new_path: str) -> click.Command:
    """``target`` under the hidden name ``old``: it runs as ``target`` after one
    ``warning: ... deprecated ...`` line on stderr (once its options are parsed, so a refused
    option is still the only line)."""
    import copy

    alias = copy.copy(target)
    alias.name = old
    alias.hidden = True
    callback: Callable[..., Any] | None = target.callback
    if callback is not None:
        @functools.wraps(callback)
        def warned(*args: Any, **kwargs: Any) -> Any:
            click.echo(f"warning: '{old_path}' is a deprecated name, to be removed; use '{new_path}'",
                       err=True)
            return callback(*args, **kwargs)

        alias.callback = warned
    return alias


class LazyGroup(click.Group):
    """A click group whose commands come from ``table`` (``{name: "module:attribute"}``),
    from the commands attached to it in code, and from the entry points of ``entry_group``;
    ``aliases`` (``{old name: new name}``) are hidden deprecated names of table commands.

    A name in the table wins over an extension of the same name (the core's commands cannot
    be replaced by accident); commands attached in code win over both.
    """

    def __init__(self, *args: Any, table: Mapping[str, str] | None = None, entry_group: str | None = None,
                 aliases: Mapping[str, str] | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.table: dict[str, str] = dict(table or {})
        self.entry_group = entry_group if entry_group is not None else entry_point_group(self.name or "")
        self.aliases: dict[str, str] = dict(aliases or {})
        add_output_options(self)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        """The command ``name``, importing its module now, with ``--quiet``/``--verbose`` and its
        text parameters refusing ``''``; None when there is none."""
        cmd = self._get_command(ctx, name)
        return refuse_empty_text(add_output_options(cmd)) if cmd is not None else None

    def list_commands(self, ctx: click.Context) -> list[str]:
        """Every visible command name, sorted (deprecated aliases are left out)."""
        names = set(super().list_commands(ctx)) | set(self.table)
        names |= set(extension_entry_points(self.entry_group))
        return sorted(names)

    def _get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        cmd = super().get_command(ctx, name)
        if cmd is not None:
            return cmd
        if name in self.table:
            return load_target(self.table[name])
        if name in self.aliases:
            new = self.aliases[name]
            target = self.get_command(ctx, new)
            if target is None:
                return None
            # named as the user types it, whatever the root was invoked as (a test runner's "cli")
            here = " ".join(["skinkit", *ctx.command_path.split()[1:]])
            return deprecated_alias(name, target, f"{here} {name}", f"{here} {new}")
        ep = extension_entry_points(self.entry_group).get(name)
        if ep is None:
            return None
        try:
            return ep.load()
        except Exception as exc:  # a broken extension must not break the other commands
            return _broken(name, ep, exc)
