"""The CLI contract as a property.

Invocations are generated from the documented options (the click commands are introspected:
each ranged, typed or choice option gets values outside its type or range) and small model
files get mutated entries. Every run, in-process through click's CliRunner, must end in exit 0,
or exit 2 with exactly one ``error:`` line naming the option or entry -- never exit 3 (an
internal error), a traceback, or a file left behind or changed in its folder.

Budget: fixed ``max_examples``, ``deadline=None``, ``derandomize=True`` (the examples are a
function of the test alone, so CI reruns the same cases). Heavy commands (demo, bench, fit, gap,
lab, predict, ...) get only invalid option values, which click refuses while parsing.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skinkit.cli import cli
from skinkit.cli._types import FiniteFloat
from skinkit.schemas import Protocol, RobotRecord
from skinkit.store import create_experiment

from ._cli import check as _check
from ._cli import commands as _commands
from ._cli import tree as _tree
from ._model_files import base_spec, to_toml

pytestmark = pytest.mark.needs_plugins

BUDGET = settings(max_examples=120, deadline=None, derandomize=True, database=None,
                  suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _bad_values(p: click.Option) -> list[str]:
    """Values outside the option's declared type or range."""
    t = p.type
    if isinstance(t, click.Choice):
        return ["no-such-choice"]
    if isinstance(t, click.IntRange):
        out = ["abc", "1.5"]
        if t.min is not None:
            out.append(str(t.min - 1 if not t.min_open else t.min))
        if t.max is not None:
            out.append(str(t.max + 1 if not t.max_open else t.max))
        return out
    if isinstance(t, click.FloatRange):
        out = ["abc"]
        if t.min is not None:
            out.append(repr(t.min - 1.0 if not t.min_open else t.min))
        if t.max is not None:
            out.append(repr(t.max * 2 + 1.0 if not t.max_open else t.max))
        if isinstance(t, FiniteFloat):
            out += ["nan", "inf"]
        return out
    if t is click.INT or t is click.FLOAT:
        return ["abc"]
    return []


def _dummy(arg: click.Argument) -> list[str]:
    t = arg.type
    v = t.choices[0] if isinstance(t, click.Choice) else ("1" if t in (click.INT, click.FLOAT) else "x")
    return [str(v)] * (1 if arg.nargs in (1, -1) else arg.nargs)


def _option_cases() -> list[tuple[tuple[str, ...], str, str, list[str]]]:
    cases = []
    for path, cmd in _commands(cli, click.Context(cli)):
        args = [a for p in cmd.params if isinstance(p, click.Argument) for a in _dummy(p)]
        for p in cmd.params:
            if isinstance(p, click.Option) and not p.is_flag:
                name = max(p.opts, key=len)
                cases += [(path, name, v, args) for v in _bad_values(p)]
    return cases


OPTION_CASES = _option_cases()


def test_every_ranged_option_has_invalid_values():
    assert len(OPTION_CASES) > 50
    covered = {c[0] for c in OPTION_CASES}
    assert ("convergence",) in covered and ("robot", "emulate") in covered and ("sysid",) in covered


@BUDGET
@given(case=st.sampled_from(OPTION_CASES))
def test_invalid_option_values_fail_with_one_line(tmp_path_factory, case):
    path, name, value, args = case
    root = tmp_path_factory.mktemp("opt")
    before = _tree(root)
    old = os.getcwd()
    os.chdir(root)
    try:
        r = CliRunner().invoke(cli, [*path, f"{name}={value}" if name.startswith("--") else name,
                                     *([] if name.startswith("--") else [value]), *args])
    finally:
        os.chdir(old)
    assert r.exit_code == 2, (path, name, value, r.output)
    _check(r, root, before, (name,))


def _record(path: Path) -> Path:
    rng = np.random.default_rng(0)
    n = 600
    f = np.zeros((n, 3))
    f[:, 2] = rng.normal(0, 0.05, n)
    with create_experiment(path) as exp:
        exp.write_record(RobotRecord(time_s=np.arange(n) / 500.0, tip_force=f,
                                     protocol=Protocol("normal_indentation")))
    return path


_SYSID_OPTIONS = {
    "--robot-mass": st.sampled_from(["0", "0.01", "-1", "nan", "inf", "1e9", "x"]),
    "--robot-damping": st.sampled_from(["0", "2", "-2", "inf", "nan"]),
    "--robot-stiffness": st.sampled_from(["0", "10", "-10", "1e12"]),
    "--memory": st.sampled_from(["0.05", "0", "-1", "1e6", "nan"]),
    "--model": st.sampled_from(["linear", "wiener", "hammerstein", "bogus"]),
    "--axis": st.sampled_from(["x", "z", "w"]),
}


@BUDGET
@given(opts=st.dictionaries(st.sampled_from(sorted(_SYSID_OPTIONS)), st.just(None), max_size=3),
       data=st.data())
def test_sysid_valid_and_invalid_options(tmp_path_factory, opts, data):
    root = tmp_path_factory.mktemp("sysid")
    rec = _record(root / "r.h5")
    argv = ["sysid", str(rec)]
    for k in opts:
        argv += [k, data.draw(_SYSID_OPTIONS[k], label=k)]
    before = _tree(root)
    r = CliRunner().invoke(cli, argv)
    # a zero-mean noise force with no position is refused as a record, naming it
    _check(r, root, before, (*opts, str(rec), "position", "record"))


# ---- model files with mutated entries ---------------------------------------------------

_ODD = st.sampled_from([-1, 0, 0.5, 2, 1e9, math.nan, math.inf, -math.inf, "abc", "1 kPa", "-2 mm",
                        "3 s", True, [1], [], {}, {"x": 1}, "0.2 mm"])

#: (table, key) entries of the base model and its sinusoid variant
_ENTRIES = [("geometry", "size"), ("geometry", "n"), ("geometry", "indenter_diameter"),
            ("geometry", "kind"), ("geometry", "grading"),
            ("layers[0]", "thickness"), ("layers[0]", "elements"), ("layers[1]", "thickness"),
            ("layers[1]", "elements"), ("layers[0]", "law"), ("layers[0]", "options"),
            ("layers[0]", "prestress"), ("layers[0]", "thicknes"),
            ("layers[0].parameters", "mu"), ("layers[1].parameters", "K"),
            ("indenter", "mode"), ("indenter", "components"),
            ("load", "value"), ("load", "steps"), ("load", "duration"), ("load", "kind"),
            ("load", "periods"), ("load", "steps_per_period"), ("load", "frequency"),
            ("solver", "rtol"), ("solver", "atol"), ("solver", "intorder"), ("solver", "max_iter"),
            ("solver", "max_cuts"), ("solver", "line_search"), ("solver", "linear"),
            ("solver", "rtoll"), ("boundary", "fixed"), ("output", "point_depth"),
            ("output", "sensitivities"), ("model", "name")]


def _table(spec: dict, where: str) -> dict:
    node = spec
    for part in where.split("."):
        if "[" in part:
            key, idx = part[:-1].split("[")
            node = node[key][int(idx)]
        else:
            node = node.setdefault(part, {})
    return node


@settings(BUDGET, max_examples=100)
@given(mutations=st.lists(st.tuples(st.sampled_from(_ENTRIES), _ODD), min_size=0, max_size=2),
       sinusoid=st.booleans())
def test_mutated_model_files_keep_the_contract(tmp_path_factory, mutations, sinusoid):
    spec = base_spec()
    if sinusoid:
        spec["load"] = {"kind": "sinusoid", "peak_to_peak": "0.1 mm", "frequency": "1 Hz",
                        "periods": 1, "steps_per_period": 2}
    for (where, key), value in mutations:
        _table(spec, where)[key] = value
    root = tmp_path_factory.mktemp("model")
    model = root / "m.toml"
    model.write_text(to_toml(spec), encoding="utf-8")
    before = _tree(root)
    r = CliRunner().invoke(cli, ["solve", str(model), "--no-vtu", "--out", str(root / "out")])
    names = tuple(n for (where, key), _ in mutations for n in (key, where.split("[")[0].split(".")[0]))
    # a valid model that the solver cannot follow fails with its own one line (no file left)
    _check(r, root, before, (*names, "gave up", "inverted", "Newton", "geometry"))
    if r.exit_code == 0:
        assert sorted(p.name for p in (root / "out").iterdir()) == ["result.h5", "summary.json"]


def test_all_invalid_option_values_exhaustively(tmp_path):
    """Every generated (command, option, value) once: cheap, since click refuses while parsing."""
    failures = []
    for case in OPTION_CASES:
        path, name, value, args = case
        before = _tree(tmp_path)
        old = os.getcwd()
        os.chdir(tmp_path)
        try:
            r = CliRunner().invoke(cli, [*path, f"{name}={value}", *args])
        finally:
            os.chdir(old)
        try:
            assert r.exit_code == 2, r.output
            _check(r, tmp_path, before, (name,))
        except AssertionError as exc:
            failures.append((path, name, value, str(exc)[:200]))
    assert not failures, failures
