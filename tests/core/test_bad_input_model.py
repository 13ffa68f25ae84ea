"""Model files and ``skinkit solve`` / ``convergence``: every bad entry is
one ``error:`` line naming the entry and its accepted range, exit status 2, before any work;
a refused or failed solve leaves no file behind and never changes an existing one."""

from __future__ import annotations

import math
import os
import time

import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.fem.errors import ModelError
from skinkit.fem.model import build_model, estimate_size, layer_table
from tests.core._cli import one_error

from ._model_files import base_spec, write

pytestmark = pytest.mark.needs_plugins


def _run(*args: str, env: dict | None = None):
    return CliRunner().invoke(cli, list(args), env=env)


def _tree(root) -> dict:
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in sorted(root.rglob("*"))}


def _layer(i: int, **kw):
    def mutate(s):
        s["layers"][i].update(kw)
    return mutate


def _set(table: str, **kw):
    def mutate(s):
        s.setdefault(table, {}).update(kw)
    return mutate


def _sinusoid(**kw):
    def mutate(s):
        s["load"] = {"kind": "sinusoid", "peak_to_peak": "0.1 mm", "frequency": "1 Hz",
                     "periods": 1, "steps_per_period": 4, **kw}
    return mutate


# (mutation, entry named in the message, words of the accepted range or reason)
CASES = [
    # wrong types
    (_layer(0, elements="abc"), "layers[0].elements", "whole number in [1, 200]"),
    (_layer(0, elements=1.5), "layers[0].elements", "whole number"),
    (_set("geometry", n="4"), "geometry.n", "[nx, ny]"),
    (_set("geometry", n=[2, "x"]), "geometry.n[1]", "whole number"),
    (_set("load", steps="ten"), "load.steps", "whole number in [1, 100000]"),
    (_set("indenter", components="z"), "indenter.components", "0, 1, 2"),
    (_set("indenter", components=[5]), "indenter.components", "0, 1, 2"),
    (_layer(0, options="fast"), "layers[0].options", "expected a table"),
    (_layer(0, prestress={"stretch": ["a", 1.0]}), "layers[0].prestress.stretch[0]", "number"),
    (_layer(0, prestress={"stretch": 1.1}), "layers[0].prestress.stretch", "[l1, l2]"),
    (_layer(0, prestress=3), "layers[0].prestress", "expected a table"),
    (_layer(0, parameters=[1, 2]), "layers[0].parameters", "expected a table"),
    (_set("output", sensitivities="yes"), "output.sensitivities", "true or false"),
    # ranges
    (_set("load", duration="-1 s"), "load.duration", "(0, 1e+06] s"),
    (_sinusoid(periods=-2), "load.periods", "(0, 100000]"),
    (_sinusoid(periods=1.3), "load.periods", "whole number of steps"),
    (_sinusoid(steps_per_period=0), "load.steps_per_period", "[1, 100000]"),
    (_sinusoid(frequency="1e-9 Hz"), "load.frequency", "[1e-06, 10000] Hz"),
    (_layer(1, thickness="-4 mm"), "layers[1].thickness", "(0, 1] m"),
    (_layer(1, thickness=0), "layers[1].thickness", "(0, 1] m"),
    (_layer(1, thickness=math.nan), "layers[1].thickness", "finite"),
    (_layer(1, thickness=math.inf), "layers[1].thickness", "finite"),
    (_layer(1, elements=0), "layers[1].elements", "[1, 200]"),
    (_layer(1, elements=-3), "layers[1].elements", "[1, 200]"),
    (_set("solver", rtol=-1e-8), "solver.rtol", "(0, 0.1]"),
    (_set("solver", rtol=0), "solver.rtol", "(0, 0.1]"),
    (_set("solver", intorder=0), "solver.intorder", "[2, 12]"),
    (_set("solver", intorder=10**6), "solver.intorder", "[2, 12]"),
    (_set("solver", linear="magic"), "solver.linear", "unknown linear solver"),
    (_set("geometry", indenter_diameter="20 mm"), "geometry.indenter_diameter", "(0, 0.01] m"),
    (lambda s: s.update(geometry={"kind": "disc", "diameter": "10 mm", "indenter_diameter": "12 mm"}),
     "geometry.indenter_diameter", "smaller than the disc"),
    (_set("load", value=["0 mm", "0 mm", "-2 m"]), "load.value", "plausible range"),
    (_layer(0, prestress={"stretch": [5.0, 1.0]}), "layers[0].prestress.stretch[0]", "[0.5, 2]"),
    (lambda s: s.update(indenter={"mode": "force", "components": [2]},
                        load={"kind": "ramp", "value": [0, 0, -5000.0], "steps": 1}),
     "load.value", "[0, 1000] N"),
    (lambda s: s.update(load={"kind": "table", "times": [1, 2], "values": [[0, 0, -1e-5]]}),
     "load.values", "one value per time"),
    # unknown keys: the nearest valid key
    (_layer(0, thicknes="1 mm"), "layers[0].thicknes", "did you mean 'thickness'"),
    (_set("solver", rtoll=1e-6), "solver.rtoll", "did you mean 'rtol'"),
    (_set("load", step=3), "load.step", "did you mean 'steps'"),
    (lambda s: s.update(boundry={}), "boundry", "did you mean 'boundary'"),
]


@pytest.mark.parametrize(("mutate", "entry", "words"), CASES,
                         ids=[f"{c[1]}-{i}" for i, c in enumerate(CASES)])
def test_bad_entry_is_one_line_naming_it(tmp_path, mutate, entry, words):
    spec = base_spec()
    mutate(spec)
    with pytest.raises(ModelError) as err:
        build_model(spec)
    assert str(err.value).startswith(f"{entry}: "), str(err.value)
    assert words in str(err.value)
    # and through the CLI: one line, exit 2, nothing written
    path = write(spec, tmp_path / "m.toml")
    before = _tree(tmp_path)
    one_error(_run("solve", str(path)), entry)
    assert _tree(tmp_path) == before


def test_valid_base_model_solves(tmp_path, monkeypatch):
    (tmp_path / "models").mkdir()
    path = write(base_spec(), tmp_path / "models" / "m.toml")
    monkeypatch.chdir(tmp_path)
    r = _run("solve", str(path), "--no-vtu")
    assert r.exit_code == 0, r.output
    # the default output: named after the model, in the current directory, not beside the model
    assert sorted(p.name for p in (tmp_path / "m").iterdir()) == ["result.h5", "summary.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m", "models"]  # no temporary left
    assert sorted(p.name for p in (tmp_path / "models").iterdir()) == ["m.toml"]


def test_size_estimate_is_exact_for_the_base_mesh():
    spec = base_spec()
    m = build_model(spec)
    assert estimate_size(spec, layer_table(spec))["unknowns"] == m.mesh.n_dof


def test_huge_mesh_is_refused_fast_with_estimate_and_override(tmp_path):
    spec = base_spec()
    spec["geometry"]["n"] = [200, 200]
    spec["layers"][1]["elements"] = 40
    path = write(spec, tmp_path / "m.toml")
    t0 = time.process_time()
    line = one_error(_run("solve", str(path)), "geometry:", "unknowns", "GB",
                      "max_unknowns", "SKINKIT_MAX_UNKNOWNS")
    assert time.process_time() - t0 < 10  # refused from the estimate, not built
    assert "80,000 elements" not in line and "over the limit of 300,000" in line
    # the environment variable moves the limit both ways
    small = write(base_spec(), tmp_path / "s.toml")
    one_error(_run("solve", str(small), env={"SKINKIT_MAX_UNKNOWNS": "100"}), "over the limit of 100")
    spec = base_spec()
    spec["solver"]["max_unknowns"] = 100
    one_error(_run("solve", str(write(spec, tmp_path / "t.toml"))), "over the limit of 100")


@pytest.mark.parametrize(("content", "words"), [
    (b"\x89HDF\r\n\x1a\n\x00\x00\xff\xfe", "not a UTF-8 text file"),
    ("name = 'caf\u00e9'\n".encode("latin-1"), "not a UTF-8 text file"),
    (b"[model\nname=", "not valid TOML"),
])
def test_binary_latin1_and_broken_files(tmp_path, content, words):
    path = tmp_path / "m.toml"
    path.write_bytes(content)
    one_error(_run("solve", str(path)), str(path), words)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.toml"]


def test_model_path_without_toml(tmp_path):
    path = tmp_path / "model"
    path.write_text((tmp_path / "x").name)
    one_error(_run("solve", str(path)), "MODEL_FILE", ".toml")
    assert path.is_file() and path.read_text() == "x"


def test_out_that_is_a_file_under_a_file_or_a_symlink(tmp_path):
    model = write(base_spec(), tmp_path / "m.toml")
    f = tmp_path / "afile"
    f.write_text("keep")
    one_error(_run("solve", str(model), "--out", str(f)), "--out")
    one_error(_run("solve", str(model), "--out", str(f / "sub")), "--out", "not a directory")
    target = tmp_path / "elsewhere"
    target.mkdir()
    (tmp_path / "link").symlink_to(target)
    one_error(_run("solve", str(model), "--out", str(tmp_path / "link")), "--out", "symbolic link")
    assert f.read_text() == "keep" and not any(target.iterdir())


def test_failed_solve_keeps_existing_output_and_leaves_nothing(tmp_path):
    model = write(base_spec(), tmp_path / "m.toml")
    out = tmp_path / "res"
    assert _run("solve", str(model), "--out", str(out), "--no-vtu").exit_code == 0
    before = _tree(tmp_path)
    # a model that fails in the solver (the indenter pushed through the block in one step)
    spec = base_spec()
    spec["load"].update(value=["0 mm", "0 mm", "-4.9 mm"], steps=1)
    spec["solver"].update(max_cuts=0, max_iter=3)
    bad = write(spec, tmp_path / "bad.toml")
    before[bad.name] = bad.stat().st_mtime_ns
    r = _run("solve", str(bad), "--out", str(out), "--no-vtu", "--overwrite")
    assert r.exit_code == 2, r.output
    assert "gave up at load" in r.output, r.output  # the solver failed: not a refusal of --out
    assert _tree(tmp_path) == before  # the earlier result is untouched, no temporary is left


@pytest.mark.parametrize("levels", ["0", "-1", "99"])
def test_convergence_levels_out_of_range(tmp_path, levels):
    model = write(base_spec(), tmp_path / "m.toml")
    one_error(_run("convergence", str(model), "--levels", levels), "'--levels'", "1<=x<=8")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.toml"]


def test_convergence_refuses_a_finest_level_too_large_before_solving(tmp_path):
    model = write(base_spec(), tmp_path / "m.toml")
    r = _run("convergence", str(model), "--levels", "3", env={"SKINKIT_MAX_UNKNOWNS": "5000"})
    one_error(r, "over the limit of 5,000")
    assert "level 1" not in r.stderr and sorted(os.listdir(tmp_path)) == ["m.toml"]
