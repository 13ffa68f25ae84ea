"""docs/ stays true to the code."""

from __future__ import annotations

from pathlib import Path

import pytest

from skinkit.cli.docgen import render

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.needs_plugins
@pytest.mark.needs_hardware
def test_cli_reference_is_current():
    """In a full environment (every command installed) the generated reference matches."""
    doc = ROOT / "docs" / "cli.md"
    if render() != doc.read_text():
        pytest.fail("docs/cli.md is out of date: run `python -m skinkit.cli.docgen > docs/cli.md`")


def test_readme_commands_exist_in_makefile():
    readme = (ROOT / "README.md").read_text()
    make = (ROOT / "Makefile").read_text()
    for target in ("demo", "test", "venv"):
        assert f"make {target}" in readme or target == "venv"
        assert f"\n{target}:" in make
