"""The Python guide's example (docs/guide/python.md) runs as written: its code block, unchanged,
in a fresh process and an empty folder, as a reader would paste it."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "guide" / "python.md"
#: the most lines the example may have
MAX_EXAMPLE_LINES = 20


def example() -> str:
    """The guide's one ``python`` code block."""
    blocks = re.findall(r"^```python\n(.*?)^```", GUIDE.read_text(encoding="utf-8"), flags=re.S | re.M)
    assert len(blocks) == 1, f"{GUIDE.name} should have exactly one python block, has {len(blocks)}"
    return blocks[0]


def test_the_example_is_short_and_the_page_is_linked():
    assert len(example().splitlines()) <= MAX_EXAMPLE_LINES
    assert "(python.md)" in (ROOT / "docs" / "guide" / "README.md").read_text(encoding="utf-8")


@pytest.mark.needs_plugins
def test_the_example_runs_as_written(tmp_path):
    pytest.importorskip("pandas")     # the example prints tables (skinkit[table])
    script = tmp_path / "example.py"
    script.write_text(example(), encoding="utf-8")
    env = {**os.environ, "MPLBACKEND": "Agg", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    run = subprocess.run([sys.executable, script.name], cwd=tmp_path, capture_output=True, text=True,
                         env=env, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    out, err = run.stdout, run.stderr
    assert out.startswith("FitResult extension-relaxation-lumped: converged")
    assert "named: viscoelastic" in out and "chi2_per_dof_after" in out
    # progress by default, on standard error only
    assert "skinkit: fitting" in err and "skinkit: diagnosis done: viscoelastic named" in err
    assert (tmp_path / "session.h5").is_file() and (tmp_path / "truth.json").is_file()
