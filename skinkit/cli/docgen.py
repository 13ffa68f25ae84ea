"""Reference pages generated from the code, so that they stay true.

``python -m skinkit.cli.docgen > docs/reference/cli.md`` writes the CLI reference (every
command's help, walked through the command registry); ``python -m skinkit.cli.docgen effects >
docs/reference/effects.md`` the table of the installed effect plugins (entry-point group
``skinkit.effects``). Tests check that both pages are current.
"""

from __future__ import annotations

import sys
from typing import Any

import click

from skinkit.cli import cli

CLI_PAGE = "docs/reference/cli.md"
EFFECTS_PAGE = "docs/reference/effects.md"


def _walk(cmd: click.Command, ctx: click.Context, path: list[str]) -> list[str]:
    out = [f"{'#' * min(len(path) + 1, 4)} `{' '.join(path)}`", "", "```text",
           cmd.get_help(ctx).rstrip(), "```", ""]
    if isinstance(cmd, click.Group):
        for name in cmd.list_commands(ctx):
            sub = cmd.get_command(ctx, name)
            if sub is not None and not sub.hidden:
                out += _walk(sub, click.Context(sub, info_name=name, parent=ctx), [*path, name])
    return out


def render() -> str:
    """The whole CLI reference as Markdown."""
    ctx = click.Context(cli, info_name="skinkit", terminal_width=100, max_content_width=100)
    head = ["# CLI reference", "",
            f"Generated from the commands by `python -m skinkit.cli.docgen > {CLI_PAGE}`; "
            "a test checks that it is current.", "",
            "Every command exits with status 2 and a one-line `error: ...` on bad input "
            "(a file, an option, a device reply).", "",
            "Positional arguments: `EXPERIMENT` is an experiment file (HDF5) and comes first in every "
            "command that imports into or writes one; `MODEL_FILE SESSION` is a model description, "
            "then the experiment file or CSV record it is compared with.", "",
            "Progress goes to stderr, never stdout (which carries the result, `--json` included): a bar "
            "with the ETA on a terminal; in a log or CI (stderr not a terminal) a plain `progress:` line "
            "(stage, fraction, elapsed, ETA) at least every 10 s, also through a step that reports no "
            "fraction. Every command takes `-q/--quiet` (no progress, only results and errors) and "
            "`-v/--verbose` (also each stage's time and sub-steps), before or after its name: "
            "`skinkit --quiet CMD` or `skinkit CMD --quiet`.", ""]
    return "\n".join(head + _walk(cli, ctx, ["skinkit"])) + "\n"


def _summary(obj: Any) -> str:
    """The first sentence of an object's docstring, on one line."""
    # reST literals (``x``) as Markdown code (`x`)
    doc = " ".join((type(obj).__doc__ or "").split()).replace("``", "`")
    first = doc.split(". ")[0].rstrip(".")
    return f"{first}." if first else ""


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _bound(v: Any) -> str:
    return "-" if v is None else f"{v:g}"


def effect_rows() -> list[list[str]]:
    """One row per installed effect: name, kinds it applies to, parameters (unit, bounds, null
    and typical value), summary; an effect that fails to load gets its error as the summary."""
    from skinkit import registry

    rows = []
    for name in registry.names("skinkit.effects"):
        try:
            e = registry.create("skinkit.effects", name)
        except Exception as exc:  # listed with its error, as `skinkit plugins` does
            rows.append([f"`{name}`", "", "", f"failed to load: {type(exc).__name__}: {exc}"])
            continue
        forms = tuple(getattr(e, "forms", ()) or ())
        if len(forms) > 1:   # each form's parameters, the default first
            pars = "; ".join(f"form `{f}`{' (default)' if i == 0 else ''}: {_parameters(_in_form(e, f))}"
                             for i, f in enumerate(forms))
        else:
            pars = _parameters(e)
        rows.append([f"`{name}`", ", ".join(e.kinds), pars, _summary(e)])
    return rows


def _in_form(effect: Any, form: str) -> Any:
    """A shallow copy of ``effect`` in ``form`` (as an ``[[effects]]`` table choosing it gets)."""
    import copy

    inst = copy.copy(effect)
    inst.form = form
    return inst


def _parameters(effect: Any) -> str:
    """An effect's parameters: unit, bounds, null and typical value, ``; `` between them."""
    null = dict(effect.null())
    return "; ".join(f"`{p.name}` [{p.unit}] in [{_bound(p.lower)}, {_bound(p.upper)}], "
                     f"null {_bound(null.get(p.name))}, typical {_bound(p.value)}"
                     for p in effect.parameters())


def render_effects() -> str:
    """The table of installed effect plugins as Markdown."""
    head = ["# Effect plugins", "",
            f"Generated from the installed plugins (entry-point group `skinkit.effects`) by "
            f"`python -m skinkit.cli.docgen effects > {EFFECTS_PAGE}`; a test checks that it is current. "
            "`skinkit effects list` prints the same from any environment.", "",
            "Kinds: `fe` finite-element models, `lumped` lumped models. Units: `1` dimensionless, "
            "angles in radians; bounds are the values a fit may take, null the value at which the "
            "effect is absent.", "",
            "| effect | applies to | parameters | summary |", "|---|---|---|---|"]
    body = ["| " + " | ".join(_cell(c) for c in row) + " |" for row in effect_rows()]
    return "\n".join(head + body) + "\n"


def main(argv: list[str]) -> None:
    """Print the page named by ``argv`` (``cli``, the default, or ``effects``)."""
    pages = {"cli": render, "effects": render_effects}
    which = argv[0] if argv else "cli"
    if which not in pages or len(argv) > 1:
        raise SystemExit(f"usage: python -m skinkit.cli.docgen [{'|'.join(pages)}]")
    click.echo(pages[which](), nl=False)


if __name__ == "__main__":
    main(sys.argv[1:])
