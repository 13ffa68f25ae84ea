"""An experiment file whose writer died while appending in SWMR mode is refused by import-images
as import-tracks refuses it (one line naming the file and what to do), not with an internal error;
the file is left as it was."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from tests.core._cli import one_error

_WRITER = textwrap.dedent("""
    import sys, numpy as np
    from skinkit.schemas import Protocol, RobotRecord
    from skinkit.store import create_experiment
    with create_experiment(sys.argv[1]) as exp:
        with exp.record_writer(Protocol("stream", kind="force"), ["tip_force"], 1000.0) as w:
            i = np.arange(10)
            w.append(RobotRecord(time_s=i / 1000.0, tip_force=np.column_stack([i, -i, 2 * i]) * 1.0))
            print(w.n_samples, flush=True)
            sys.stdin.readline()   # killed here, the file still open for SWMR writing
""")


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


@pytest.fixture
def left_open(tmp_path):
    """An experiment file whose record writer was killed (SIGKILL) while it held it open."""
    path = tmp_path / "crash.h5"
    proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(path)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "10"
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    return path


def test_import_images_refuses_a_file_its_writer_left_open_as_import_tracks_does(left_open, tmp_path):
    (tmp_path / "cam").mkdir()
    for k in range(2):
        assert cv2.imwrite(str(tmp_path / "cam" / f"f{k}.png"), np.full((16, 16), 40 * k, np.uint8))
    (tmp_path / "dic.csv").write_text("frame,point,x_mm,y_mm\n0,1,0,0\n")
    before = left_open.read_bytes()
    images = one_error(_run("import-images", str(left_open), "--camera", "c0", str(tmp_path / "cam")),
                       str(left_open), "was not closed by its writer")
    assert "internal error" not in images
    tracks = one_error(_run("import-tracks", str(left_open), str(tmp_path / "dic.csv")))
    assert images == tracks
    assert left_open.read_bytes() == before
