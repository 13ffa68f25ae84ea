"""An installed skinkit runs outside the checkout: the wheel is built, installed with the built-in
plugins into a fresh virtual environment, and run from an empty folder on a model file it
ships (package data, found through :mod:`skinkit.examples`), with no path into the source tree.

uv (which ``make`` installs into the project's environment) builds and installs; with its cache
warm from the project's own set-up, the fresh environment takes seconds. Without uv the test
is skipped with the reason."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.slow, pytest.mark.needs_plugins]


def _uv() -> str | None:
    here = Path(sys.executable).parent / "uv"
    return str(here) if here.is_file() else shutil.which("uv")


def _run(args: list[str], cwd: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run(args, cwd=cwd, capture_output=True, text=True, env=env, timeout=900)
    assert proc.returncode == 0, f"{' '.join(args)} failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    return proc


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The ``bin`` folder of a fresh environment holding the built wheel and the plugins."""
    uv = _uv()
    if uv is None:
        pytest.skip("uv is not installed (make venv installs it)")
    base = tmp_path_factory.mktemp("wheel")
    # build from a copy of the tracked sources: nothing of the working tree's caches leaks in
    src = base / "src"
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, text=True).stdout
    for rel in filter(None, files.split("\0")):
        p = ROOT / rel
        if p.is_file() and not p.is_symlink():
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(p, src / rel)
    _run([uv, "build", "--wheel", "--out-dir", str(base / "dist"), str(src)], base)
    wheel = next((base / "dist").glob("skinkit-*.whl"))
    _run([uv, "venv", "--quiet", "--python", sys.executable, str(base / "venv")], base)
    py = base / "venv" / "bin" / "python"
    _run([uv, "pip", "install", "--quiet", "--python", str(py), str(wheel), str(src / "plugins")], base)
    return py.parent


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MPLBACKEND="Agg")
    return env


def test_the_wheel_ships_every_example_model(installed: Path, tmp_path: Path):
    out = _run([str(installed / "python"), "-c",
                "import json, skinkit, skinkit.examples as e; "
                "print(json.dumps([skinkit.__file__, e.example_models()]))"], tmp_path, _env())
    where, names = json.loads(out.stdout)
    assert not Path(where).is_relative_to(ROOT), f"skinkit imported from the checkout: {where}"
    shipped = sorted(p.stem for p in (ROOT / "skinkit" / "data" / "models").glob("*.toml"))
    assert names == shipped


def test_an_installed_skinkit_predicts_with_a_shipped_model_from_an_empty_folder(installed: Path,
                                                                                  tmp_path: Path):
    # a ramp-and-hold extension record in the CSV form a lab exports (units in the header)
    rows = ["time_s,displacement_mm,force_N"]
    for i in range(600):
        t = i / 100
        x = min(t, 2.0) * 2.0                                   # 4 mm at 2 mm/s, then held
        f = 0.05 * x * (1 + 0.3 * math.exp(-max(t - 2.0, 0.0) / 1.5))
        rows.append(f"{t:.2f},{x:.4f},{f:.5f}")
    (tmp_path / "record.csv").write_text("\n".join(rows) + "\n")
    model = _run([str(installed / "python"), "-c", "from skinkit.examples import example_model; "
                  "print(example_model('extension_relaxation_lumped'))"], tmp_path, _env()).stdout.strip()
    assert not Path(model).is_relative_to(ROOT)
    out = _run([str(installed / "skinkit"), "predict", model, "record.csv", "--json"], tmp_path, _env())
    res = json.loads(out.stdout)
    assert res, "predict printed an empty answer"
