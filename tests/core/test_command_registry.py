"""One command registry for every group: a third-party distribution joins any group through
``skinkit.commands[.<group>]``, a broken one is reported in one line and stops nothing else;
old names and the old argument order still work for one release, with a warning line."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import click
import h5py
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.cli import registry as R

ROOT = Path(__file__).resolve().parents[2]

_MODULE = '''
import click

@click.command("tp-hello")
@click.option("--json", "as_json", is_flag=True)
def hello(as_json):
    """Say hello from a third party."""
    click.echo('{"hello": 1}' if as_json else "hello")

@click.command("tp-extra")
def extra():
    """A third-party benchmark."""
    click.echo("extra ran")
'''

#: entry-point group -> name -> target of the throw-away distribution
_EPS = {
    "skinkit.commands": {"tp-hello": "tp_cmds.cmds:hello", "tp-broken": "tp_cmds.boom:cmd"},
    "skinkit.commands.bench": {"tp-extra": "tp_cmds.cmds:extra"},
    "skinkit.commands.gap": {"tp-extra": "tp_cmds.cmds:extra"},
    "skinkit.commands.vision": {"tp-extra": "tp_cmds.cmds:extra"},
}


@pytest.fixture
def third_party(tmp_path, monkeypatch):
    """A distribution installed as plain files on sys.path (a dist-info folder beside its package)."""
    pkg = tmp_path / "tp_cmds"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "cmds.py").write_text(textwrap.dedent(_MODULE))
    (pkg / "boom.py").write_text("raise RuntimeError('tp-cmds cannot find its config')\n")
    info = tmp_path / "tp_cmds-0.0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: tp-cmds\nVersion: 0.0.1\n")
    (info / "entry_points.txt").write_text("".join(
        f"[{g}]\n" + "".join(f"{n} = {t}\n" for n, t in eps.items()) + "\n" for g, eps in _EPS.items()))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for mod in [m for m in sys.modules if m == "tp_cmds" or m.startswith("tp_cmds.")]:
        del sys.modules[mod]


def test_third_party_commands_join_the_top_level_and_any_group(third_party):
    r = CliRunner().invoke(cli, ["tp-hello", "--json"])
    assert r.exit_code == 0 and r.stdout.strip() == '{"hello": 1}', r.output
    for group in ("bench", "gap", "vision"):
        r = CliRunner().invoke(cli, [group, "--help"])
        assert r.exit_code == 0 and "tp-extra" in r.output, (group, r.output)
        r = CliRunner().invoke(cli, [group, "tp-extra"])
        assert r.exit_code == 0 and r.stdout == "extra ran\n", (group, r.output)
    assert "tp-hello" in CliRunner().invoke(cli, ["--help"]).output


def test_a_broken_extension_is_one_line_and_stops_nothing(third_party):
    r = CliRunner().invoke(cli, ["--help"])
    assert r.exit_code == 0 and "tp-broken" in r.output and "tp-hello" in r.output
    r = CliRunner().invoke(cli, ["tp-broken", "--anything"])
    assert r.exit_code != 0 and "Traceback" not in r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "tp-cmds cannot find its config" in lines[0] and "tp-broken" in lines[0]
    assert CliRunner().invoke(cli, ["tp-hello"]).stdout == "hello\n"


def test_every_group_is_a_lazy_group_with_its_entry_point_group():
    ctx = click.Context(cli)
    assert isinstance(cli, R.LazyGroup) and cli.entry_group == "skinkit.commands"
    groups = [n for n in cli.list_commands(ctx) if isinstance(cli.get_command(ctx, n), click.Group)]
    assert {"bench", "effects", "gap", "lab", "robot", "vision"} <= set(groups)
    for name in groups:
        g = cli.get_command(ctx, name)
        assert isinstance(g, R.LazyGroup), name
        assert g.entry_group == R.entry_point_group(name) == f"skinkit.commands.{name}"


def test_table_targets_resolve_and_name_their_command():
    ctx = click.Context(cli)
    for group in (cli, cli.get_command(ctx, "bench"), cli.get_command(ctx, "gap")):
        for name, target in group.table.items():
            cmd = R.load_target(target)
            assert isinstance(cmd, click.Command), target
            assert cmd.name == name, (name, target)


def test_coverage_cases_of_the_command_are_the_benchmarks():
    from skinkit.bench.coverage import CASES
    from skinkit.cli.bench_ident import COVERAGE_CASES

    assert COVERAGE_CASES == CASES


def test_profile_is_a_hidden_deprecated_alias_of_profile_likelihood():
    ctx = click.Context(cli)
    assert "profile" not in cli.list_commands(ctx) and "profile-likelihood" in cli.list_commands(ctx)
    alias = cli.get_command(ctx, "profile")
    assert alias is not None and alias.hidden
    assert "profile-likelihood" in CliRunner().invoke(cli, ["--help"]).output
    assert "  profile " not in CliRunner().invoke(cli, ["--help"]).output
    # refused options: the error is still the only line (the warning comes once options parse)
    r = CliRunner().invoke(cli, ["profile", "a.toml", "b.csv", "--parameter", "x", "--n", "1"])
    assert r.exit_code == 2 and [ln for ln in r.stderr.splitlines() if ln][0].startswith("error:")


def test_profile_alias_warns_once_then_runs(tmp_path):
    r = CliRunner().invoke(cli, ["profile", str(tmp_path / "none.toml"), str(tmp_path / "none.csv"),
                                 "--parameter", "lumped.a"])
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert lines[0].startswith("warning: 'skinkit profile' is a deprecated name")
    assert "skinkit profile-likelihood" in lines[0]
    assert len(lines) == 2 and lines[1].startswith("error:") and r.exit_code == 2, r.stderr


def _csv(path: Path) -> Path:
    path.write_text("time_s,force_N\n0,0\n0.01,1\n0.02,2\n")
    return path


def test_import_csv_experiment_first(tmp_path):
    csv, exp = _csv(tmp_path / "r.csv"), tmp_path / "e.h5"
    r = CliRunner().invoke(cli, ["import-csv", str(exp), str(csv)])
    assert r.exit_code == 0 and "warning" not in r.stderr, r.output
    assert h5py.is_hdf5(exp)


@pytest.mark.parametrize("existing", [False, True])
def test_import_csv_old_order_is_swapped_with_one_warning(tmp_path, existing):
    csv, exp = _csv(tmp_path / "r.csv"), tmp_path / "e.h5"
    if existing:
        first = CliRunner().invoke(cli, ["import-csv", str(exp), str(csv), "--protocol", "first"])
        assert first.exit_code == 0, first.output
    r = CliRunner().invoke(cli, ["import-csv", str(csv), str(exp)])
    assert r.exit_code == 0, r.output
    (warning,) = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert warning.startswith("warning:") and "deprecated order" in warning
    assert "imported 3 samples" in r.stdout and csv.read_text().startswith("time_s")


def test_hdf5_is_told_by_signature_not_by_name(tmp_path):
    from skinkit.cli._order import experiment_first, has_hdf5_signature

    odd = tmp_path / "session.data"
    with h5py.File(odd, "w"):
        pass
    csv = _csv(tmp_path / "r.csv")
    assert has_hdf5_signature(odd) and not has_hdf5_signature(csv)
    assert experiment_first(csv, odd, "skinkit import-csv") == (odd, csv)
    # neither is evidently swapped: left as given
    assert experiment_first(tmp_path / "new", csv, "x") == (tmp_path / "new", csv)
    assert experiment_first(odd, csv, "x") == (odd, csv)


def test_import_extensometer_old_order_is_swapped(tmp_path):
    folder = tmp_path / "rec"
    folder.mkdir()
    r = CliRunner().invoke(cli, ["import-extensometer", str(folder), str(tmp_path / "s.h5")])
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert lines[0].startswith("warning:") and "deprecated order" in lines[0]
    # the folder is read as the source (and refused: it holds no record), no file written
    assert r.exit_code == 2 and lines[-1].startswith("error:") and str(folder) in lines[-1], r.stderr
    assert not (tmp_path / "s.h5").exists()


def test_experiment_comes_first_in_every_command_that_writes_one():
    ctx = click.Context(cli)
    for name in ("import-csv", "import-extensometer", "import-images", "import-calibration", "import-tracks"):
        args = [p.name for p in cli.get_command(ctx, name).params if isinstance(p, click.Argument)]
        assert args[0] == "experiment", (name, args)
