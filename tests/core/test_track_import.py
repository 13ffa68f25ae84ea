"""Tracks CSV from other DIC tools (``skinkit import-tracks``): layouts, units, one-line errors,
nothing written on error."""

from __future__ import annotations

import subprocess
import sys

import h5py
import numpy as np
import pytest

from skinkit.errors import StoreError
from skinkit.store import create_experiment, open_experiment
from skinkit.store.track_import import import_tracks, read_tracks_csv


def _truth(P=5, F=4, seed=0):
    """Points on a 10 mm grid moving by up to 0.3 mm [m], one point missing in frame 2."""
    rng = np.random.default_rng(seed)
    X0 = np.column_stack([np.arange(P) * 0.01, rng.uniform(-0.01, 0.01, P), rng.uniform(0, 0.002, P)])
    pts = X0[:, None, :] + rng.uniform(-3e-4, 3e-4, (P, F, 3)) * np.arange(F)[None, :, None]
    valid = np.ones((P, F), bool)
    valid[3, 2] = False
    return pts, valid


def test_long_form_3d_mm(tmp_path):
    pts, valid = _truth()
    lines = ["frame,point,time_ms,x_mm,y_mm,z_mm"]
    for f in range(pts.shape[1]):
        for p in range(pts.shape[0]):
            if valid[p, f]:
                lines.append(f"{f + 1},{p + 10},{50 * f},{','.join(f'{v * 1e3:.9f}' for v in pts[p, f])}")
    path = tmp_path / "dic.csv"
    path.write_text("\n".join(lines) + "\n")
    imp = read_tracks_csv(path)
    t = imp.track
    assert t.points.shape == pts.shape and np.array_equal(t.valid, valid)
    assert np.allclose(t.points[valid], pts[valid], atol=1e-12)  # 9 decimals of a mm
    assert np.allclose(t.time_s, [0, 0.05, 0.1, 0.15]) and t.point_ids.tolist() == [10, 11, 12, 13, 14]
    assert imp.attrs["dimensions"] == 3 and imp.attrs["layout"] == "long"


def test_wide_form_2d_pixels_and_displacements(tmp_path):
    pts, valid = _truth()
    m_per_px = 2e-5
    px = pts[..., :2] / m_per_px
    labels = ["P1", "P2", "P3", "P4", "P5"]
    head = ["frame"] + [f"{a}_{lb}_px" for lb in labels for a in "xy"]
    rows = [";".join(head)]
    for f in range(px.shape[1]):
        cells = [str(f)] + [("" if not valid[p, f] else f"{px[p, f, a]:.6f}")
                            for p in range(len(labels)) for a in range(2)]
        rows.append(";".join(cells))
    path = tmp_path / "wide.csv"
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(StoreError, match="in pixels: give the scale"):
        read_tracks_csv(path)
    imp = read_tracks_csv(path, m_per_px=m_per_px, fps=20)
    t = imp.track
    assert np.array_equal(t.valid, valid) and imp.attrs["dimensions"] == 2
    assert np.allclose(t.points[valid][:, :2], pts[valid][:, :2], atol=1e-6 * m_per_px)
    assert np.all(t.points[valid][:, 2] == 0)
    assert imp.attrs["point_labels"] == labels and np.allclose(t.time_s, np.arange(4) / 20)

    # VIC-style export: reference X, Y, Z and displacements U, V, W, a score column ignored
    ref = pts[:, 0]
    rows = ["frame,point,X,Y,Z,U,V,W,sigma"]
    for f in range(pts.shape[1]):
        for p in range(pts.shape[0]):
            d = pts[p, f] - ref[p]
            cells = [*ref[p], *d] if valid[p, f] else [*ref[p], "nan", "nan", "nan"]
            rows.append(f"{f},{p}," + ",".join(str(v * 1e3) if v != "nan" else v for v in cells) + ",0.01")
    vic = tmp_path / "vic.csv"
    vic.write_text("\n".join(rows) + "\n")
    with pytest.raises(StoreError, match=r"unknown column\(s\) 'sigma'"):
        read_tracks_csv(vic, unit="mm")
    t = read_tracks_csv(vic, unit="mm", ignore=["sigma"]).track
    assert np.array_equal(t.valid, valid)
    assert np.allclose(t.points[valid], pts[valid], atol=1e-12)


def _objects(path):
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, getattr(o, "shape", None)))
    return out


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "skinkit", "import-tracks", *args], capture_output=True,
                          text=True, timeout=120)


def test_cli_and_bad_input(tmp_path):
    good = tmp_path / "good.csv"
    good.write_text("frame,point,x_mm,y_mm,z_mm\n0,1,0,0,0\n0,2,1,0,0\n1,1,0.1,0,0\n1,2,1.1,0,0.2\n")
    s = tmp_path / "s.h5"
    r = _cli(str(s), str(good), "--name", "ext")
    assert r.returncode == 0, r.stderr
    with open_experiment(s) as exp:
        t = exp.read_track("ext")
        assert exp.track_attrs("ext")["dimensions"] == 3
    assert np.allclose(t.points[1, 1], [0.0011, 0, 0.0002])
    before = _objects(s)

    cases = {
        "frame,point,x_mm,y_mm,score,colour\n0,1,0,0,1,2\n": "unknown column(s) 'score', 'colour'",
        "frame,point,x,y\n0,1,0,0\n": "column 'x' has no unit",
        "frame,point,x_mm,y_mm\n0,1,0,0\n0,1,1,1\n": "line 3: point '1' appears twice in frame 0",
        "frame,point,x_mm,y_mm\n0,1,0,oops\n": "line 2: column 'y_mm': 'oops' is not a number",
        "point,x_mm,y_mm\n1,0,0\n": "no 'frame' column",
        "frame,x_1_mm,y_1_mm,x_mm\n0,0,0,0\n": "unknown column(s) 'x_mm'",
    }
    for k, (text, message) in enumerate(cases.items()):
        bad = tmp_path / f"bad{k}.csv"
        bad.write_text(text)
        r = _cli(str(s), str(bad))
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert r.returncode == 2 and len(lines) == 1 and message in lines[0], (message, r.stderr)
        assert _objects(s) == before
    r = _cli(str(s), str(good), "--name", "ext")
    assert r.returncode == 2 and "already exists" in r.stderr
    assert _objects(s) == before

    new = tmp_path / "new.h5"
    with pytest.raises(StoreError, match="unknown column"):
        import_tracks(new, tmp_path / "bad0.csv")
    assert not new.exists()
    with create_experiment(new):
        pass
    import_tracks(new, good)
    with open_experiment(new) as exp:
        assert exp.track_names() == ["good"]
