"""Property test of model files: random types, signs, units, missing and
extra keys applied to every example model file in docs/models never produce a traceback or an
internal error through ``skinkit solve`` — either the model solves, or one ``error:`` line with
exit status 2 says what is wrong (and where, for an entry of the file).

The examples are first shrunk to their coarsest meshes and shortest programmes (one element
per direction and layer where the geometry allows, two steps, two step cuts at most) and the
size limit is set low, so a mutation that asks for a large mesh is refused before building and
every solve that runs is small. Derandomized with a fixed budget: the same examples on every run.
"""

from __future__ import annotations

import copy
import sys
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skinkit.cli import cli
from tests.core._model_files import to_toml

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

pytestmark = pytest.mark.needs_plugins

MODELS = Path(__file__).resolve().parents[2] / "docs" / "models"
#: unknowns a solve may have here: the shrunk examples have 300 to 1,500; anything a mutation
#: enlarges beyond this is refused before building
MAX_UNKNOWNS = 3000


def _shrink(spec: dict[str, Any]) -> dict[str, Any]:
    """The example on its coarsest mesh, with at most a few load steps."""
    s = copy.deepcopy(spec)
    g = s.get("geometry")
    if isinstance(g, dict):
        kind = g.get("kind", "disc")
        if kind == "disc":
            g.update(n_inner=1, n_ring=1)
        elif kind == "block":
            g["n"] = [2, 2]
        else:
            g.update(n_pad=1, n_gap=2, n_outer=1, n_side=1)
    for L in s.get("layers", []):
        L["elements"] = 1
    ld = s.get("load")
    if isinstance(ld, dict):
        if ld.get("kind", "ramp") == "ramp":
            ld["steps"] = 2
        elif ld.get("kind") == "sinusoid":
            ld.update(periods=1, steps_per_period=2)
    # a solve the mutations make hard fails after a few step cuts, not after minutes
    s.setdefault("solver", {}).update(max_unknowns=MAX_UNKNOWNS, max_cuts=2)
    return s


EXAMPLES = {p.name: _shrink(tomllib.loads(p.read_text(encoding="utf-8")))
            for p in sorted(MODELS.glob("*.toml"))}

#: values of the wrong type, sign, size or unit for any entry
ODD = [
    -1, 0, 1, 3, 10**9, -2.5, 0.0, 1.7, 1e-300, 1e300, float("nan"), float("inf"), -float("inf"),
    True, False, "", "abc", "1.5", "-1 mm", "2 kPa", "30 deg", "1 s", "3 N", "0.2", "1e400 mm",
    "nan mm", "5 furlongs", "neo-hookean", "goh", [], [1, 2], ["a"], [1, 2, 3], [[1, 2, 3]], {}, {"x": 1},
]
UNITS = ["mm", "m", "kPa", "Pa", "MPa", "deg", "rad", "s", "Hz", "N", "mN", "1", "%", "mm/kPa", "um"]
EXTRA_KEYS = ["extra", "thicknes", "elements_", "Law", "paramters", "stepz", "indenter_diameter", "mu"]


def _paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path to an entry (key of a table or index of an array), depth first."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append(prefix + (k,))
            out += _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.append(prefix + (i,))
            out += _paths(v, prefix + (i,))
    return out


def _tables(node: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path to a table (the file itself is ``()``)."""
    out = [prefix] if isinstance(node, dict) else []
    children = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in children:
        out += _tables(v, prefix + (k,))
    return out


def _parent(spec: dict, path: tuple) -> Any:
    node = spec
    for k in path[:-1]:
        node = node[k]
    return node


def _resign(v: Any) -> Any:
    if isinstance(v, bool):
        return not v
    if isinstance(v, (int, float)):
        return -v
    if isinstance(v, str):
        parts = v.split(None, 1)
        try:
            x = float(parts[0])
        except (ValueError, IndexError):
            return "-" + v
        return " ".join([repr(-x)] + parts[1:])
    return v


def _reunit(v: Any, unit: str) -> Any:
    """The same number with another unit (or none, or a unit added to a bare number)."""
    if isinstance(v, bool):
        return v
    if isinstance(v, (int, float)):
        return f"{v!r} {unit}"
    if isinstance(v, str):
        head = v.split(None, 1)[0] if v.split() else v
        return head if unit == "1" else f"{head} {unit}"
    return v


def _mutate(spec: dict, data) -> list[str]:
    """Apply one drawn mutation; returns the words that name it (for the report)."""
    op = data.draw(st.sampled_from(["set", "set", "delete", "extra", "sign", "unit"]), label="op")
    if op == "extra":
        where = data.draw(st.sampled_from(_tables(spec)), label="table")
        key = data.draw(st.sampled_from(EXTRA_KEYS), label="key")
        _table = spec
        for k in where:
            _table = _table[k]
        _table[key] = data.draw(st.sampled_from(ODD), label="value")
        return [op, *map(str, where), key]
    paths = _paths(spec)
    if not paths:
        return []
    path = data.draw(st.sampled_from(paths), label="path")
    parent = _parent(spec, path)
    key = path[-1]
    if op == "delete":
        del parent[key]
    elif op == "set":
        parent[key] = copy.deepcopy(data.draw(st.sampled_from(ODD), label="value"))
    elif op == "sign":
        parent[key] = _resign(parent[key])
    else:
        parent[key] = _reunit(parent[key], data.draw(st.sampled_from(UNITS), label="unit"))
    return [op, *map(str, path)]


@settings(max_examples=120, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(name=st.sampled_from(sorted(EXAMPLES)), n=st.integers(1, 3), data=st.data())
def test_mutated_example_model_files_never_crash(tmp_path_factory, name, n, data):
    spec = copy.deepcopy(EXAMPLES[name])
    done = [_mutate(spec, data) for _ in range(n)]
    root = tmp_path_factory.mktemp("model")
    path = root / "m.toml"
    path.write_text(to_toml(spec), encoding="utf-8")
    r = CliRunner().invoke(cli, ["solve", str(path), "--no-vtu", "--out", str(root / "out")],
                           env={"SKINKIT_MAX_UNKNOWNS": str(MAX_UNKNOWNS)})
    where = f"{name} after {done}"
    assert "Traceback" not in r.output and "Traceback" not in r.stderr, (where, r.stderr)
    assert r.exit_code in (0, 2), (where, r.exit_code, r.stderr)
    if r.exit_code == 0:
        assert sorted(p.name for p in (root / "out").iterdir()) == ["result.h5", "summary.json"], where
    else:
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), (where, r.stderr)
        assert not (root / "out").exists(), where
