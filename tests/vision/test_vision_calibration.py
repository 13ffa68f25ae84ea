"""Joint calibration of the rendered four-camera ring rig."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit.vision import VisionError
from skinkit.vision import camera as C
from skinkit.vision.boards import check_board, detect_board
from skinkit.vision.calibration import calibrate, detect_all
from skinkit.vision.triangulation import triangulate

# one xdist worker runs these: it builds the rendered scenes of tests/vision/conftest.py once
pytestmark = pytest.mark.xdist_group("vision_scenes")


def _in_board0(poses, X):
    """World points expressed in the frame of the first (flat) board: the calibrated world."""
    return (X - poses[0].t) @ poses[0].R


def test_corner_detection_matches_truth(true_rig, board_set, board):
    poses, images = board_set
    det = detect_all(images, board.inner)
    errs = [det.corners[f, c] - C.project(cam, poses[f].corners_world())
            for f in range(len(poses)) for c, cam in enumerate(true_rig.cameras) if det.found[f, c]]
    e = np.concatenate(errs)
    print("corner error rms", np.sqrt(np.mean(e**2)), "max", np.abs(e).max())
    # Detected order equals the board's (no flips): a flipped order would be off by squares.
    assert np.abs(e).max() < 1.0
    assert det.found.sum(axis=0).min() >= 10


def test_four_camera_calibration(true_rig, board_set, board):
    poses, images = board_set
    cal = calibrate(images, board.inner, board.square_m, camera_names=true_rig.names)
    print("rms", cal.rms_px, "per camera", cal.per_camera_rms_px)
    # The thesis's calibration reached about 0.2 px; with 1 % noise our corners are better.
    assert cal.rms_px <= 0.2
    assert np.all(cal.per_camera_rms_px <= 0.2)
    for true, est in zip(true_rig.cameras, cal.rig.cameras, strict=True):
        R_true = true.R @ poses[0].R
        c_true = _in_board0(poses, true.centre[None])[0]
        dist = np.linalg.norm(c_true)
        angle = np.degrees(np.arccos(np.clip((np.trace(R_true.T @ est.R) - 1) / 2, -1, 1)))
        print(true.name, "f", est.K[0, 0], "centre err um", 1e6 * np.linalg.norm(est.centre - c_true),
              "rot err deg", angle)
        # Tolerances: a relative focal error e moves the image edge (240 px from the centre)
        # by 240 e px; it must stay within the 0.2 px error budget -> e < 1e-3... doubled for the
        # trade-off of focal length against distance along the line of sight, which the field
        # points (all near one depth) barely separate. The same factor bounds the camera
        # distance error (109 mm * 2e-3 = 220 um, allowed 2x for the 40 deg tilts' spread).
        assert abs(est.K[0, 0] / true.K[0, 0] - 1) < 2e-3
        assert np.linalg.norm(est.centre - c_true) < 2 * 2e-3 * dist
        # A narrow (25 deg) field pins the principal point to a few px only, and a shift of
        # the principal point by d px trades against a camera rotation of d / f rad. So the
        # principal point must lie within 8 px (3 % of the half-width) and the rotation error
        # within that trade-off plus 0.05 deg (f * 0.05 deg ~ 1 px, the reprojection budget of
        # the 5x RMS corner error).
        dpp = np.linalg.norm(est.K[:2, 2] - true.K[:2, 2])
        assert dpp < 8
        assert angle < np.degrees(dpp / est.K[0, 0]) + 0.05
    # What matters for tracking: points of the 40 mm field triangulated with the calibrated
    # rig from their true projections land within the thesis's 20 um.
    g = np.mgrid[-0.02:0.0201:0.002, -0.02:0.0201:0.002].reshape(2, -1).T
    X = np.column_stack([g, 0.002 * np.sin(100 * g[:, 0])])
    px = np.stack([C.project(cam, X) for cam in true_rig.cameras], axis=1)
    tri = triangulate(cal.rig, px)
    e = np.linalg.norm(tri.points - _in_board0(poses, X), axis=1)
    print("field 3D error rms um", 1e6 * np.sqrt(np.mean(e**2)), "max", 1e6 * e.max())
    assert np.sqrt(np.mean(e**2)) < 20e-6


def test_symmetric_board_is_refused():
    with pytest.raises(VisionError, match="symmetric"):
        check_board((8, 6))
    with pytest.raises(VisionError, match="symmetric"):
        detect_board(np.zeros((50, 50), np.uint8), (7, 7))


def test_too_few_detections(board_set, true_rig, board):
    _, images = board_set
    blank = images[:6].copy()
    blank[:, 2] = 0  # camera 2 sees nothing
    with pytest.raises(VisionError, match=r"too few board detections: cam2 \(0\)"):
        calibrate(blank, board.inner, board.square_m, camera_names=true_rig.names, min_views=3)
    with pytest.raises(VisionError, match="expected \\(frames, cameras, H, W\\)"):
        calibrate(images[0], board.inner, board.square_m)
    # the name count is refused whatever the views hold: one frame is enough to detect
    with pytest.raises(VisionError, match="camera names"):
        calibrate(images[:1], board.inner, board.square_m, camera_names=["a", "b"])


def test_charuco_calibration_with_partial_views(true_rig):
    """ChArUco: marker ids fix the corner order and partly visible boards still count."""
    from skinkit.vision import boards
    from skinkit.vision.calibration import calibrate_charuco
    from skinkit.vision.scene import CharucoTarget
    from skinkit.vision.sensor import Sensor

    target = CharucoTarget(squares=(9, 7), square_m=0.004, marker_m=0.003)
    poses = boards.random_board_poses(10, np.random.default_rng(3), target, tilt_deg=40,
                                      lift_m=(-0.01, 0.01))
    images = boards.board_views(true_rig, poses, Sensor(noise=0.01, falloff=0.2), seed=2)
    cal = calibrate_charuco(images, target, camera_names=true_rig.names, min_views=4)
    partial = cal.detections.found & ~np.all(np.isfinite(cal.detections.corners[..., 0]), axis=2)
    print("charuco rms", cal.rms_px, cal.per_camera_rms_px, "partial views", partial.sum())
    assert partial.any()  # the test does exercise partial views
    assert cal.rms_px <= 0.2 and np.all(cal.per_camera_rms_px <= 0.2)
    # World: the first board, printed face up; z points to the cameras either way.
    assert all(cam.centre[2] > 0 for cam in cal.rig.cameras)
    g = np.mgrid[-0.02:0.0201:0.002, -0.02:0.0201:0.002].reshape(2, -1).T
    X = np.column_stack([g, 0.002 * np.sin(100 * g[:, 0])])
    px = np.stack([C.project(cam, X) for cam in true_rig.cameras], axis=1)
    flip = np.diag([1.0, -1.0, -1.0])  # ChArUco z is into the board; the world's is out
    truth = ((X - poses[0].t) @ poses[0].R) @ flip
    e = np.linalg.norm(triangulate(cal.rig, px).points - truth, axis=1)
    print("charuco field 3D error rms um", 1e6 * np.sqrt(np.mean(e**2)))
    assert np.sqrt(np.mean(e**2)) < 20e-6
