"""The README's Python tour runs as written."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared"


@pytest.mark.needs_plugins
@pytest.mark.skipif(not (SHARED / "data" / "real").exists(), reason="shared data not beside the checkout")
def test_readme_tour(tmp_path, monkeypatch):
    code = re.search(r"## A tour of the Python API\s+```python\n(.*?)```", (ROOT / "README.md").read_text(),
                     re.S).group(1)
    # The tour is written to run from the checkout, where ../shared is the shared folder.
    code = code.replace("../shared/", f"{SHARED}{os.sep}")
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {})
    assert (tmp_path / "session.h5").exists()
