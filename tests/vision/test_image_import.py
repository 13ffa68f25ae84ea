"""``skinkit import-images`` and ``skinkit import-calibration`` on real files: image files
written with OpenCV, calibrations written by cv::FileStorage, experiment files in HDF5."""

from __future__ import annotations

import subprocess
import sys

import cv2
import h5py
import numpy as np
import pytest

from skinkit.schemas import ImageSequence
from skinkit.store import create_experiment, open_experiment


def _skinkit(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "skinkit", *args], capture_output=True, text=True,
                          timeout=300)


def _one_line_error(r: subprocess.CompletedProcess, *words: str) -> None:
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    for w in words:
        assert w in lines[0], lines[0]


def _speckle(rng, shape=(48, 64), dtype=np.uint8):
    full = np.iinfo(dtype).max
    return (rng.random(shape) * full).astype(dtype)


def _objects(path):
    """Every HDF5 object name and its shape: what a failed import must leave untouched."""
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, getattr(o, "shape", None)))
    return out


def test_formats_and_frame_matching(tmp_path):
    """8-bit PNG/BMP/JPEG and 16-bit TIFF, colour turned grey; frames matched by the number in
    differently patterned names, or by natural order when the names carry none."""
    rng = np.random.default_rng(0)
    frames16 = np.stack([[_speckle(rng, dtype=np.uint16) for _ in range(2)] for _ in range(3)])
    (tmp_path / "left").mkdir()
    (tmp_path / "right").mkdir()
    for f in range(3):
        # the two cameras number their files differently: left_0007, R-7 (plus a camera number)
        assert cv2.imwrite(str(tmp_path / "left" / f"left_{f + 7:04d}.tif"), frames16[f, 0])
        assert cv2.imwrite(str(tmp_path / "right" / f"cam2-R-{f + 7}.tif"), frames16[f, 1])
    s = tmp_path / "s.h5"
    r = _skinkit("import-images", str(s), "--camera", "left", str(tmp_path / "left"),
                 "--camera", "right", str(tmp_path / "right" / "*.tif"), "--name", "deep", "--fps", "10")
    assert r.returncode == 0, r.stderr
    assert "matched by name" in r.stdout
    with open_experiment(s) as exp:
        seq = exp.read_images("deep")
    assert seq.frames.dtype == np.uint16 and np.array_equal(seq.frames, frames16)
    assert seq.camera_names == ("left", "right")
    assert np.allclose(seq.time_s, [0.0, 0.1, 0.2])

    # 8-bit: PNG (colour, turned grey), BMP lossless; JPEG lossy; names without frame numbers
    grey = np.stack([[_speckle(rng) for _ in range(3)] for _ in range(11)])
    for c, ext in enumerate(("png", "bmp", "jpg")):
        d = tmp_path / f"c{c}"
        d.mkdir()
        for f in range(11):
            img = cv2.cvtColor(grey[f, c], cv2.COLOR_GRAY2BGR) if ext == "png" else grey[f, c]
            # "shot" + a letter run: natural order, no number shared with the other cameras
            name = f"shot{'abcdefghijk'[f]}.{ext}" if c != 1 else f"take_{f + 1}.{ext}"
            assert cv2.imwrite(str(d / name), img)
    cams = [a for c, ext in enumerate(("png", "bmp", "jpg"))
            for a in ("--camera", f"c{c}", str(tmp_path / f"c{c}" / f"*.{ext}"))]
    r = _skinkit("import-images", str(s), *cams, "--name", "grey")
    assert r.returncode == 0, r.stderr
    assert "matched by order" in r.stdout
    with open_experiment(s) as exp:
        seq = exp.read_images("grey")
        assert exp.image_names() == ["deep", "grey"]
    assert seq.frames.dtype == np.uint8
    assert np.array_equal(seq.frames[:, :2], grey[:, :2])  # PNG and BMP are lossless
    # JPEG of white noise at OpenCV's default quality 95: errors of a few counts
    assert np.sqrt(np.mean((seq.frames[:, 2].astype(float) - grey[:, 2]) ** 2)) < 20


def test_bad_images_leave_the_file_as_it_was(tmp_path):
    rng = np.random.default_rng(1)
    s = tmp_path / "s.h5"
    with create_experiment(s) as exp:
        exp.write_images(ImageSequence("before", _speckle(rng, (2, 2, 48, 64)), ("a", "b"), [0.0, 1.0]))
    before = _objects(s)
    for cam in ("a", "b"):
        (tmp_path / cam).mkdir()
        for f in range(4):
            cv2.imwrite(str(tmp_path / cam / f"{cam}_{f:03d}.png"), _speckle(rng))
    args = ["import-images", str(s), "--camera", "a", str(tmp_path / "a" / "*.png"),
            "--camera", "b", str(tmp_path / "b" / "*.png")]

    (tmp_path / "b" / "b_002.png").unlink()
    _one_line_error(_skinkit(*args), "camera b has no image for frame(s) 2", "present for a")
    cv2.imwrite(str(tmp_path / "b" / "b_002.png"), _speckle(rng, (50, 64)))
    _one_line_error(_skinkit(*args), "mixed image sizes", "b_002.png is 64x50 px")
    cv2.imwrite(str(tmp_path / "b" / "b_002.png"), _speckle(rng, dtype=np.uint16))
    _one_line_error(_skinkit(*args), "mixed bit depths", "uint16")
    (tmp_path / "b" / "b_003.png").write_bytes(b"\x89PNG\r\n\x1a\n not really")  # the last frame
    cv2.imwrite(str(tmp_path / "b" / "b_002.png"), _speckle(rng))
    _one_line_error(_skinkit(*args), "camera b, frame 3", "b_003.png: cannot be read as an image")
    _one_line_error(_skinkit(*args[:2], "--camera", "a", str(tmp_path / "nothing*.png")),
                    "camera a: no files match")
    _one_line_error(_skinkit(*args[:2], "--camera", "a", str(tmp_path / "a"), "--camera", "b",
                             str(tmp_path / "b"), "--name", "before"), "already holds an image sequence")
    assert _objects(s) == before  # nothing half-written, no temporary sequence left

    # a failed import into a new file leaves no file behind
    new = tmp_path / "new.h5"
    _one_line_error(_skinkit("import-images", str(new), *args[2:]), "cannot be read")
    assert not new.exists()


def _write_camera(fs, cam, key_k="camera_matrix", key_d="distortion_coefficients", scale=1e3):
    fs.write(key_k, cam.K)
    fs.write(key_d, cam.distortion.reshape(1, -1))
    fs.write("R", cam.R)
    fs.write("T", cam.t.reshape(3, 1) * scale)
    fs.write("image_width", int(cam.image_size[0]))
    fs.write("image_height", int(cam.image_size[1]))


def _session(path, rig):
    with create_experiment(path) as exp:
        frames = np.zeros((1, len(rig.cameras), 384, 480), np.uint8)
        exp.write_images(ImageSequence("boards", frames, rig.names, [0.0]))


def _same_rig(a, b):
    for x, y in zip(a.cameras, b.cameras, strict=True):
        assert x.name == y.name and x.image_size == y.image_size
        for u, v in ((x.K, y.K), (x.distortion, y.distortion), (x.R, y.R), (x.t, y.t)):
            assert np.allclose(u, v, rtol=1e-12, atol=1e-15)


def test_opencv_calibration_files(tmp_path, true_rig):
    """Per-camera YAML files (T in mm), one XML with a map per camera (T in m, Rodrigues
    vectors), and OpenCV stereo_calib's pair of files; round trip to machine precision."""
    s = tmp_path / "s.h5"
    _session(s, true_rig)
    files = []
    for cam in true_rig.cameras:
        files.append(str(tmp_path / f"{cam.name}.yml"))
        fs = cv2.FileStorage(files[-1], cv2.FILE_STORAGE_WRITE)
        _write_camera(fs, cam)
        fs.release()
    r = _skinkit("import-calibration", str(s), *files)
    _one_line_error(r, "translations T without their unit", "--unit mm")
    r = _skinkit("import-calibration", str(s), *files, "--unit", "mm")
    assert r.returncode == 0, r.stderr
    with open_experiment(s) as exp:
        _same_rig(exp.read_rig(), true_rig)
        assert exp.read_calibration("rig_import")["unit"] == "mm"
    _one_line_error(_skinkit("import-calibration", str(s), *files, "--unit", "mm"), "already holds a rig")

    # one XML, cameras as named maps in another order than the session's, rotations as vectors
    xml = str(tmp_path / "rig.xml")
    fs = cv2.FileStorage(xml, cv2.FILE_STORAGE_WRITE)
    fs.write("unit", "m")
    for cam in reversed(true_rig.cameras):
        fs.startWriteStruct(cam.name, cv2.FileNode_MAP)
        fs.write("K", cam.K)
        fs.write("D", cam.distortion.reshape(1, -1))
        fs.write("rvec", cv2.Rodrigues(cam.R)[0])
        fs.write("tvec", cam.t.reshape(3, 1))
        fs.endWriteStruct()
    fs.release()
    s2 = tmp_path / "s2.h5"
    _session(s2, true_rig)
    r = _skinkit("import-calibration", str(s2), xml)
    assert r.returncode == 0, r.stderr
    with open_experiment(s2) as exp:
        got = exp.read_rig()
    for x, y in zip(got.cameras, true_rig.cameras, strict=True):
        assert x.name == y.name and x.image_size == (480, 384)  # taken from the session's images
        assert np.allclose(x.R, y.R, atol=1e-12) and np.allclose(x.t, y.t, atol=1e-15)
        assert np.allclose(x.K, y.K) and np.allclose(x.distortion, y.distortion)

    # stereo_calib: intrinsics.yml (M1, D1, M2, D2) + extrinsics.yml (R, T of camera 2 to 1, and
    # rectification R1, R2, P1, P2, Q that are no camera poses); a 4-camera session is refused
    a, b = true_rig.cameras[0], true_rig.cameras[1]
    intr, extr = str(tmp_path / "intrinsics.yml"), str(tmp_path / "extrinsics.yml")
    fs = cv2.FileStorage(intr, cv2.FILE_STORAGE_WRITE)
    for i, cam in ((1, a), (2, b)):
        fs.write(f"M{i}", cam.K)
        fs.write(f"D{i}", cam.distortion.reshape(1, -1))
    fs.release()
    R12 = b.R @ a.R.T
    T12 = b.t - R12 @ a.t
    fs = cv2.FileStorage(extr, cv2.FILE_STORAGE_WRITE)
    fs.write("R", R12)
    fs.write("T", T12.reshape(3, 1) * 1e3)
    fs.write("R1", np.eye(3))
    fs.write("R2", np.eye(3))
    fs.write("P1", np.eye(3, 4))
    fs.release()
    s3 = tmp_path / "s3.h5"
    _session(s3, true_rig)
    before = _objects(s3)
    _one_line_error(_skinkit("import-calibration", str(s3), intr, extr, "--unit", "mm"),
                    "2 camera(s) in the calibration but the session has 4")
    assert _objects(s3) == before
    s4 = tmp_path / "s4.h5"
    with create_experiment(s4) as exp:
        exp.write_images(ImageSequence("pair", np.zeros((1, 2, 384, 480), np.uint8), ("L", "R"), [0.0]))
    r = _skinkit("import-calibration", str(s4), intr, extr, "--unit", "mm")
    assert r.returncode == 0, r.stderr
    with open_experiment(s4) as exp:
        L, R = exp.read_rig().cameras
    assert np.allclose(L.R, np.eye(3)) and np.allclose(L.t, 0)
    assert np.allclose(R.R, R12, atol=1e-12) and np.allclose(R.t, T12, atol=1e-15)
    # the baseline is the rig's: camera 2's centre seen from camera 1
    assert np.linalg.norm(R.centre) == pytest.approx(np.linalg.norm(b.centre - a.centre), rel=1e-12)

    bad = tmp_path / "bad.yml"
    bad.write_text("%YAML:1.0\n---\nfoo: [1, 2\n")
    _one_line_error(_skinkit("import-calibration", str(s3), str(bad)), "bad.yml")
