"""The README's Python tour runs as written and does what its comments say."""

from __future__ import annotations

import ast
import os
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared"


@pytest.mark.needs_plugins
@pytest.mark.skipif(not (SHARED / "data" / "real").exists(), reason="shared data not beside the checkout")
def test_readme_tour(tmp_path, monkeypatch, capsys):
    code = re.search(r"## A tour of the Python API\s+```python\n(.*?)```", (ROOT / "README.md").read_text(),
                     re.S).group(1)
    # The tour is written to run from the checkout, where ../shared is the shared folder.
    code = code.replace("../shared/", f"{SHARED}{os.sep}")
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    exec(compile(code, "README.md", "exec"), ns)
    printed = capsys.readouterr().out.splitlines()

    # what it printed: the one record of session.h5 ...
    (info,) = ast.literal_eval(printed[0])
    rec = ns["rec"]
    assert info["protocol"] == "normal_indentation" and info["samples"] == rec.n_samples == 1000
    assert info["complete"] is True
    # the rate given to the writer, and the span of 1000 samples at 2 kHz, exactly
    assert info["rate_hz"] == 2000.0
    assert info["duration_s"] == pytest.approx(999 / 2000.0, rel=1e-12)
    # ... and the optimisers found by entry point, the one it creates among them
    assert "scipy-lsq" in ast.literal_eval(printed[1])

    # appended block by block, read back bit for bit; the millimetres were stored as metres
    back = ns["back"]
    assert np.array_equal(back.time_s, rec.time_s)
    assert np.array_equal(back.tip_force, rec.tip_force)
    assert np.array_equal(back.tip_position, rec.tip_position)
    assert back.protocol.parameters == {"amplitude": 7.5e-4}
    assert (tmp_path / "session.h5").exists()

    # the real CSV (shared/data/real/README.md): 100 Hz, 0 to 347.39 s, ramps to 9.45 mm
    # read in metres, a rest offset of -0.077 N in its first row (values copied unchanged)
    ext = ns["ext"]
    assert ext.n_samples == 34740
    assert np.allclose(np.diff(ext.time_s), 0.01, atol=1e-9)
    assert ext.time_s[-1] == pytest.approx(347.39, abs=1e-9)
    # the README rounds the ramp to 9.45 mm; the file's largest sample is 9.46 mm
    assert np.nanmax(ext.tip_position[:, 0]) == pytest.approx(9.45e-3, abs=0.02e-3)
    assert ext.tip_force[0, 0] == -0.077

    # a parameter given in kPa is SI inside
    assert ns["params"]["skin.mu"] == pytest.approx(1e4, rel=1e-12)
    assert ns["opt"].name == "scipy-lsq"
