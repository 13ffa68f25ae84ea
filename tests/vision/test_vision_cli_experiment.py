"""``skinkit vision calibrate | profile | track-3d`` over a real experiment file."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit.schemas import ImageSequence
from skinkit.store import create_experiment, open_experiment
from tests.core._cli import in_process

# one xdist worker runs these: it builds the rendered scenes of tests/vision/conftest.py once
pytestmark = [pytest.mark.needs_plugins, pytest.mark.xdist_group("vision_scenes")]


def _run(*args: str):
    """``skinkit vision ARGS`` run in this process (twelve calls: no interpreter start-up each)."""
    return in_process("vision", *args)


def test_calibrate_profile_track(tmp_path, true_rig, board_set, arm_scene):
    _, boards_img = board_set
    path = tmp_path / "session.h5"
    with create_experiment(path) as exp:
        exp.write_images(ImageSequence("calib", boards_img, true_rig.names, np.arange(len(boards_img)) * 1.0))
        exp.write_images(arm_scene["images"])

    r = _run("calibrate", str(path), "--images", "calib", "--board", "7x7", "--square-mm", "3")
    assert r.exit_code == 2 and "symmetric" in r.stderr, r.stderr
    r = _run("profile", str(path), "--images", "indent")
    assert r.exit_code == 2 and "error:" in r.stderr and "Traceback" not in r.stderr

    r = _run("calibrate", str(path), "--images", "calib", "--board", "9x6", "--square-mm", "3")
    assert r.exit_code == 0, r.stderr
    assert "overall reprojection RMS" in r.stdout
    r = _run("profile", str(path), "--images", "indent", "--spacing", "24", "--plot",
             str(tmp_path / "profile.png"))
    assert r.exit_code == 0, r.stderr
    assert "mean ISU" in r.stdout
    assert (tmp_path / "profile.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    r = _run("track-3d", str(path), "--images", "indent", "--tracker", "pcc")
    assert r.exit_code == 0, r.stderr
    # a stored track is not replaced silently: refused in one line before any tracking, the
    # file byte for byte as it was; --overwrite replaces it
    stored = path.read_bytes()
    r = _run("track-3d", str(path), "--images", "indent", "--tracker", "pcc")
    assert r.exit_code == 2 and r.stderr.strip().splitlines() == [
        f"error: {path} already holds a track named 'indent'; give another --name, or --overwrite to "
        "replace it"], r.stderr
    assert path.read_bytes() == stored
    r = _run("track-3d", str(path), "--images", "indent", "--tracker", "pcc", "--overwrite")
    assert r.exit_code == 0, r.stderr
    # nor a stored profile or rig: both refused before any work, the file as it was
    stored = path.read_bytes()
    r = _run("profile", str(path), "--images", "indent", "--spacing", "24")
    assert r.exit_code == 2 and "already holds a profile named 'profile'" in r.stderr, r.stderr
    r = _run("profile", str(path), "--images", "indent", "--name", "again",
             "--plot", str(tmp_path / "profile.png"))
    assert r.exit_code == 2 and "--plot" in r.stderr and "already exists" in r.stderr, r.stderr
    r = _run("calibrate", str(path), "--images", "calib", "--board", "9x6", "--square-mm", "3")
    assert r.exit_code == 2 and "already holds a rig" in r.stderr and "--overwrite" in r.stderr, r.stderr
    assert path.read_bytes() == stored

    with open_experiment(path) as exp:
        rig = exp.read_rig()
        profile = exp.read_profile("profile")
        track = exp.read_track("indent")
        assert exp.track_names() == ["indent"]
    assert rig.names == true_rig.names
    assert profile.n_points >= 100
    assert track.n_frames == 2 and track.valid[:, 1].mean() > 0.7
    # The skin moves by less than its 0.6 mm dimple plus the 1 % stretch of 25 mm.
    moved = np.linalg.norm(track.displacements()[track.valid[:, 1], 1], axis=1)
    assert moved.max() < 0.0006 + 0.00025 + 50e-6
