"""The plugin-author guide's worked law example, built from docs/guide/writing-plugins.md,
installed into a fresh environment, and run: the guide cannot drift from what works. (Its
effect example is installed and run by tests/plugin_surface/test_guide_effects.py.)"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from .thirdparty import build_wheel, make_env, pip_install

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guide" / "writing-plugins.md"


def guide_files(package: str) -> dict[str, str]:
    """The guide's ``file=<package>/<path>`` code blocks of one package: path -> text."""
    blocks = re.findall(r"```\w+ file=(\S+)\n(.*?)```", GUIDE.read_text(encoding="utf-8"), flags=re.S)
    prefix = f"{package}/"
    return {path[len(prefix):]: text for path, text in blocks if path.startswith(prefix)}


def test_guide_example_builds_installs_and_passes_its_tests(tmp_path):
    files = guide_files("skinkit-yeoh")
    assert {"pyproject.toml", "skinkit_yeoh/yeoh.py", "tests/test_yeoh.py"} <= set(files)
    meta = tomllib.loads(files["pyproject.toml"])["project"]
    modules = {k: v for k, v in files.items() if k.startswith("skinkit_yeoh/")}
    wheel = build_wheel(tmp_path, meta["name"], modules, meta["entry-points"], meta["version"])
    python = make_env(tmp_path / "venv")
    pip_install(python, wheel)
    test = tmp_path / "tests" / "test_yeoh.py"
    test.parent.mkdir()
    test.write_text(files["tests/test_yeoh.py"])
    proc = subprocess.run([str(python), "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:dash",
                           str(test)], capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = subprocess.run([str(python), "-m", "skinkit", "plugins", "--json", "--group", "skinkit.laws"],
                         capture_output=True, text=True, check=True).stdout
    assert '"name": "yeoh"' in out and '"dist": "skinkit-yeoh"' in out


def test_guide_code_imports_only_the_declared_api():
    """Every file of the guide's packages passes the import-boundary check the built-in
    plugins pass."""
    from .test_import_boundary import check_source

    blocks = re.findall(r"```python file=(\S+)\n(.*?)```", GUIDE.read_text(encoding="utf-8"), flags=re.S)
    assert len(blocks) >= 6
    found = [f for path, text in blocks for f in check_source(text, path)]
    assert not found, found
