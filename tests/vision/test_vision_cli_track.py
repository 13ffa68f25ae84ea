"""``skinkit vision track`` on real image files."""

from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

from skinkit.vision import planar
from skinkit.vision.sensor import Sensor
from skinkit.vision.texture import SpeckleTexture

pytestmark = pytest.mark.needs_plugins


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "skinkit", "vision", "track", *args],
                          capture_output=True, text=True, timeout=120)


@pytest.fixture()
def pair(tmp_path):
    rng = np.random.default_rng(4)
    tex = SpeckleTexture(cell=5.0, seed=21)
    sen = Sensor(noise=0.01)
    ref = sen.expose(planar.render(tex, (120, 160)), rng)
    cur = sen.expose(planar.render(tex, (120, 160), planar.translation(2.4, 0.7)), rng)
    cv2.imwrite(str(tmp_path / "ref.png"), ref)
    cv2.imwrite(str(tmp_path / "cur.png"), cur)
    (tmp_path / "pts.csv").write_text("x_px,y_px\n80,60\n70.5,55.2\n5,60\n")
    return tmp_path


def test_track_json(pair):
    r = _run(str(pair / "ref.png"), str(pair / "cur.png"), "--points", str(pair / "pts.csv"),
             "--subset", "48", "--json")
    assert r.returncode == 0, r.stderr
    pts = json.loads(r.stdout)["points"]
    assert [p["valid"] for p in pts] == [True, True, False]
    for p in pts[:2]:
        # 48-px subsets at 1 % noise: noise floor ~0.005 px, 0.05 px is 10 sigma.
        assert abs(p["dx_px"] - 2.4) < 0.05 and abs(p["dy_px"] - 0.7) < 0.05
        assert 0.5 < p["quality"] <= 1
    assert pts[2]["dx_px"] is None and "edge" in pts[2]["reason"]
    assert set(pts[0]) >= {"x_px", "y_px", "dx_px", "dy_px", "quality", "valid"}


def test_track_table_with_pcc(pair):
    r = _run(str(pair / "ref.png"), str(pair / "cur.png"), "--points", str(pair / "pts.csv"),
             "--subset", "48", "--tracker", "pcc")
    assert r.returncode == 0, r.stderr
    assert "2 of 3 points tracked with pcc" in r.stdout


def test_track_errors(pair, tmp_path):
    (tmp_path / "junk.png").write_bytes(b"not an image")
    small = np.zeros((50, 50), np.uint8)
    cv2.imwrite(str(tmp_path / "small.png"), small)
    (tmp_path / "bad.csv").write_text("x,y\n1,2\n")
    cases = [
        ((str(tmp_path / "junk.png"), str(pair / "cur.png")), "cannot be read as an image"),
        ((str(tmp_path / "nope.png"), str(pair / "cur.png")), "no such image file"),
        ((str(pair / "ref.png"), str(tmp_path / "small.png")), "image sizes differ"),
    ]
    for images, msg in cases:
        r = _run(*images, "--points", str(pair / "pts.csv"))
        assert r.returncode == 2 and msg in r.stderr and "Traceback" not in r.stderr, r.stderr
    r = _run(str(pair / "ref.png"), str(pair / "cur.png"), "--points", str(tmp_path / "bad.csv"))
    assert r.returncode == 2 and "lacks the columns x_px,y_px" in r.stderr
    r = _run(str(pair / "ref.png"), str(pair / "cur.png"), "--points", str(pair / "pts.csv"),
             "--tracker", "nosuch")
    assert r.returncode == 2 and "no plugin 'nosuch'" in r.stderr
