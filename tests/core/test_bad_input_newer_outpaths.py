"""An output path whose folder takes no file (read-only, or a pseudo-filesystem even root cannot
write in) is refused naming the path the user gave, not the hidden temporary file written beside
it: ``lab session --out / --truth-out`` and ``import-extensometer EXPERIMENT``. Nothing is run."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.examples import example_model
from tests.core._cli import one_error
from tests.core._extensometer import write_record


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


def _takes_no_file(folder: Path) -> bool:
    try:
        fd, probe = tempfile.mkstemp(dir=folder)
    except OSError:
        return True
    os.close(fd)
    os.unlink(probe)
    return False


@pytest.fixture
def unwritable(tmp_path) -> Path:
    """A folder in which no file can be created: a read-only folder, or /sys for root (whom the
    permission bits do not stop)."""
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        for folder in (ro, Path("/sys")):
            if folder.is_dir() and _takes_no_file(folder):
                yield folder
                return
        pytest.skip("no folder here refuses files")
    finally:
        ro.chmod(0o755)


@pytest.mark.needs_plugins
@pytest.mark.parametrize("which", ["--out", "--truth-out"])
def test_lab_session_names_the_out_path_given(unwritable, tmp_path, which):
    paths = {"--out": str(tmp_path / "s.h5"), "--truth-out": str(tmp_path / "t.json")}
    paths[which] = str(unwritable / "x.out")
    line = one_error(_run("lab", "session", str(example_model("extension_relaxation_lumped")),
                          "--seed", "0", *[a for kv in paths.items() for a in kv]),
                     f"{which} {unwritable / 'x.out'}", "cannot create it", f"{unwritable} is not writable")
    assert ".tmp" not in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ro"]


def test_import_extensometer_names_the_experiment_given(unwritable, tmp_path):
    folder = write_record(tmp_path / "rec")
    out = unwritable / "e.h5"
    line = one_error(_run("import-extensometer", str(out), str(folder)), f"{out}: cannot be written in",
                     str(unwritable))
    assert ".tmp" not in line
