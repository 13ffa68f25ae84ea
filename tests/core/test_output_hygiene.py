"""Outputs go where the user is: commands that write by default write under the current
directory, named after the model, never beside an input inside the repository (docs/models,
the package); nothing replaces a stored result without --overwrite; the README's Python tour
runs twice in a row.

The repository is checked at the specific paths the old defaults wrote to (other work changes
files in the checkout at the same time, so a whole-tree comparison would not be this test's)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from skinkit.cli import cli

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared"
MODEL = ROOT / "docs" / "models" / "phantom_membrane_gel.toml"  # the cheapest FE model file: ~2 s


def _state(paths: list[Path]) -> dict[str, tuple[bool, int]]:
    """Existence and modification time of each path: what a write would change."""
    return {str(p): (p.exists(), p.stat().st_mtime_ns if p.exists() else 0) for p in paths}


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


def _one_line(r) -> str:
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error: "), (r.exit_code, r.output)
    return lines[0]


@pytest.mark.parametrize("command, folder, written", [
    ("solve", "phantom_membrane_gel", ["result.h5", "summary.json"]),
    ("convergence", "phantom_membrane_gel_convergence", ["convergence.json", "convergence.png"]),
])
@pytest.mark.needs_plugins
def test_default_output_is_under_the_current_directory_and_never_replaced_silently(
        tmp_path, monkeypatch, command, folder, written):
    options = ["--no-vtu"] if command == "solve" else ["--levels", "1"]
    # where the old defaults wrote: beside the model file, inside the repository
    repo_paths = [MODEL.with_suffix(""), MODEL.with_name(MODEL.stem + "_convergence"), ROOT / folder]
    before = _state(repo_paths)
    monkeypatch.chdir(tmp_path)

    r = _run(command, str(MODEL), *options)
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in (tmp_path / folder).iterdir()) == written
    assert sorted(p.name for p in tmp_path.iterdir()) == [folder]  # no temporary left
    assert _state(repo_paths) == before

    stamp = _state([tmp_path / folder / name for name in written])
    line = _one_line(_run(command, str(MODEL), *options))  # the same command again
    assert f"--out {tmp_path / folder}: already holds a result" in line and "--overwrite" in line
    assert _state([tmp_path / folder / name for name in written]) == stamp

    r = _run(command, str(MODEL), *options, "--overwrite")
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in (tmp_path / folder).iterdir()) == written
    assert _state(repo_paths) == before


def test_overwrite_never_replaces_a_folder_of_other_files(tmp_path):
    """--out names a folder that a solve replaces as a whole: one holding anything a solve did not
    write is refused, with or without --overwrite, and left as it was."""
    out = tmp_path / "notes"
    out.mkdir()
    (out / "mine.txt").write_text("keep")
    for extra in ([], ["--overwrite"]):
        line = _one_line(_run("solve", str(MODEL), "--no-vtu", "--out", str(out), *extra))
        assert "holds files skinkit solve did not write (mine.txt)" in line
    assert [p.name for p in out.iterdir()] == ["mine.txt"] and (out / "mine.txt").read_text() == "keep"


@pytest.mark.needs_plugins
def test_an_empty_out_folder_is_written(tmp_path):
    out = tmp_path / "empty"
    out.mkdir()
    r = _run("solve", str(MODEL), "--no-vtu", "--out", str(out))
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in out.iterdir()) == ["result.h5", "summary.json"]


@pytest.mark.skipif(not (SHARED / "data" / "real").exists(), reason="shared data not beside the checkout")
def test_predict_out_is_not_replaced_silently(tmp_path):
    """The README's lumped prediction of the real record (~2 s), written with --out twice."""
    csv = SHARED / "data" / "real" / "healthy_skin_extension_relaxation.csv"
    args = ["predict", str(ROOT / "docs" / "models" / "extension_relaxation_lumped.toml"), str(csv),
            "--axis", "x", "--out", str(tmp_path / "p.h5")]
    assert _run(*args).exit_code == 0
    stamp = _state([tmp_path / "p.h5"])
    line = _one_line(_run(*args))
    assert f"--out {tmp_path / 'p.h5'}: already exists" in line and "--overwrite" in line
    assert _state([tmp_path / "p.h5"]) == stamp
    assert _run(*args, "--overwrite").exit_code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.h5"]


@pytest.mark.needs_plugins
@pytest.mark.skipif(not (SHARED / "data" / "real").exists(), reason="shared data not beside the checkout")
def test_readme_tour_runs_twice_and_writes_only_in_the_current_directory(tmp_path, monkeypatch, capsys):
    code = re.search(r"## A tour of the Python API\s+```python\n(.*?)```", (ROOT / "README.md").read_text(),
                     re.S).group(1)
    code = code.replace("../shared/", f"{SHARED}{os.sep}")  # written to run from the checkout
    repo_paths = [ROOT / "session.h5", ROOT / "docs" / "session.h5"]
    before = _state(repo_paths)
    monkeypatch.chdir(tmp_path)
    printed = []
    for _ in (1, 2):
        exec(compile(code, "README.md", "exec"), {})
        printed.append(capsys.readouterr().out)
    assert printed[0] == printed[1]  # the same session, read back the same way
    assert [p.name for p in tmp_path.iterdir()] == ["session.h5"]
    assert _state(repo_paths) == before
