"""DIC exports that cannot misread units (``skinkit import-tracks``): pixel beside metric columns
refused unless chosen, DICe per-frame solution files, Vic-3D per-frame CSV exports, format
detection and its override, and one-line refusals of bad input.

The fixtures are written here from the tools' documented column names (DICe: the solution
file's ``***`` comment block, ``SUBSET_ID, COORDINATE_X, ..., MODEL_DISPLACEMENT_Z, SIGMA``;
Vic-3D: ``X, Y, Z, U, V, W`` [mm], ``x, y, u, v`` [pixel], ``sigma``, -1 where not correlated),
not by skinkit's own writer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.errors import StoreError
from skinkit.store import open_experiment
from skinkit.store.track_import import read_tracks
from tests.core._cli import one_error

M_PER_PX = 5e-5


def _run(*args: str):
    return CliRunner().invoke(cli, ["import-tracks", *args])


def _truth(P=4, F=11, seed=1):
    """Reference positions ``(P, 3)`` [mm], displacements ``(P, F, 3)`` [mm] (0 in frame 0),
    pixel references ``(P, 2)`` and pixel displacements ``(P, F, 2)``; point 2 is missing in
    frame 3."""
    rng = np.random.default_rng(seed)
    ref = np.column_stack([np.arange(P) * 5.0, rng.uniform(-5, 5, P), rng.uniform(0, 1, P)])
    disp = rng.uniform(-0.2, 0.2, (P, F, 3)) * np.arange(F)[None, :, None]
    ref_px = rng.uniform(100, 900, (P, 2))
    disp_px = rng.uniform(-3, 3, (P, F, 2)) * np.arange(F)[None, :, None]
    valid = np.ones((P, F), bool)
    valid[2, min(3, F - 1)] = False
    return ref, disp, ref_px, disp_px, valid


def _fmt(v: float) -> str:
    return f"{v:.10E}"     # DICe's own layout, more digits: the check below is to 1e-12 m


# ---- the generic CSV: pixel x, y beside metric X, Y, Z, U, V, W ----------------------------------

def test_csv_with_pixel_and_metric_columns_is_refused_until_chosen(tmp_path):
    ref, disp, ref_px, disp_px, valid = _truth(P=3, F=2)
    rows = ["frame,point,X,Y,Z,U,V,W,x,y"]
    for f in range(2):
        for p in range(3):
            rows.append(",".join([str(f), str(p), *map(str, ref[p]), *map(str, disp[p, f]),
                                  *map(str, ref_px[p] + disp_px[p, f])]))
    path = tmp_path / "vic_style.csv"
    path.write_text("\n".join(rows) + "\n")
    exp = tmp_path / "s.h5"
    one_error(_run(str(exp), str(path), "--unit", "mm"), "vic_style.csv:line 1",
              "pixel columns x, y", "metric columns X, Y, Z, U, V, W", "--columns pixel", "--columns metric")
    assert not exp.exists()

    t = read_tracks(path, columns="metric", unit="mm").track
    assert np.allclose(t.points, (ref[:, None, :] + disp[:, :2]) * 1e-3, atol=1e-12)
    t = read_tracks(path, columns="pixel", unit="mm", m_per_px=M_PER_PX).track   # --unit names X only
    assert np.allclose(t.points[..., :2], (ref_px[:, None, :] + disp_px[:, :2]) * M_PER_PX, atol=1e-12)
    assert np.all(t.points[..., 2] == 0)
    with pytest.raises(StoreError, match="'x_mm' and 'x_m'"):
        _write_and_read(tmp_path, "frame,point,x_mm,x_m,y_mm\n0,1,0,0,0\n")
    with pytest.raises(StoreError, match=r"pixel columns x_px, y_px and metric columns x_mm, y_mm"):
        _write_and_read(tmp_path, "frame,point,x_px,y_px,x_mm,y_mm\n0,1,0,0,0,0\n")
    with pytest.raises(StoreError, match=r"'Frame': column names are case-sensitive"):
        _write_and_read(tmp_path, "Frame,point,x_mm,y_mm\n0,1,0,0\n")
    with pytest.raises(StoreError, match=r"unknown column\(s\) 'Z_px'"):
        _write_and_read(tmp_path, "frame,point,x_mm,y_mm,Z_px\n0,1,0,0,0\n")

    r = _run(str(exp), str(path), "--unit", "mm", "--columns", "metric", "--name", "vic")
    assert r.exit_code == 0, r.output
    assert "csv, metric columns" in r.output
    with open_experiment(exp) as e:
        p0 = e.read_track("vic").points[0, 0]
    assert np.allclose(p0, ref[0] * 1e-3)   # not 0.1 m away: pixels are no longer read as mm


def _write_and_read(tmp_path: Path, text: str):
    p = tmp_path / "small.csv"
    p.write_text(text)
    return read_tracks(p)


# ---- DICe -------------------------------------------------------------------------------------

_DICE_COMMENT = """***
*** Digital Image Correlation Engine (DICe), (git sha1: test) Copyright 2021 NTESS
***
*** Reference image: ref.tif
*** Deformed image: def_{f}.tif
*** DIC method : local
*** Coordinates given with (0,0) as upper left corner of image, x positive right, y positive down
***
"""


def _dice(folder: Path, stereo: bool, order=None) -> tuple:
    """DICe_solution_<f>.txt for frames 0..10 (unpadded names: natural order matters); subset
    ids 10.. written in ``order`` in frame 5; subset 12 not correlated (SIGMA -1) in frame 3."""
    ref, disp, ref_px, disp_px, valid = _truth()
    P, F = valid.shape
    folder.mkdir()
    head = "SUBSET_ID,COORDINATE_X,COORDINATE_Y,DISPLACEMENT_X,DISPLACEMENT_Y"
    head += ",MODEL_COORDINATES_X,MODEL_COORDINATES_Y,MODEL_COORDINATES_Z,MODEL_DISPLACEMENT_X," \
            "MODEL_DISPLACEMENT_Y,MODEL_DISPLACEMENT_Z" if stereo else ""
    head += ",SIGMA,GAMMA,BETA,STATUS_FLAG,UNCERTAINTY"
    for f in range(F):
        lines = [head]
        for p in (order if (order is not None and f == 5) else range(P)):
            cells = [str(10 + p), *map(_fmt, ref_px[p]), *map(_fmt, disp_px[p, f])]
            if stereo:
                cells += [*map(_fmt, ref[p]), *map(_fmt, disp[p, f])]
            sigma = 0.004 if valid[p, f] else -1.0
            cells += [_fmt(sigma), _fmt(0.01), _fmt(12.0), "4", _fmt(0.0)]
            lines.append(",".join(cells))
        (folder / f"DICe_solution_{f}.txt").write_text(_DICE_COMMENT.format(f=f) + "\n".join(lines) + "\n")
    return ref, disp, ref_px, disp_px, valid


def test_dice_2d_folder_point_by_point(tmp_path):
    ref, disp, ref_px, disp_px, valid = _dice(tmp_path / "results", stereo=False, order=[3, 1, 0, 2])
    exp = tmp_path / "s.h5"
    r = _run(str(exp), str(tmp_path / "results"), "--m-per-px", str(M_PER_PX), "--fps", "10")
    assert r.exit_code == 0, r.output
    assert "4 points x 11 frames (2D, dice, pixel columns" in r.output
    with open_experiment(exp) as e:
        t = e.read_track("results")
        attrs = e.track_attrs("results")
    assert attrs["format"] == "dice" and attrs["files"] == {"first": "DICe_solution_0.txt",
                                                            "last": "DICe_solution_10.txt", "count": 11}
    assert t.point_ids.tolist() == [10, 11, 12, 13] and np.allclose(t.time_s, np.arange(11) / 10)
    assert np.array_equal(t.valid, valid)
    want = (ref_px[:, None, :] + disp_px) * M_PER_PX
    for p in range(4):
        for f in range(11):
            if valid[p, f]:
                assert np.allclose(t.points[p, f, :2], want[p, f], rtol=0, atol=1e-12), (p, f)
                assert t.points[p, f, 2] == 0
    assert not np.isfinite(t.points[2, 3]).any()


def test_dice_stereo_needs_a_column_choice_and_a_unit(tmp_path):
    ref, disp, _rpx, _dpx, valid = _dice(tmp_path / "stereo", stereo=True)
    src = str(tmp_path / "stereo" / "DICe_solution_*.txt")
    exp = tmp_path / "s.h5"
    one_error(_run(str(exp), src), "DICe_solution_0.txt:line 9", "pixel columns COORDINATE_X, COORDINATE_Y, "
              "DISPLACEMENT_X, DISPLACEMENT_Y", "metric columns MODEL_COORDINATES_X", "--columns")
    one_error(_run(str(exp), src, "--columns", "metric"), "MODEL_COORDINATES_X", "calibration's unit",
              "--unit")
    assert not exp.exists()
    r = _run(str(exp), src, "--columns", "metric", "--unit", "mm")
    assert r.exit_code == 0, r.output
    with open_experiment(exp) as e:
        t = e.read_track("stereo")
        assert e.track_attrs("stereo")["dimensions"] == 3
    assert np.array_equal(t.valid, valid)
    assert np.allclose(t.points[valid], ((ref[:, None, :] + disp) * 1e-3)[valid], rtol=0, atol=1e-12)


# ---- Vic-3D -----------------------------------------------------------------------------------

def _vic(folder: Path, units: bool, n_points=None) -> tuple:
    """One CSV per frame (``spec-<f>_0.csv``), quoted header as Vic-3D exports it; sigma -1 where
    the point was not correlated (its other cells then hold 0)."""
    ref, disp, ref_px, disp_px, valid = _truth()
    P, F = valid.shape
    folder.mkdir()
    names = ["Count", "X", "Y", "Z", "U", "V", "W", "sigma", "x", "y", "u", "v", "exx"]
    if units:
        names = [f"{n} [mm]" if n in "XYZUVW" else (f"{n} [pixel]" if n in ("x", "y", "u", "v", "sigma")
                                                       else n) for n in names]
    for f in range(F):
        lines = [",".join(f'"{n}"' for n in names)]
        for p in range((n_points or {}).get(f, P)):
            if valid[p, f]:
                cells = [p, *ref[p], *disp[p, f], 0.01, *ref_px[p], *disp_px[p, f], 1e-4]
            else:
                cells = [p, 0, 0, 0, 0, 0, 0, -1, 0, 0, 0, 0, 0]
            lines.append(",".join(f"{c:.9g}" for c in cells))
        (folder / f"spec-{f}_0.csv").write_text("\n".join(lines) + "\n")
    return ref, disp, ref_px, disp_px, valid


def test_vic3d_metric_with_units_in_the_header(tmp_path):
    ref, disp, ref_px, disp_px, valid = _vic(tmp_path / "vic", units=True)
    exp = tmp_path / "s.h5"
    one_error(_run(str(exp), str(tmp_path / "vic")), "spec-0_0.csv:line 1",
              "pixel columns x [pixel], y [pixel]", "metric columns X [mm]", "--columns")
    one_error(_run(str(exp), str(tmp_path / "vic"), "--columns", "metric", "--unit", "m"),
              "'X [mm]' is in mm but --unit says m")
    r = _run(str(exp), str(tmp_path / "vic"), "--columns", "metric", "--name", "shape")
    assert r.exit_code == 0, r.output
    with open_experiment(exp) as e:
        t = e.read_track("shape")
        assert e.track_attrs("shape")["format"] == "vic3d"
    assert t.points.shape == (4, 11, 3) and np.array_equal(t.valid, valid)
    want = (ref[:, None, :] + disp) * 1e-3
    for p in range(4):
        for f in range(11):
            if valid[p, f]:
                assert np.allclose(t.points[p, f], want[p, f], rtol=0, atol=1e-11), (p, f)
    r = _run(str(exp), str(tmp_path / "vic"), "--columns", "pixel", "--m-per-px", str(M_PER_PX),
             "--name", "px")
    assert r.exit_code == 0, r.output
    with open_experiment(exp) as e:
        t = e.read_track("px")
    assert np.allclose(t.points[valid][:, :2], ((ref_px[:, None, :] + disp_px) * M_PER_PX)[valid], rtol=0,
                       atol=1e-10)   # 9 digits of ~900 px


def test_vic3d_without_units_and_the_format_override(tmp_path):
    ref, disp, _rpx, _dpx, valid = _vic(tmp_path / "vic", units=False)
    src = tmp_path / "vic" / "spec-3_0.csv"
    with pytest.raises(StoreError, match="metric column 'X': its header gives no unit; give --unit"):
        read_tracks(src, columns="metric")
    t = read_tracks(src, "vic3d", columns="metric", unit="mm").track
    assert t.n_frames == 1 and np.array_equal(t.valid[:, 0], valid[:, 3])
    assert np.allclose(t.points[valid[:, 3], 0], ((ref + disp[:, 3]) * 1e-3)[valid[:, 3]])
    # the same file forced through the csv reader: its own refusal, not a silent reading
    with pytest.raises(StoreError, match="no 'frame' column"):
        read_tracks(src, "csv", columns="metric", unit="mm")


# ---- bad input: one line each, nothing written ----------------------------------------------------

def test_bad_input_is_one_line(tmp_path):
    exp = tmp_path / "s.h5"
    odd = tmp_path / "odd.csv"
    odd.write_text("a,b,c\n1,2,3\n")
    one_error(_run(str(exp), str(odd)), "odd.csv:line 1", "unknown track format", "header: a, b, c",
              "--format")
    empty = tmp_path / "empty"
    empty.mkdir()
    one_error(_run(str(exp), str(empty), "--format", "dice"), "no DICe solution files (DICe_solution_*.txt)")
    one_error(_run(str(exp), str(empty)), "holds no DICe_solution_*.txt or *.csv files")
    one_error(_run(str(exp), str(tmp_path / "none_*.csv")), "no files match")

    _vic(tmp_path / "short", units=True, n_points={7: 3})
    one_error(_run(str(exp), str(tmp_path / "short"), "--columns", "metric"),
              "spec-7_0.csv", "holds 3 points but spec-0_0.csv holds 4")

    _dice(tmp_path / "dice", stereo=False)
    bad = tmp_path / "dice" / "DICe_solution_4.txt"
    lines = bad.read_text().splitlines()
    lines[10] = lines[10].replace(lines[10].split(",")[2], "oops", 1)
    bad.write_text("\n".join(lines) + "\n")
    one_error(_run(str(exp), str(tmp_path / "dice"), "--m-per-px", "1e-5"),
              "DICe_solution_4.txt:line 11", "column 'COORDINATE_Y'", "'oops' is not a number")
    one_error(_run(str(exp), str(tmp_path / "dice")), "in pixels", "--m-per-px")
    one_error(_run(str(exp), str(tmp_path / "dice"), "--format", "csv"), "csv format is one file")
    assert not exp.exists()


# ---- MultiDIC ---------------------------------------------------------------------------------

def _points3d(P=5, F=4, seed=2):
    """``Points3D``: one ``(P, 3)`` matrix [mm] per frame, point 1 not reconstructed (NaN) in
    frame 2."""
    rng = np.random.default_rng(seed)
    frames = [rng.uniform(-20, 20, (P, 3)) + 0.1 * f for f in range(F)]
    frames[2][1] = np.nan
    return frames


def test_multidic_mat_v5_and_v73(tmp_path):
    import h5py
    import scipy.io

    frames = _points3d()
    cell = np.empty((len(frames), 1), dtype=object)
    for k, a in enumerate(frames):
        cell[k, 0] = a
    v5 = tmp_path / "DIC3DPPresults.mat"
    scipy.io.savemat(v5, {"DIC3DPPresults": {"Points3D": cell, "Faces": np.array([[1, 2, 3]])}})
    exp = tmp_path / "s.h5"
    one_error(_run(str(exp), str(v5)), "DIC3DPPresults.mat", "calibration's unit", "--unit")
    one_error(_run(str(exp), str(v5), "--unit", "mm", "--columns", "pixel"), "metric positions only")
    r = _run(str(exp), str(v5), "--unit", "mm", "--fps", "2")
    assert r.exit_code == 0, r.output
    assert "5 points x 4 frames (3D, multidic, metric columns, 19 valid positions)" in r.output
    with open_experiment(exp) as e:
        t = e.read_track("DIC3DPPresults")
    want = np.stack(frames, axis=1) * 1e-3
    ok = np.all(np.isfinite(want), axis=2)
    assert np.array_equal(t.valid, ok) and not ok[1, 2] and np.allclose(t.time_s, np.arange(4) / 2)
    assert np.allclose(t.points[ok], want[ok], rtol=0, atol=1e-15)

    # MAT v7.3 as MATLAB lays it out: HDF5, the cell a dataset of references to (3, N) matrices
    v73 = tmp_path / "pairs.mat"
    with h5py.File(v73, "w", userblock_size=512) as f:
        refs = [f.create_dataset(f"#refs#/{k}", data=a.T).ref for k, a in enumerate(frames)]
        g = f.create_group("DIC3DpairResults")
        g.create_dataset("Points3D", data=np.array(refs, dtype=h5py.ref_dtype).reshape(-1, 1))
    with open(v73, "r+b") as f:   # MATLAB's text header in the HDF5 user block
        f.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: test HDF5 schema 1.00 .".ljust(116))
    t = read_tracks(v73, unit="mm").track
    assert np.array_equal(t.valid, ok) and np.allclose(t.points[ok], want[ok], rtol=0, atol=1e-15)

    short = tmp_path / "short.mat"
    cell[3, 0] = frames[3][:4]
    scipy.io.savemat(short, {"DIC3DPPresults": {"Points3D": cell}})
    one_error(_run(str(exp), str(short), "--unit", "mm"),
              "Points3D{4} holds 4 points but Points3D{1} holds 5")
    other = tmp_path / "ncorr.mat"
    scipy.io.savemat(other, {"data_dic_save": {"dispinfo": 1}})
    one_error(_run(str(exp), str(other), "--unit", "mm"), "holds no DIC3DPPresults or DIC3DpairResults",
              "data_dic_save")
