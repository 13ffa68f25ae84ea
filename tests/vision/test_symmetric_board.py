"""A 12 x 8 inner-corner checkerboard (symmetric under a half turn) calibrates the four-camera
ring rig: rendered views written as 16-bit TIFF files, imported and calibrated from the CLI."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from skinkit.store import open_experiment
from skinkit.vision import VisionError, boards
from skinkit.vision import camera as C
from skinkit.vision.board_symmetry import resolve_half_turns
from skinkit.vision.calibration import detect_all
from skinkit.vision.scene import Board
from skinkit.vision.sensor import Sensor
from tests.core._cli import in_process

# both tests read the rendered views: one xdist worker runs them, rendering the views once
pytestmark = pytest.mark.xdist_group("symmetric_board_views")

INNER = (12, 8)
SQUARE_M = 0.002  # 26 x 18 mm of squares: the whole board stays in the 40 mm field when tilted


@pytest.fixture(scope="module")
def sym_views(true_rig):
    """14 placements of the 12 x 8 board (first flat), 16-bit renders by every camera."""
    poses = boards.random_board_poses(14, np.random.default_rng(5), Board(INNER, SQUARE_M), tilt_deg=35,
                                      lift_m=(-0.01, 0.01))
    images = boards.board_views(true_rig, poses, Sensor(noise=0.01, falloff=0.2, bits=16), seed=1)
    return poses, images


def _labelling(corners, found, rig, poses):
    """(F, C): 1 where a view's corners are in board order, -1 reversed (half turn), 0 not found."""
    out = np.zeros(found.shape, int)
    for f, c in zip(*np.nonzero(found), strict=True):
        truth = C.project(rig.cameras[c], poses[f].corners_world())
        if np.abs(corners[f, c] - truth).max() < 1.0:
            out[f, c] = 1
        elif np.abs(corners[f, c][::-1] - truth).max() < 1.0:
            out[f, c] = -1
        else:
            raise AssertionError(f"view {f}, {c}: corners match neither order")
    return out


def test_half_turns_resolved_per_frame(true_rig, sym_views):
    """The detector's labelling differs between the cameras of a frame (opposite cameras of the
    ring see the board turned by half a turn); after resolution every frame is labelled alike."""
    poses, images = sym_views
    det = detect_all(images, INNER, true_rig.names, symmetric_ok=True)
    raw = _labelling(det.corners, det.found, true_rig, poses)
    mixed = [f for f in range(len(poses)) if len(set(raw[f][raw[f] != 0])) > 1]
    assert mixed, "the test must exercise frames labelled differently by different cameras"
    corners, found = resolve_half_turns(det.corners, det.found, INNER, SQUARE_M, det.image_size,
                                        true_rig.names)
    fixed = _labelling(corners, found, true_rig, poses)
    assert found.sum() == det.found.sum()  # no view dropped on clean renders
    for f in range(len(poses)):
        assert len(set(fixed[f][fixed[f] != 0])) == 1, f"frame {f} still mixed: {fixed[f]}"

    # A camera that shares a single view with the others cannot be resolved: one clear error.
    few = det.found.copy()
    both = np.flatnonzero(few[:, 3] & few[:, :3].any(axis=1))
    few[both[1:], 3] = False
    few[np.flatnonzero(~few[:, :3].any(axis=1)), 3] = True  # cam3 keeps views of its own
    with pytest.raises(VisionError, match="cam3 shares 1 view"):
        resolve_half_turns(det.corners, few, INNER, SQUARE_M, det.image_size, true_rig.names)


def _angle_deg(Ra, Rb):
    return float(np.degrees(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1, 1))))


@pytest.mark.needs_plugins
def test_symmetric_board_from_files_through_cli(tmp_path, true_rig, sym_views):
    """Files on disk -> ``skinkit import-images`` -> ``skinkit vision calibrate --board 12x8``.

    Tolerances (as for the 9 x 6 board in test_vision_calibration, same rig, sensor and noise):
    the rendered corners are found to about 0.1 px, so the reprojection RMS must stay within
    0.2 px. A relative focal error e moves the image edge (240 px from the centre) by 240 e px;
    keeping that inside the 0.2 px budget gives e < 1e-3, doubled because focal length trades
    against distance along the line of sight (all corners lie near one depth): |e| < 2e-3.
    The narrow (25 deg) field pins the principal point only to a few px: within 8 px.
    Relative pose of camera c to camera 0: each camera's rotation may err by its principal-point
    shift d / f plus 0.05 deg (f * 0.05 deg ~ 1 px, 5x the corner error), so the relative
    rotation within the sum of both; each camera centre may err by 2 e_f * distance (the
    focal/distance trade-off, 109 mm * 4e-3), so the baseline within twice that plus the
    baseline turned by the rotation tolerance.
    """
    poses, images = sym_views
    F, Cn = images.shape[:2]
    for c, name in enumerate(true_rig.names):
        (tmp_path / name).mkdir()
        for f in range(F):
            # as a camera's software writes them: one 16-bit TIFF per frame, numbered
            assert cv2.imwrite(str(tmp_path / name / f"{name}_board_{f + 1:04d}.tif"), images[f, c])
    session = tmp_path / "session.h5"
    cams = [a for name in true_rig.names for a in ("--camera", name, str(tmp_path / name / "*.tif"))]
    r = in_process("import-images", str(session), *cams, "--name", "calibration")
    assert r.exit_code == 0, r.stderr
    assert f"imported {F} frames x {Cn} cameras" in r.stdout and "uint16" in r.stdout
    r = in_process("vision", "calibrate", str(session), "--images", "calibration", "--board", "12x8",
                 "--square-mm", str(SQUARE_M * 1e3))
    assert r.exit_code == 0, r.stderr
    print(r.stdout)
    with open_experiment(session) as exp:
        rig = exp.read_rig()
        assert np.array_equal(exp.read_images("calibration").frames, images)
    assert rig.names == true_rig.names
    t0, e0 = true_rig.cameras[0], rig.cameras[0]
    dist = np.linalg.norm(t0.centre)
    tol_rot = {}
    for true, est in zip(true_rig.cameras, rig.cameras, strict=True):
        e_f = est.K[0, 0] / true.K[0, 0] - 1
        dpp = float(np.linalg.norm(est.K[:2, 2] - true.K[:2, 2]))
        print(true.name, "focal rel err", e_f, "principal point err px", dpp)
        assert abs(e_f) < 2e-3 and abs(est.K[1, 1] / true.K[1, 1] - 1) < 2e-3
        assert dpp < 8
        tol_rot[true.name] = np.degrees(dpp / est.K[0, 0]) + 0.05
    for true, est in zip(true_rig.cameras[1:], rig.cameras[1:], strict=True):
        R_true, R_est = true.R @ t0.R.T, est.R @ e0.R.T          # camera 0 -> camera c
        b_true = t0.R @ (true.centre - t0.centre)                 # baseline in camera 0's frame [m]
        b_est = e0.R @ (est.centre - e0.centre)
        rot = _angle_deg(R_true, R_est)
        tol = tol_rot[true.name] + tol_rot[t0.name]
        print(true.name, "relative rotation err deg", rot, "tol", tol,
              "baseline err um", 1e6 * np.linalg.norm(b_est - b_true))
        assert rot < tol
        assert np.linalg.norm(b_est - b_true) < 2 * 2 * 2e-3 * dist + np.linalg.norm(b_true) * np.radians(tol)
