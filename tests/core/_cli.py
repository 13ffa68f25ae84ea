"""What the CLI tests share: a command run in this process, the contract of a refused command
(exit 2, one ``error:`` line), the walk over every command of the command line, and a small
one-axis extension record to feed the model commands."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import click
import numpy as np


def in_process(*args: str) -> Any:
    """``skinkit ARGS`` run in this process by click's runner (the command line's parsing and its
    one-line error contract are the same; a new interpreter would only add its start-up): the
    result (exit_code, stdout, stderr). An exception that escaped the one-line error handling is
    raised, as a traceback would be a bug."""
    from click.testing import CliRunner

    from skinkit.cli import cli

    r = CliRunner().invoke(cli, list(args))
    if r.exception is not None and not isinstance(r.exception, SystemExit):
        raise r.exception
    return r


def one_error(r: Any, *needles: str, warnings_ok: bool = False) -> str:
    """Assert that the click result ``r`` is a refusal: exit status 2, no traceback, and exactly one
    ``error: `` line on stderr holding every ``needle`` (``warnings_ok``: ``warning:`` lines may
    precede it). Returns that line."""
    assert r.exit_code == 2, (r.exit_code, r.output)
    assert "Traceback" not in r.output
    lines = [ln for ln in r.stderr.splitlines()
             if ln.strip() and not (warnings_ok and ln.startswith("warning:"))]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


def commands(group: click.Group, ctx: click.Context, prefix: tuple[str, ...] = (), *,
             groups: bool = False) -> Iterator[tuple[tuple[str, ...], click.Command]]:
    """Every command under ``group``: its words after ``skinkit`` and the click command; the
    groups are walked, and yielded too (``group`` itself first) when ``groups``."""
    if groups:
        yield prefix, group
    for name in group.list_commands(ctx):
        cmd = group.get_command(ctx, name)
        if cmd is None:
            continue
        if isinstance(cmd, click.Group):
            yield from commands(cmd, click.Context(cmd, parent=ctx), (*prefix, name), groups=groups)
        else:
            yield (*prefix, name), cmd


def tree(root: Path) -> dict[str, int]:
    """Every path under ``root`` with its modification time [ns]: equal before and after a
    command when it left nothing behind and changed nothing."""
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in sorted(root.rglob("*"))}


def check(result: Any, root: Path, before: dict[str, int], names: tuple[str, ...]) -> None:
    """The contract: exit 0, or exit 2 with one ``error:`` line naming one of ``names`` and
    the folder ``root`` as it was (``before``, a :func:`tree`)."""
    assert result.exit_code in (0, 2), (result.exit_code, result.output)
    assert "Traceback" not in result.output
    if result.exit_code == 2:
        lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
        assert any(n in lines[0] for n in names), (names, lines[0])
        assert tree(root) == before, "a refused command changed or left files"


def extension_record(path: Path, displacement_mm: np.ndarray) -> str:
    """Write a one-axis extension record CSV at 100 Hz to ``path``: the tip displacement
    ``displacement_mm`` ``(n,)`` [mm] and an exponential force of it [N] with a small ripple;
    returns the path as a string."""
    d_mm = np.asarray(displacement_mm, dtype=float)
    t = np.arange(d_mm.size) / 100.0
    f = 0.015 * np.expm1(0.32 * d_mm) - 0.077 + 1e-3 * np.sin(7.0 * t)
    path.write_text("time_s,displacement_mm,force_N\n"
                    + "".join(f"{a:.4f},{b:.5f},{c:.6f}\n" for a, b, c in zip(t, d_mm, f, strict=True)))
    return str(path)
