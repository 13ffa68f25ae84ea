"""docs/ stays true to the code."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.needs_plugins
@pytest.mark.needs_hardware
def test_cli_reference_is_current():
    """In a full environment (every command installed) the generated reference matches."""
    import difflib
    import os
    import subprocess
    import sys

    doc = ROOT / "docs" / "cli.md"
    # in a fresh process, exactly as the docs say to generate it: other tests in this worker
    # may have changed the environment (terminal width, working directory) that help reads
    out = subprocess.run([sys.executable, "-m", "skinkit.cli.docgen"], capture_output=True, text=True,
                         cwd=ROOT, env={k: v for k, v in os.environ.items() if k != "COLUMNS"},
                         check=True).stdout
    if out != doc.read_text():
        lines = difflib.unified_diff(doc.read_text().splitlines(True), out.splitlines(True))
        diff = "".join(list(lines)[:30])
        pytest.fail("docs/cli.md is out of date: run `python -m skinkit.cli.docgen > docs/cli.md`\n" + diff)


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
