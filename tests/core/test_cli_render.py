"""Terminal output: units survive rich markup, tables fit 80 columns, numbers are rounded
to their significance."""

from __future__ import annotations

import io
import re

import numpy as np
import pytest
from click.testing import CliRunner
from rich.console import Console

from skinkit.cli import cli
from skinkit.cli.render import number, numbers, text, value
from skinkit.schemas import Protocol, RobotRecord
from skinkit.store import create_experiment


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    path = tmp_path_factory.mktemp("inspect") / "s.h5"
    n = 300
    with create_experiment(path) as exp:
        exp.set_metadata(subject="virtual [m]", offset_m=-0.0, depth_m=1.5e-3)
        for name, rate in (("stochastic_preconditioning", 1000.0), ("normal_indentation", 100.0)):
            exp.write_record(RobotRecord(time_s=np.arange(n) / rate, tip_force=np.zeros((n, 3)),
                                         tip_position=np.zeros((n, 3)), motor_current=np.zeros((n, 3)),
                                         protocol=Protocol(name)))
    return path


def test_inspect_at_80_columns_keeps_units_and_width(session):
    res = CliRunner().invoke(cli, ["inspect", str(session)], env={"COLUMNS": "80"})
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert max(len(ln) for ln in lines) <= 80
    out = res.output
    for unit in ("tip_position [m]", "tip_force [N]", "motor_current [A]", "duration [s]"):
        assert unit in out, unit
    assert "stochastic_preconditioning" in out  # names are not broken across lines
    assert "subject: virtual [m]" in out and "offset_m: 0" in out
    # no negative zero printed as a number (the file's path, e.g. /tmp/pytest-of-root/pytest-0/,
    # may hold "-0" inside a word)
    assert not re.search(r"(?<![\w/.-])-0(?:\.0+)?(?![\w.])", out), out
    assert "depth_m: 0.0015" in out


def test_inspect_console_width_80_directly(session):
    from skinkit.cli.inspect import _print
    from skinkit.store import open_experiment

    con = Console(width=80, record=True, file=io.StringIO())
    with open_experiment(session) as exp:
        _print(con, exp.summary(), exp.metadata())
    out = con.export_text()
    assert max(len(ln) for ln in out.splitlines()) <= 80
    assert "tip_position [m]" in out


@pytest.mark.parametrize(("x", "s"), [(-0.0, "0"), (0.0, "0"), (999.9999999999991, "1000"),
                                      (0.30000000000000004, "0.3"), (-0.020000000000000264, "-0.02"),
                                      (30000, "30000"), (1.23456e-5, "1.235e-5"), (2.5e7, "2.5e+7"),
                                      (float("nan"), "nan")])
def test_number_significance(x, s):
    assert number(x) == s


def test_vector_round_off_prints_as_zero():
    # an FE tip force: the in-plane components are round-off of a 20 mN axial load
    assert numbers([-1.3877787807814457e-17, -1.2674323396355547e-16, -0.020000000000000264]) \
        == "0, 0, -0.02"
    assert numbers([-3.52e-16, 1.0]) == "0, 1"
    assert numbers([-3.52e-16]) == "-3.52e-16"  # alone, nothing says it is round-off
    assert value(np.array([1.0, -0.0])) == "[1, 0]"


def test_text_escapes_markup():
    con = Console(width=80, record=True, file=io.StringIO())
    con.print(text("tip_position [m], tip_torque [N m], [bold]x[/bold]"))
    assert con.export_text().strip() == "tip_position [m], tip_torque [N m], [bold]x[/bold]"
