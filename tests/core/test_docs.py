"""docs/ stays true to the code."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _generated(*args: str) -> str:
    """A page as ``python -m skinkit.cli.docgen ARGS`` writes it, in a fresh process exactly as the
    page says to generate it: other tests in this worker may have changed the environment
    (terminal width, working directory) that help reads."""
    import os
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "skinkit.cli.docgen", *args], capture_output=True,
                          text=True, cwd=ROOT, env={k: v for k, v in os.environ.items() if k != "COLUMNS"},
                          check=True).stdout


def _check_current(page: str, out: str, command: str) -> None:
    import difflib

    doc = ROOT / page
    if not doc.is_file() or out != doc.read_text(encoding="utf-8"):
        old = doc.read_text(encoding="utf-8") if doc.is_file() else ""
        diff = "".join(list(difflib.unified_diff(old.splitlines(True), out.splitlines(True)))[:30])
        pytest.fail(f"{page} is out of date: run `{command} > {page}`\n" + diff)


@pytest.mark.needs_plugins
@pytest.mark.needs_hardware
def test_cli_reference_is_current():
    """In a full environment (every command installed) the generated reference matches."""
    from skinkit.cli.docgen import CLI_PAGE

    _check_current(CLI_PAGE, _generated(), "python -m skinkit.cli.docgen")


@pytest.mark.needs_plugins
@pytest.mark.needs_hardware
def test_effects_reference_is_current():
    """In a full environment (every effect plugin installed) the generated table matches."""
    from skinkit.cli.docgen import EFFECTS_PAGE

    _check_current(EFFECTS_PAGE, _generated("effects"), "python -m skinkit.cli.docgen effects")


def test_the_effects_table_has_a_row_per_installed_effect():
    from skinkit import registry
    from skinkit.cli.docgen import effect_rows, render_effects

    rows = effect_rows()
    assert [r[0].strip("`") for r in rows] == registry.names("skinkit.effects")
    page = render_effects()
    assert page.count("\n| `") == len(rows)
    for r in rows:
        if r[1]:   # a loaded effect: its kinds and a summary sentence
            assert set(r[1].split(", ")) <= {"fe", "lumped"} and r[3].endswith("."), r


def test_docgen_refuses_an_unknown_page():
    from skinkit.cli.docgen import main

    with pytest.raises(SystemExit, match="usage"):
        main(["nope"])


def test_readme_commands_exist_in_makefile():
    """The README's two set-up commands are there, and every ``make X`` it names is a target;
    ``demo`` and ``test`` set up the environment they run in (the README says they build .venv)."""
    import re

    readme = (ROOT / "README.md").read_text()
    make = (ROOT / "Makefile").read_text()
    targets = {m.group(1): m.group(2).split() for m in re.finditer(r"^([\w-]+):(?!=)(.*)$", make, re.M)}
    named = set(re.findall(r"\bmake ([a-z][\w-]*)", readme))
    assert {"demo", "test"} <= named
    missing = sorted(named - set(targets))
    assert not missing, f"README names make target(s) the Makefile lacks: {missing}"
    assert "venv" in targets["demo"] and "venv-test" in targets["test"]
