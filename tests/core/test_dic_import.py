"""The two-pad extensometer + 2D tracking importer on the real healthy record, and bad input."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.errors import StoreError
from skinkit.store import open_experiment
from skinkit.store.dic_import import MARK_SPACING_M, import_extensometer, read_extensometer

ROOT = Path(__file__).resolve().parents[2]
RECORD = ROOT.parent / "shared" / "data" / "real" / "invivo_extension_dic_healthy"
RAW = RECORD / "datafiles_unprocessed"

pytestmark = pytest.mark.skipif(not RAW.is_dir(), reason="shared real data not beside the checkout")


@pytest.fixture(scope="module")
def imp():
    return read_extensometer(RECORD)


def test_shapes_units_and_signs(imp):
    rec, tr = imp.record, imp.track
    assert rec.n_samples == 876 and rec.protocol.name == "extension" and rec.protocol.kind == "external"
    # the device's raw values in SI: 0.008 to 8.70 mm, about -0.012 to 0.412 N, x only
    np.testing.assert_allclose([rec.tip_position[:, 0].min(), rec.tip_position[:, 0].max()], [8e-6, 8.7e-3])
    assert rec.tip_force[:, 0].min() == pytest.approx(-0.012) and rec.tip_force[:, 0].max() < 0.42
    assert np.isnan(rec.tip_force[:, 1:]).all() and np.isnan(rec.tip_position[:, 1:]).all()
    np.testing.assert_allclose(np.diff(rec.time_s), 0.1)          # nominal 10 Hz
    assert tr.points.shape == (544, 50, 3) and tr.valid.shape == (544, 50)
    assert np.all(tr.points[tr.valid][:, 2] == 0.0)                  # 2D: z = 0
    # the points lie between the pads (centres at +-18.2 mm), within the 8 mm band of the pads
    xy = tr.points[tr.valid][:, :2]
    assert np.all(np.abs(xy[:, 0]) < 0.0142) and np.all(np.abs(xy[:, 1]) < 0.0045)
    # pulling: the moving pad (+x) moves out; the points follow it on average, force grows
    d = np.array(imp.track_attrs["moving_pad_displacement_m"])
    assert d[0] == 0 and d[-1] == pytest.approx(3.82e-3, abs=0.02e-3)
    u = tr.displacements()[..., 0]
    assert np.nanmean(u[:, -1]) > 0
    assert np.all(np.diff(tr.time_s) > 0)


def test_pixel_scale_consistent_with_the_pads(imp):
    a = imp.track_attrs
    s = a["pixel_scale_m_per_px"]
    w1, w2 = a["mark_spacing_px"]
    # the two pads' mark spacings disagree by 4.3 %: each gives the scale to about +-2.2 %
    assert abs(w1 - w2) / (0.5 * (w1 + w2)) < 0.05
    for w in (w1, w2):
        assert MARK_SPACING_M / w == pytest.approx(s, rel=0.025)
    assert 1e-3 / s == pytest.approx(18.70, abs=0.01)                # px per mm
    # across frames the spacings drift by < 1.6 % (the same tolerance of the marks' placement)
    lo, hi = a["mark_spacing_px_range"]
    assert lo > w2 * 0.98 and hi <= w1 * 1.0001
    # the tracked grid's band (150 px across) is one pad wide, 8 mm, at this scale (+-2.5 %)
    y0 = np.loadtxt(RAW / "displacement" / "y0.dat")
    assert (y0.max() - y0.min()) * s == pytest.approx(0.008, rel=0.025)
    assert a["pad_centre_distance_m"] == pytest.approx(0.03647, abs=1e-4)


def test_noise_and_frame_matching(imp):
    a = imp.track_attrs
    nx, ny, nz = a["noise_m"]
    # about 0.3-0.4 px of DIC scatter: 10-30 um per axis; z is not measured
    assert 10e-6 < nx < 30e-6 and 10e-6 < ny < 30e-6 and np.isnan(nz)
    assert "not measured" in a["noise_m_reason"]   # beside the null the file holds for z
    # the residual mismatch of the frame times against a constant camera rate stays below the
    # per-frame pad step (~78 um), i.e. about the pad tracking noise
    assert a["frame_match_mismatch_rms_m"] < 40e-6
    assert a["dimensions"] == 2 and a["invalid_points"] < 0.1 * 544


def test_experiment_file_and_cli(tmp_path):
    out = tmp_path / "session.h5"
    r = CliRunner().invoke(cli, ["import-extensometer", str(out), str(RECORD)])
    assert r.exit_code == 0, r.output
    assert "18.7 px/mm" in r.output
    with open_experiment(out) as exp:
        assert exp.record_names() == ["extension"] and exp.track_names() == ["extension"]
        assert exp.track_attrs("extension")["dimensions"] == 2
        assert exp.record_info("extension")["extra"]["nominal_rate_hz"] == 10.0
        assert exp.read_track("extension").n_frames == 50
    r = CliRunner().invoke(cli, ["import-extensometer", str(out), str(RECORD)])
    assert r.exit_code == 2 and "already exists" in r.output
    r = CliRunner().invoke(cli, ["import-extensometer", str(out), str(RECORD), "--overwrite",
                                 "--protocol", "pull", "--rate", "20"])
    assert r.exit_code == 0, r.output
    with open_experiment(out) as exp:
        assert exp.record_names() == ["pull"]


def _copy(tmp_path: Path) -> Path:
    dst = tmp_path / "rec"
    shutil.copytree(RAW, dst)
    return dst


@pytest.mark.parametrize(("mutate", "message"), [
    (lambda d: (d / "reactionforce" / "f_moving_pad.dat").unlink(), r"f_moving_pad\.dat: no such file"),
    (lambda d: (d / "reactionforce" / "f_moving_pad.dat").write_text("0.1\n0.2\n"),
     r"f_moving_pad\.dat: has 2 values but u_moving_pad\.dat has 876"),
    (lambda d: (d / "displacement" / "yt.dat").write_text("1 2\n3 4\n"), r"yt\.dat: expected 544 points"),
    (lambda d: (d / "displacement" / "x0.dat").write_text("419\nabc\n"), r"x0\.dat: is not a numeric table"),
    (lambda d: (d / "displacement" / "xt_ref_2.dat").write_text("1 2\n3 4\n"),
     r"xt_ref_2\.dat: expected shape"),
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, mutate, message):
    d = _copy(tmp_path)
    mutate(d)
    out = tmp_path / "out.h5"
    with pytest.raises(StoreError, match=message) as ei:
        import_extensometer(d, out)
    assert "\n" not in str(ei.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]      # no file, no temporary left
    r = CliRunner().invoke(cli, ["import-extensometer", str(out), str(d)])
    assert r.exit_code == 2 and r.output.count("\n") == 1 and "Traceback" not in r.output


def test_missing_folder(tmp_path):
    with pytest.raises(StoreError, match="no such folder"):
        read_extensometer(tmp_path / "nowhere")
