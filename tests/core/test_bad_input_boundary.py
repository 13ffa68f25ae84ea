"""The CLI boundary: bad input is one line and exit 2; anything else is
one line and exit 3 (or the traceback with --debug); Ctrl-C is one line and exit 130."""

from __future__ import annotations

import subprocess
import sys

import click
import pytest
from click.testing import CliRunner

from skinkit.cli import EXIT_INTERNAL, EXIT_INTERRUPTED, cli
from skinkit.errors import SkinkitError


def _raiser(exc: BaseException) -> click.Command:
    def run() -> None:
        raise exc
    return click.Command("_boom", callback=run)


@pytest.fixture
def boom():
    """Register a throw-away command that raises what the test gives it."""
    def add(exc: BaseException) -> None:
        cli.add_command(_raiser(exc))
    yield add
    cli.commands.pop("_boom", None)


def _lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip()]


def test_unexpected_exception_is_one_line_exit_3(boom):
    boom(ZeroDivisionError("division by zero"))
    r = CliRunner().invoke(cli, ["_boom"])
    assert r.exit_code == EXIT_INTERNAL == 3
    (line,) = _lines(r.stderr)
    assert line.startswith("error: internal error in skinkit: ZeroDivisionError: division by zero")
    assert "--debug" in line and "SKINKIT_DEBUG=1" in line and "report" in line
    assert "Traceback" not in r.output


@pytest.mark.parametrize("how", [["--debug"], "env"])
def test_debug_reraises(boom, how):
    boom(ZeroDivisionError("division by zero"))
    if how == "env":
        r = CliRunner().invoke(cli, ["_boom"], env={"SKINKIT_DEBUG": "1"})
    else:
        r = CliRunner().invoke(cli, [*how, "_boom"])
    assert isinstance(r.exception, ZeroDivisionError)
    assert "internal error" not in r.output


def test_skinkit_error_stays_exit_2(boom):
    boom(SkinkitError("thing: is wrong"))
    r = CliRunner().invoke(cli, ["_boom"])
    assert r.exit_code == 2 and _lines(r.stderr) == ["error: thing: is wrong"]


def test_keyboard_interrupt_is_one_line_exit_130(boom):
    boom(KeyboardInterrupt())
    r = CliRunner().invoke(cli, ["_boom"])
    assert r.exit_code == EXIT_INTERRUPTED == 130
    assert _lines(r.stderr) == ["error: interrupted"]


def test_unwritable_path_is_bad_input(boom, tmp_path):
    boom(PermissionError(13, "Permission denied", str(tmp_path / "x")))
    r = CliRunner().invoke(cli, ["_boom"])
    assert r.exit_code == 2 and _lines(r.stderr) == [f"error: {tmp_path / 'x'}: Permission denied"]


def test_usage_error_is_one_line_naming_the_option():
    r = CliRunner().invoke(cli, ["convergence", "m.toml", "--levels", "abc"])
    assert r.exit_code == 2
    (line,) = _lines(r.stderr)
    assert line.startswith("error: Invalid value for '--levels'")
    assert "convergence --help" in line


def test_console_script_exit_status(tmp_path):
    """The real entry point (not CliRunner): a wrong-typed model entry ends in one line."""
    bad = tmp_path / "m.toml"
    bad.write_bytes(b"\xff\xfe\x00binary")
    p = subprocess.run([sys.executable, "-m", "skinkit", "solve", str(bad)],
                       capture_output=True, text=True)
    assert p.returncode == 2, p.stderr
    assert len(_lines(p.stderr)) == 1 and "Traceback" not in p.stderr
