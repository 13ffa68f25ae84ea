"""Dot-grid calibration targets (DIC style, with fiducials; OpenCV's plain circle grids) calibrate
the four-camera ring rig: rendered views written as 16-bit TIFF files, imported and calibrated
from the CLI, checked against the rendering's truth."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from skinkit.store import open_experiment
from skinkit.vision import VisionError, boards
from skinkit.vision import camera as C
from skinkit.vision.dotgrid import DotGrid, parse_fiducials, random_grid_poses
from skinkit.vision.dotgrid_detect import calibrate_dotgrid, detect_all_dotgrid, detect_dotgrid
from skinkit.vision.sensor import Sensor
from tests.core._cli import in_process

#: 14 x 10 dots, 1.6 mm pitch (21 x 14 mm: the whole grid stays in the 40 mm field when tilted),
#: 0.8 mm dots, three hollow fiducials in an L at (1, 1), (2, 1), (1, 2). The lattice looks the
#: same after half a turn: only the fiducials tell its ends apart.
GRID = DotGrid(14, 10, 0.0016, 0.0008)
SENSOR = Sensor(noise=0.01, falloff=0.2, bits=16)
SIGMA_BOUND = 0.1  # px: RMS error of the dot centres against the truth (derived below)
#: the tests of the rendered placements share one worker, so the views are rendered and the grid
#: detected in them once
SHARED_VIEWS = pytest.mark.xdist_group("dotgrid_views")


@pytest.fixture(scope="module")
def dot_views(true_rig):
    """14 placements (first flat), tilts up to 35 deg, 16-bit renders by every camera."""
    poses = random_grid_poses(14, np.random.default_rng(5), GRID, tilt_deg=35, lift_m=(-0.01, 0.01))
    return poses, boards.board_views(true_rig, poses, SENSOR, seed=1)


@pytest.fixture(scope="module")
def dot_detections(true_rig, dot_views):
    """The grid detected in every rendered view, once (detection is deterministic): the
    checks of the centres and of what the CLI calibrated from the same views read it."""
    return detect_all_dotgrid(dot_views[1], GRID, true_rig.names)


def _truth(rig, poses, f, c):
    return C.project(rig.cameras[c], poses[f].corners_world())


@SHARED_VIEWS
def test_dots_subpixel_and_oriented_by_fiducials(true_rig, dot_views, dot_detections):
    """Every view where the whole grid is in the image is found, labelled from the true dot
    (0, 0), with centres close to the projected dot centres.

    Bound on the centre error: the renderer samples 2 x 2 rays per pixel, so each pixel on a
    dot's edge is off by up to 1/8 of its ink (sd 1 / (4 sqrt 12) = 0.072); over the ~pi D edge
    pixels of a dot D px across, at lever arm D / 2, the centroid moves by 0.072 sqrt(2 / (pi D))
    per axis: 0.02 px for D = 8 (face on), 0.03 px for D = 4 (steepest views), 0.04 px in 2D.
    The 1 % noise adds ~0.01 px, the perspective shift of a circle's centre 0.01 px (see
    skinkit.vision.dotgrid_detect). RMS within 0.1 px (2x), no dot beyond 0.3 px.
    """
    poses, images = dot_views
    F, Cn = images.shape[:2]
    det = dot_detections
    plain = DotGrid(14, 10, 0.0016, 0.0008, fiducials=())    # the same lattice, fiducials ignored
    errors, half_turned = [], 0
    for f in range(F):
        for c in range(Cn):
            truth = _truth(true_rig, poses, f, c)
            w, h = true_rig.cameras[c].image_size
            whole = np.all((truth > 3) & (truth < [w - 4, h - 4]))
            if whole:
                assert det.found[f, c], f"frame {f}, {true_rig.names[c]}: grid in view but not found"
            if not det.found[f, c]:
                continue
            e = np.linalg.norm(det.corners[f, c] - truth, axis=1)
            assert e.max() < 0.3, f"frame {f}, {true_rig.names[c]}: wrong order or centre ({e.max():.2f} px)"
            errors.append(e)
            if not half_turned:  # one half-turned view proves the point; the rest cost 0.3 s each
                raw, _ = detect_dotgrid(images[f, c], plain)
                half_turned += bool(np.abs(raw[::-1] - truth).max() < 0.3)
    e = np.concatenate(errors)
    rms = float(np.sqrt(np.mean(e**2)))
    print(f"{det.found.sum()} of {F * Cn} views; dot centre error RMS {rms:.3f} px, max {e.max():.3f} px")
    assert det.found.sum() >= 0.8 * F * Cn
    assert rms < SIGMA_BOUND
    # without its fiducials the lattice comes out half-turned in some views: they fixed it
    assert half_turned > 0


@pytest.mark.parametrize("grid", [
    DotGrid(10, 10, 0.0018, 0.0009, fiducial_kind="large", fiducials=((1, 1), (2, 1), (1, 2))),
    DotGrid(4, 11, 0.0012, 0.0009, fiducials=(), asymmetric=True),
], ids=["square-large-fiducials", "opencv-asymmetric-4x11"])
def test_other_layouts_labelled(true_rig, grid):
    """A square grid (four turns look alike) is oriented by its large fiducial dots; OpenCV's
    asymmetric 4 x 11 circle grid needs none. Three placements, every camera."""
    poses = random_grid_poses(3, np.random.default_rng(2), grid, tilt_deg=30, lift_m=(-0.005, 0.005))
    images = boards.board_views(true_rig, poses, SENSOR, seed=4)
    det = detect_all_dotgrid(images, grid, true_rig.names)
    assert det.found.sum() >= 10
    for f, c in zip(*np.nonzero(det.found), strict=True):
        e = np.linalg.norm(det.corners[f, c] - _truth(true_rig, poses, f, c), axis=1)
        assert e.max() < 0.3, f"frame {f}, camera {c}: {e.max():.2f} px"


def test_grid_and_fiducial_checks():
    """Targets whose fiducials cannot fix the orientation are refused with one line."""
    with pytest.raises(VisionError, match="look the same after a turn"):
        DotGrid(14, 10, 0.002, 0.001, fiducials=((0, 0), (13, 9)))
    with pytest.raises(VisionError, match="quarter turn"):
        DotGrid(10, 10, 0.002, 0.001, fiducials=())
    with pytest.raises(VisionError, match="overlap"):
        DotGrid(14, 10, 0.002, 0.0015, fiducial_kind="large")
    assert parse_fiducials("large:0,0;3,0;0,2") == ("large", ((0, 0), (3, 0), (0, 2)))
    assert parse_fiducials("none") == ("hollow", ())
    with pytest.raises(VisionError, match="I,J pairs"):
        parse_fiducials("hollow:1;2")


@SHARED_VIEWS
def test_too_few_views_named(true_rig, dot_views, dot_detections):
    """A camera that finds the grid in too few views: one line naming it, the frames and why;
    a camera beside it with views enough is not named."""
    _, images = dot_views
    seen = dot_detections.found[:4].sum(axis=0)
    short = [c for c in range(len(seen)) if 0 < seen[c] < 4]
    enough = [c for c in range(len(seen)) if seen[c] == 4]
    assert short, "the first four placements must leave some camera short of views"
    # one short camera and, when there is one, one with all four views: the message must tell
    # them apart, and the other cameras would only repeat the detection
    cams = short[:1] + enough[:1]
    names = [true_rig.names[c] for c in cams]
    with pytest.raises(VisionError, match=rf"too few views of the dot grid .*{names[0]} found it in "
                                          rf"{seen[cams[0]]} of 4 \(frames? \d") as err:
        calibrate_dotgrid(images[:4, cams], GRID, names, min_views=4)
    assert len(str(err.value).splitlines()) == 1
    assert all(f"{n} found it" not in str(err.value) for n in names[1:])


@SHARED_VIEWS
def test_too_few_views_in_all_is_named_not_a_crash(true_rig, dot_views, dot_detections):
    """A camera that found the grid in every one of too few frames: one line that says so."""
    _, images = dot_views
    c = int(np.flatnonzero(dot_detections.found[:2].all(axis=0))[0])
    with pytest.raises(VisionError, match=rf"{true_rig.names[c]} found it in 2 of 2 \(found in every "
                                          r"frame: take more views\)") as err:
        calibrate_dotgrid(images[:2, [c]], GRID, [true_rig.names[c]], min_views=4)
    assert len(str(err.value).splitlines()) == 1


def _angle_deg(Ra, Rb):
    return float(np.degrees(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1, 1))))


@pytest.mark.needs_plugins
@SHARED_VIEWS
def test_dot_grid_from_files_through_cli(tmp_path, true_rig, dot_views, dot_detections):
    """Files on disk -> ``skinkit import-images`` -> ``skinkit vision calibrate --target dotgrid``.

    Tolerances, from the rendering. The true rig reprojects the detected dots with their RMS
    error against the truth, sigma (measured here from the rendering); a least-squares fit can
    only do better, so the reprojection RMS stays within sigma (+5 %). The rest is the
    derivation of test_symmetric_board with the dots' error bound SIGMA_BOUND = 0.1 px (asserted
    here and by test_dots_subpixel_and_oriented_by_fiducials) in place of the corners' 0.1 px:
    the same rig, placements and tilts pin the perspective equally well. A relative focal error
    e moves the image edge (240 px from the centre) by 240 e px; keeping that inside a
    2 SIGMA_BOUND budget gives e < 1e-3, doubled because focal length trades against distance
    along the line of sight (all dots lie near one depth): |e| < 2e-3. The narrow (25 deg) field
    pins the principal point only to a few px: within 8 px. Relative pose of camera c to camera
    0: each camera's rotation may err by its principal-point shift d / f plus 0.05 deg
    (f * 0.05 deg ~ 1 px, 10 SIGMA_BOUND), the relative rotation by the sum of both; each camera
    centre may err by 2 e * distance (the focal/distance trade-off), so the baseline within
    twice that plus the baseline turned by the rotation tolerance.
    """
    poses, images = dot_views
    F, Cn = images.shape[:2]
    for c, name in enumerate(true_rig.names):
        (tmp_path / name).mkdir()
        for f in range(F):
            assert cv2.imwrite(str(tmp_path / name / f"{name}_grid_{f + 1:04d}.tif"), images[f, c])
    session = tmp_path / "session.h5"
    cams = [a for name in true_rig.names for a in ("--camera", name, str(tmp_path / name / "*.tif"))]
    r = in_process("import-images", str(session), *cams, "--name", "calibration")
    assert r.exit_code == 0, r.stderr

    # bad input first: a grid size the images do not hold is one line naming cameras and frames
    bad = in_process("vision", "calibrate", str(session), "--images", "calibration", "--target", "dotgrid",
                   "--grid", "15x10", "--pitch-mm", "1.6")
    assert bad.exit_code != 0 and "Traceback" not in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    assert "15x10 dot grid not found in any view of cam0 (frames 0, 1, 2, 3, 4, 5, 6, 7, ...: " \
        "140 dots seen, the grid has 150)" in bad.stderr, bad.stderr
    with open_experiment(session) as exp:
        assert "rig" not in exp.calibration_names()  # nothing written

    r = in_process("vision", "calibrate", str(session), "--images", "calibration", "--target", "dotgrid",
                 "--grid", "14x10", "--pitch-mm", str(GRID.pitch_m * 1e3),
                 "--fiducials", "hollow:1,1;2,1;1,2")
    assert r.exit_code == 0, r.stderr
    print(r.stdout)
    with open_experiment(session) as exp:
        rig = exp.read_rig()
        note = exp.read_calibration("rig")
        det_found = note["views"]
    assert note["target"] == "dotgrid" and rig.names == true_rig.names

    # sigma: the detected dots against the truth, over the views the calibration used
    det = dot_detections
    assert [int(v) for v in det.found.sum(axis=0)] == list(det_found)
    err = np.concatenate([np.linalg.norm(det.corners[f, c] - _truth(true_rig, poses, f, c), axis=1)
                          for f, c in zip(*np.nonzero(det.found), strict=True)])
    sigma = float(np.sqrt(np.mean(err**2)))
    print("dot error RMS vs truth", sigma, "px; calibration RMS", note["rms_px"])
    assert sigma < SIGMA_BOUND and note["rms_px"] <= 1.05 * sigma
    e_tol = 2 * (2 * SIGMA_BOUND / 240)

    t0, e0 = true_rig.cameras[0], rig.cameras[0]
    dist = np.linalg.norm(t0.centre)
    tol_rot = {}
    for true, est in zip(true_rig.cameras, rig.cameras, strict=True):
        e_f = est.K[0, 0] / true.K[0, 0] - 1
        dpp = float(np.linalg.norm(est.K[:2, 2] - true.K[:2, 2]))
        print(true.name, "focal rel err", e_f, "tol", e_tol, "principal point err px", dpp)
        assert abs(e_f) < e_tol and abs(est.K[1, 1] / true.K[1, 1] - 1) < e_tol
        assert dpp < 8
        tol_rot[true.name] = np.degrees(dpp / est.K[0, 0]) + 0.05
    for true, est in zip(true_rig.cameras[1:], rig.cameras[1:], strict=True):
        R_true, R_est = true.R @ t0.R.T, est.R @ e0.R.T          # camera 0 -> camera c
        b_true = t0.R @ (true.centre - t0.centre)                 # baseline in camera 0's frame [m]
        b_est = e0.R @ (est.centre - e0.centre)
        rot = _angle_deg(R_true, R_est)
        tol = tol_rot[true.name] + tol_rot[t0.name]
        tol_b = 2 * 2 * e_tol * dist + np.linalg.norm(b_true) * np.radians(tol)
        print(true.name, "relative rotation err deg", rot, "tol", tol,
              "baseline err um", 1e6 * np.linalg.norm(b_est - b_true), "tol", 1e6 * tol_b)
        assert rot < tol
        assert np.linalg.norm(b_est - b_true) < tol_b
    # the world frame is the flat first placement: dot (0, 0) at its origin, x along its rows
    X = C.project(e0, np.array([[0.0, 0, 0], [GRID.pitch_m, 0, 0]]))
    assert np.abs(X - _truth(true_rig, poses, 0, 0)[:2]).max() < 0.5
