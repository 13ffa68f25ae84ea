"""Virtual scar sessions (``skinkit lab scar-session``): the scar draw, what the truth and the session
files hold, healthy sessions, noise at the real record's levels, bad options.

Noise statistics as in ``test_lab_session.py``: for n independent N(0, σ²) samples, (n − 1) s²/σ²
is χ² with n − 1 degrees of freedom; a sample standard deviation is accepted within the two-sided
99.99 % interval of that law. The sessions are solved on the model's mesh (``--shared-mesh``, a
few seconds); the own-mesh path is the lab's, tested with ``skinkit lab session``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy.stats import chi2

from skinkit.fem.fields import ellipse_distance
from skinkit.lab import record_sensors as R
from skinkit.lab.scar import (
    OUTLINE_POINTS,
    RATIO_RANGE,
    SPAN_RANGE_M,
    gap_band,
    make_scar_session,
    model_spec,
    scar_for_seed,
    simulate_scar,
)
from skinkit.lab.session import LabError

pytestmark = pytest.mark.needs_plugins

P_TAIL = 1e-4 / 2
REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real" / "invivo_extension_dic_healthy"


def _sd_accepted(s: float, sigma: float, n: int) -> bool:
    lo, hi = (math.sqrt(chi2.ppf(q, n - 1) / (n - 1)) for q in (P_TAIL, 1 - P_TAIL))
    return lo * sigma <= s <= hi * sigma


def test_scars_fit_the_band_and_their_ranges():
    """Every drawn scar: ratio and both diameters in their ranges, the outline inside the pads'
    gap band (between the facing edges in x, within the pads' width in y)."""
    spec = model_spec()
    half_gap, half_band = gap_band(spec)
    for seed in range(200):
        s = scar_for_seed(seed, spec)
        assert RATIO_RANGE[0] <= s.ratio <= RATIO_RANGE[1]
        assert all(SPAN_RANGE_M[0] <= 2 * v <= SPAN_RANGE_M[1] for v in (s.a, s.b))
        assert -math.pi / 2 <= s.angle < math.pi / 2
        xy = s.outline(400)
        assert np.all(np.abs(xy[:, 0]) < half_gap) and np.all(np.abs(xy[:, 1]) < half_band)


def test_two_seeds_give_different_scars_and_one_seed_the_same():
    spec = model_spec()
    a, b = scar_for_seed(1, spec), scar_for_seed(2, spec)
    assert a != b and scar_for_seed(1, spec) == a


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("scar")
    docs = {}
    for kind, healthy in (("scar", False), ("healthy", True)):
        docs[kind] = make_scar_session(d / f"{kind}.h5", d / f"{kind}.json", 5, healthy=healthy,
                                       mesh="shared", workers=1)
    return d, docs


def test_the_truth_file_holds_the_scar_and_its_outline(files):
    d, _ = files
    doc = json.loads((d / "scar.json").read_text())
    scar = doc["scar"]
    out = np.asarray(scar["outline_m"])
    assert out.shape == (OUTLINE_POINTS, 2)
    dist = ellipse_distance(out[:, 0] - scar["x_m"], out[:, 1] - scar["y_m"], scar["a_m"], scar["b_m"],
                            scar["angle_rad"])
    assert np.max(np.abs(dist)) < 1e-12
    (eff,) = doc["effects"]
    assert eff["name"] == "inclusion" and eff["form"] == "ellipse" and eff["ratio"] == scar["ratio"]
    (field,) = doc["model"]["fields"]
    assert field["kind"] == "inclusion" and field["a"] == pytest.approx(scar["a_m"])
    assert doc["mesh"]["mode"] == "shared"


def _contents(path: Path) -> tuple[list[str], str]:
    """Every group, dataset and attribute name of an HDF5 file, and the attribute values as text."""
    names: list[str] = []
    values: list[str] = []

    def visit(name: str, obj) -> None:
        names.append(name)
        names.extend(f"{name}@{k}" for k in obj.attrs)
        values.extend(repr(v) for v in obj.attrs.values())

    with h5py.File(path, "r") as f:
        names.extend(f"@{k}" for k in f.attrs)
        values.extend(repr(v) for v in f.attrs.values())
        f.visititems(visit)
    return names, "\n".join(names + values).lower()


def test_the_session_file_holds_no_scar(files):
    d, _ = files
    names, text = _contents(d / "scar.h5")
    for word in ("scar", "inclusion", "ellipse", "effect", "outline", "truth"):
        assert word not in text, word
    # the healthy and the scar session hold the same groups, datasets and attributes
    assert names == _contents(d / "healthy.h5")[0]


def test_the_healthy_session_has_no_inclusion(files):
    d, docs = files
    doc = json.loads((d / "healthy.json").read_text())
    assert doc["healthy"] is True and doc["scar"] is None and doc["effects"] == []
    assert not doc["model"].get("fields")
    assert docs["scar"]["healthy"] is False


def test_the_session_records_like_the_real_record(files):
    """Force and pad displacement along x only (y, z NaN), a 2D track with the tracker's noise."""
    from skinkit.store import open_experiment

    d, _ = files

    with open_experiment(d / "scar.h5") as exp:
        rec = exp.read_record("in_plane_000")
        attrs = exp.track_attrs("in_plane_000")
    for c in ("tip_position", "tip_force"):
        v = getattr(rec, c)
        assert np.isfinite(v[:, 0]).all() and np.isnan(v[:, 1:]).all()
    assert attrs["dimensions"] == 2
    # z not measured: NaN as written, read back as None (the store's JSON attributes), as the import's
    assert attrs["noise_m"][:2] == pytest.approx(list(R.TRACK_SIGMA_M))
    assert attrs["noise_m"][2] is None or math.isnan(attrs["noise_m"][2])


def test_noise_levels_are_the_real_records():
    """Recorded minus true, per channel, against the levels measured on the real record: the force's
    and the tracker's within the χ² interval; the displacement's within 5 % (it is rounded to steps
    of 1.8 σ, so the rounding error is uniform only where the drive sweeps through the steps, not at
    rest or at the turning point)."""
    vs, scar = simulate_scar(6, mesh="shared", workers=1)
    assert scar is not None
    rec, true = vs.recorded["in_plane_000"], vs.noiseless["in_plane_000"]
    ef = rec["tip_force"][:, 0] - true["tip_force"][:, 0]
    assert _sd_accepted(float(np.std(ef, ddof=1)), R.FORCE_SIGMA_N, ef.size)
    ep = rec["tip_position"][:, 0] - true["tip_position"][:, 0]
    assert float(np.std(ep, ddof=1)) == pytest.approx(R.POSITION_SIGMA_M, rel=0.05)
    # the tracker: every point and frame, x and y; z is not measured (0)
    e = rec["points"] - true["points"]
    for j in (0, 1):
        assert _sd_accepted(float(np.std(e[..., j], ddof=1)), R.TRACK_SIGMA_M[j], e[..., j].size)
    assert np.all(rec["points"][..., 2] == 0)
    assert vs.truth["sensors"]["tip_force"]["sigma_n"] == R.FORCE_SIGMA_N


@pytest.mark.skipif(not REAL.is_dir(), reason="the real record is not beside the checkout")
def test_the_levels_are_those_measured_on_the_real_record():
    """The constants are the record's figures to the digits they are written with."""
    got = R.measure_record(REAL)
    assert got["rest_samples"] == [4, 5, 6, 7, 8]
    assert got["force_sigma_n"] == pytest.approx(R.FORCE_SIGMA_N, rel=1e-3)
    assert got["position_sigma_m"] == pytest.approx(R.POSITION_SIGMA_M, rel=1e-3)
    assert got["track_sigma_m"] == pytest.approx(list(R.TRACK_SIGMA_M), rel=1e-3)
    # the whole record's second differences give a lower level, within the 5 samples' 95 % range
    assert 0.5 * R.FORCE_SIGMA_N < got["force_second_difference_n"] < R.FORCE_SIGMA_N


def test_bad_options_are_one_line(tmp_path):
    from tests.core._cli import in_process, one_error

    base = ["lab", "scar-session", "--out", str(tmp_path / "s.h5"), "--truth-out", str(tmp_path / "t.json")]
    one_error(in_process(*base, "--seed", "-1"), "--seed")
    one_error(in_process(*base, "--seed", "x"), "--seed")
    one_error(in_process("lab", "scar-session", "--seed", "1", "--out", str(tmp_path / "s.h5"),
                         "--truth-out", str(tmp_path / "s.h5")), "--truth-out", "must differ")
    one_error(in_process("lab", "scar-session", "--seed", "1", "--out", str(tmp_path / "no" / "s.h5"),
                         "--truth-out", str(tmp_path / "t.json")), "--out")
    (tmp_path / "t.json").write_text("{}")
    one_error(in_process(*base, "--seed", "1"), "--truth-out", "already exists")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.json"]
    with pytest.raises(LabError, match="--seed"):
        make_scar_session(tmp_path / "a.h5", tmp_path / "b.json", -3)


def test_the_command_writes_both_files(tmp_path):
    from tests.core._cli import in_process

    r = in_process("lab", "scar-session", "--seed", "3", "--healthy", "--shared-mesh",
                   "--out", str(tmp_path / "s.h5"), "--truth-out", str(tmp_path / "t.json"))
    assert r.exit_code == 0, r.output
    assert "healthy (no scar)" in r.stdout and "11 frames" in r.stdout
    assert json.loads((tmp_path / "t.json").read_text())["seed"] == 3
