"""A throw-away effect distribution written from the plugin guide alone
(docs/guide/writing-plugins.md): built with pip from its pyproject.toml into a fresh
environment that sees this one's packages, then, in fresh processes, listed by ``skinkit
plugins``, passing the effects conformance kit (the package's own tests, as the guide writes
them) and scored by ``skinkit gap diagnose`` — touching no file of skinkit."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from ..core.thirdparty import make_env

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "guide" / "writing-plugins.md"
PACKAGE = "skinkit-extra-effects"
RECORD = ROOT.parent / "shared" / "data" / "real" / "healthy_skin_extension_relaxation.csv"

# one worker builds the throw-away environment (a module fixture) and runs every test on it
pytestmark = [pytest.mark.slow, pytest.mark.needs_plugins, pytest.mark.xdist_group("guide_effects")]


def _write_package(root: Path) -> Path:
    """The guide's ``file=<PACKAGE>/...`` blocks written under ``root``; the package's folder."""
    blocks = re.findall(r"```\w+ file=(\S+)\n(.*?)```", GUIDE.read_text(encoding="utf-8"), flags=re.S)
    files = {path: text for path, text in blocks if path.startswith(f"{PACKAGE}/")}
    assert {f"{PACKAGE}/pyproject.toml", f"{PACKAGE}/tests/test_extra_effects.py"} <= set(files)
    for path, text in files.items():
        (root / path).parent.mkdir(parents=True, exist_ok=True)
        (root / path).write_text(text, encoding="utf-8")
    return root / PACKAGE


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """A fresh environment holding the guide's package (a throw-away environment rather than
    this one, so that no other test running meanwhile sees the extra effects)."""
    root = tmp_path_factory.mktemp("guide-effects")
    package = _write_package(root)
    python = make_env(root / "venv")
    _install(python, package)
    return python, package


def _install(python: Path, package: Path) -> None:
    """``pip install ./<package>`` as the guide says, with what this machine has: uv from its
    cache (the build backend the pyproject asks for included), then uv from the index, then
    pip building with this environment's setuptools."""
    uv = shutil.which("uv", path=str(Path(sys.executable).parent)) or shutil.which("uv")
    tries = [[uv, "pip", "install", "--offline", "--python", str(python), "--no-deps", str(package)],
             [uv, "pip", "install", "--python", str(python), "--no-deps", str(package)]] if uv else []
    tries.append([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
                  "--no-build-isolation", "--no-index", "--disable-pip-version-check", str(package)])
    errors = []
    for cmd in tries:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        if proc.returncode == 0:
            return
        errors.append(f"{' '.join(cmd[:4])}: {proc.stderr.strip()[-400:]}")
    pytest.fail("cannot build the guide's package:\n" + "\n".join(errors))


def _run(python: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(python), *args], capture_output=True, text=True, cwd=cwd,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})


def test_skinkit_plugins_lists_the_new_effects(env):
    python, package = env
    proc = _run(python, "-m", "skinkit", "plugins", "--json", "--check", "--group", "skinkit.effects",
                cwd=package.parent)
    assert proc.returncode == 0, proc.stderr
    listed = {e["name"]: e for e in json.loads(proc.stdout)["groups"]["skinkit.effects"]}
    for name in ("sensor-zero", "skin-ageing"):
        assert listed[name]["dist"] == PACKAGE and listed[name]["status"] == "ok", listed[name]


def test_the_new_effects_pass_the_conformance_kit(env):
    python, package = env
    proc = _run(python, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:dash", "tests",
                cwd=package)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 passed" in proc.stdout


@pytest.mark.skipif(not RECORD.is_file(), reason=f"needs the real record {RECORD}")
def test_gap_diagnose_scores_the_new_effect(env):
    python, package = env
    model = ROOT / "skinkit" / "data" / "models" / "extension_relaxation_lumped.toml"
    # score every installed effect that applies (the new one found like the built-in ones),
    # name none: the score tests are what this is about
    proc = _run(python, "-m", "skinkit", "gap", "diagnose", str(model), str(RECORD), "--json",
                "--max-effects", "0", cwd=package.parent)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert "sensor-zero" in report["effects_tested"]
    scored = {c["effect"]: c for c in report["candidates"]}
    assert "sensor-zero" in scored, sorted(scored)
    assert "skin-ageing" not in report["effects_tested"]  # finite-element models only
