"""Build throw-away third-party plugin distributions as real wheels, and a temporary
environment to install them into with pip."""

from __future__ import annotations

import base64
import hashlib
import subprocess
import sys
import sysconfig
import textwrap
import venv
import zipfile
from pathlib import Path


def build_wheel(out_dir: Path, dist: str, modules: dict[str, str], entry_points: dict[str, dict[str, str]],
                version: str = "0.0.1") -> Path:
    """Write a pure-Python wheel holding ``modules`` (path -> source) and ``entry_points``
    (group -> name -> target) and return its path."""
    norm = dist.replace("-", "_")
    info = f"{norm}-{version}.dist-info"
    files: dict[str, bytes] = {path: textwrap.dedent(src).encode() for path, src in modules.items()}
    files[f"{info}/METADATA"] = f"Metadata-Version: 2.1\nName: {dist}\nVersion: {version}\n".encode()
    files[f"{info}/WHEEL"] = (b"Wheel-Version: 1.0\nGenerator: skinkit-tests\nRoot-Is-Purelib: true\n"
                              b"Tag: py3-none-any\n")
    ep = "".join(f"[{g}]\n" + "".join(f"{n} = {t}\n" for n, t in eps.items()) + "\n"
                 for g, eps in entry_points.items())
    files[f"{info}/entry_points.txt"] = ep.encode()
    record_lines = []
    for path, content in files.items():
        digest = base64.urlsafe_b64encode(hashlib.sha256(content).digest()).rstrip(b"=").decode()
        record_lines.append(f"{path},sha256={digest},{len(content)}")
    record_lines.append(f"{info}/RECORD,,")
    files[f"{info}/RECORD"] = ("\n".join(record_lines) + "\n").encode()
    wheel = out_dir / f"{norm}-{version}-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as zf:
        for path, content in files.items():
            zf.writestr(path, content)
    return wheel


def make_env(root: Path) -> Path:
    """A new virtual environment at ``root`` that also sees this interpreter's packages
    (so skinkit and its dependencies import); returns its python executable."""
    venv.EnvBuilder(with_pip=False, symlinks=True).create(root)
    python = root / "bin" / "python"
    purelib = subprocess.check_output(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], text=True).strip()
    # addsitedir (not a bare path) so the parent's .pth files, editable installs among them, apply.
    parent = sysconfig.get_paths()["purelib"]
    Path(purelib, "zz_parent_env.pth").write_text(f"import site; site.addsitedir({parent!r})\n")
    return python


def pip_install(python: Path, wheel: Path) -> None:
    """Install ``wheel`` into the environment of ``python`` with this interpreter's pip."""
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet",
                    "--no-deps", "--no-index", "--disable-pip-version-check", str(wheel)], check=True)
