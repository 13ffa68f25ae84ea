"""``skinkit lab session``: layout, no truth in the session, noise statistics, seeds, bad options.

Noise statistics: for n independent samples of N(0, σ²), (n - 1) s² / σ² is chi-square with
n - 1 degrees of freedom; each test accepts the sample standard deviation within the
two-sided 99.99 % interval of that law (so the suite, with ~60 such checks, fails by chance
less than once in 150 runs), and the sample mean within 4 standard errors of the offset the
truth file declares.
"""

from __future__ import annotations

import json
import math
import os
import re

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.stats import chi2

from skinkit.lab import sensors as S
from skinkit.lab.session import (
    FLIP,
    LabError,
    make_session,
    resample,
    simulate,
    write_session,
)
from skinkit.schemas import ChannelPrediction, Parameter, ParameterSet, Prediction
from skinkit.store import open_experiment

P_TAIL = 1e-4 / 2


class Spring:
    """A stub lumped truth: tip force = k * tip position (skin frame), driven by the position."""

    name = "stub-spring"
    kind = "lumped"
    spec = {"model": {"name": "stub-spring", "kind": "lumped"}}
    K = 321.5

    def parameters(self) -> ParameterSet:
        return ParameterSet([Parameter("lumped.k", self.K, "N/m", 0.0, 1e6)])

    def predict(self, params, obs, sensitivities=False):
        k = params["lumped.k"]
        return Prediction({po.name: {"tip_force": ChannelPrediction(k * po.channels["tip_position"].values)}
                           for po in obs}, {}, {po.name: "tip_position" for po in obs}, {})


class Broken(Spring):
    def predict(self, params, obs, sensitivities=False):
        raise RuntimeError("solver blew up")


#: a tiny FE truth with an effect, two short protocols (10 s, cameras at 0.5 Hz); its parameter
#: values lie off the 1 ms time grid so that the no-truth search cannot hit a sample time
FE_SPEC = {
    "model": {"name": "tiny-truth"},
    "session": {"protocols": ["normal_indentation", "in_plane_090"],
                "parameters": {"normal_indentation": {"periods": 1, "camera_rate": 0.5},
                               "in_plane_090": {"periods": 1, "camera_rate": 0.5}}},
    # one element across the indenter: its truth on its own mesh (17,199 unknowns) is the module's
    # cost; the checks concern the session, not the model's accuracy
    "geometry": {"kind": "disc", "diameter": "20 mm", "indenter_diameter": "4 mm", "n_inner": 1, "n_ring": 2},
    "layers": [
        {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "neo-hookean-ni",
         "parameters": {"mu": "13.7 kPa", "K": "517 kPa"}},
        {"name": "subdermal", "thickness": "3.5 mm", "elements": 1, "law": "neo-hookean-enu",
         "parameters": {"E": "9.3 kPa", "nu": 0.4321}},
    ],
    "boundary": {"fixed": ["outer", "bottom"]},
    "indenter": {"mode": "force"},
    "drive": {"max_step": "2.5 s"},
    "effects": [{"name": "prestress", "l1": 1.0712, "l2": 1.0234, "angle": "17 deg"}],
}


def _check_noise(resid: np.ndarray, sigma: float, offset: float, what: str) -> None:
    """``resid`` (n,): recorded - noiseless truth; its std against ``sigma``, mean against ``offset``."""
    n = resid.size
    s2 = float(np.var(resid, ddof=1))
    lo, hi = chi2.ppf(P_TAIL, n - 1) / (n - 1), chi2.ppf(1 - P_TAIL, n - 1) / (n - 1)
    assert lo <= s2 / sigma**2 <= hi, (what, math.sqrt(s2), sigma, lo, hi)
    assert abs(resid.mean() - offset) <= 4 * sigma / math.sqrt(n), (what, resid.mean(), offset)


def _walk(path):
    """Every (name, dataset values or attribute value) of an HDF5 file."""
    out = []
    with h5py.File(path, "r") as f:
        for k, v in f.attrs.items():
            out.append((f"/@{k}", v))

        def visit(name, obj):
            for k, v in obj.attrs.items():
                out.append((f"{name}@{k}", v))
            if isinstance(obj, h5py.Dataset):
                out.append((name, obj[()]))

        f.visititems(visit)
    return out


def _assert_no_truth(path, truth: dict) -> None:
    """No parameter value (other than 0, 1 and the protocols' own parameter values), no
    effect name and not the model's name anywhere in the session file."""
    proto_values = {float(v) for p in truth["protocols"] for v in p["parameters"].values()
                    if isinstance(v, (int, float))}
    values = [float(p["value"]) for p in truth["parameters"]]
    values = [v for v in values if v not in (0.0, 1.0) and v not in proto_values]
    words = [e["name"] for e in truth["effects"]] + [str(truth["model_file"]["model"]["name"])]
    assert values and words
    for where, v in _walk(path):
        if isinstance(v, (bytes, str)):
            text = v.decode() if isinstance(v, bytes) else v
            for w in words:
                assert w.lower() not in text.lower(), (where, w)
            nums = [float(x) for x in re.findall(r"[-+]?\d+\.?\d*(?:[eE][-+]?\d+)?", text)]
            for x in nums:
                assert not any(math.isclose(x, t, rel_tol=1e-9) for t in values), (where, x)
        else:
            a = np.asarray(v)
            if a.dtype.kind == "f":
                for t in values:
                    assert not np.any(np.isclose(a, t, rtol=1e-9, atol=0.0)), (where, t)


def _same_content(a, b) -> bool:
    """Identical datasets and attributes, the root's creation time aside."""
    wa = [(k, v) for k, v in _walk(a) if k != "/@created"]
    wb = [(k, v) for k, v in _walk(b) if k != "/@created"]
    if [k for k, _ in wa] != [k for k, _ in wb]:
        return False
    return all(np.array_equal(np.asarray(x), np.asarray(y)) for (_, x), (_, y) in zip(wa, wb, strict=True))


# -- the instruments ----------------------------------------------------------------------------
def test_sensor_numbers_match_the_hardware_model():
    hw = pytest.importorskip("skinkit_hardware.params")
    kin = pytest.importorskip("skinkit_hardware.kinematics")
    p = hw.RobotParameters()
    assert S.POT_SIGMA_M == pytest.approx(p.pot_sigma_m, rel=1e-12)
    lsb = (p.adc_span_m[1] - p.adc_span_m[0]) / ((1 << p.adc_bits) - 1)
    assert S.ADC_LSB_M == pytest.approx(lsb, rel=1e-12)
    assert S.ADC_LO_M == p.adc_span_m[0]
    assert S.FT_RESOLUTION_N == p.ft_force_resolution_N
    assert S.LOG_RATE_HZ == p.control_rate_hz / 10  # the device's default decimation
    g = kin.Geometry()
    assert S.HOME_Q_M == g.home_m
    J = kin.jacobian(np.full(3, g.home_m), g)
    assert np.allclose(S.JACOBIAN_HOME, J, atol=1e-8)  # finite-difference Jacobian, step 1 um


def test_sensor_model_declared_levels_and_scaling():
    m1, m3 = S.SensorModel(1.0), S.SensorModel(3.0)
    assert np.allclose(m1.position_sigma(), [1.633e-6, 1.633e-6, 0.9623e-6], rtol=1e-3)
    assert np.allclose(m1.force_sigma(), 5.8e-3 * math.sqrt(0.36 + 1 / 12), rtol=1e-12)
    assert np.allclose(m1.sigma("points"), 7.0e-6 / math.sqrt(3))
    assert np.allclose(m3.position_sigma(), 3 * m1.position_sigma())
    assert m3.profile_sigma == pytest.approx(3 * 6.5e-6)
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError):
            S.SensorModel(bad)


# -- a lumped truth (stub model: no FE solve) -------------------------------------------------------
@pytest.fixture(scope="module")
def lumped(tmp_path_factory):
    d = tmp_path_factory.mktemp("lumped")
    vs = simulate(Spring(), seed=7, protocols="normal_indentation,in_plane_000")
    doc = write_session(vs, d / "s.h5", d / "t.json")
    return vs, doc, d


def test_lumped_session_layout(lumped):
    vs, doc, d = lumped
    with open_experiment(d / "s.h5") as exp:
        assert exp.metadata()["subject"] == "virtual"
        assert exp.record_names() == ["in_plane_000", "normal_indentation"]
        assert exp.track_names() == []          # a lumped truth has no surface to track
        assert exp.profile_names() == ["undeformed"]
        rec = exp.read_record("normal_indentation")
        info = exp.record_info("normal_indentation")
        assert info["complete"] and info["rate_hz"] == S.LOG_RATE_HZ
        assert info["extra"]["session_index"] == 0
    # robot frame: normal indentation goes into the skin (+z) and pushes (+z), peak 1.5 mm
    assert rec.tip_position[:, 2].max() == pytest.approx(1.5e-3, abs=10e-6)
    assert rec.tip_force[:, 2].max() == pytest.approx(Spring.K * 1.5e-3, abs=0.02)
    assert rec.n_samples == 30001
    truth = json.loads((d / "t.json").read_text())
    assert truth == doc and truth["seed"] == 7 and truth["parameters"][0]["value"] == Spring.K
    assert [p["name"] for p in truth["protocols"]] == ["normal_indentation", "in_plane_000"]


def test_lumped_session_holds_no_truth(lumped):
    _, doc, d = lumped
    _assert_no_truth(d / "s.h5", doc)


def test_lumped_noise_matches_declared_levels(lumped):
    vs, doc, _ = lumped
    for name, rec in vs.recorded.items():
        for c in ("tip_position", "tip_force"):
            true = vs.noiseless[name][c] * FLIP
            off = doc["offsets"][name][c]["robot_frame"]
            for j in range(3):
                _check_noise(rec[c][:, j] - true[:, j], vs.sensors.sigma(c)[j], off[j], f"{name}.{c}[{j}]")
        # the force is quantised at the Nano17's resolution before the tare's offset
        q = (rec["tip_force"] - doc["offsets"][name]["tip_force"]["robot_frame"]) / S.FT_RESOLUTION_N
        assert np.allclose(q, np.round(q), atol=1e-6)
    prof = vs.profile - vs.profile_true
    assert np.all(prof[:, :2] == 0)
    _check_noise(prof[:, 2], S.PROFILE_SIGMA_M, 0.0, "profile")


def test_reader_sees_the_declared_noise(lumped):
    from skinkit.forward import read_observations

    vs, _, d = lumped
    obs = read_observations(d / "s.h5")
    assert obs.names == ["normal_indentation", "in_plane_000"]  # session order, not alphabetical
    for c in ("tip_position", "tip_force"):
        ch = obs["normal_indentation"].channels[c]
        # the reader's rest-segment estimate (>= 50 samples) agrees to its own sampling error
        assert np.allclose(ch.noise, vs.sensors.sigma(c), rtol=0.25), (c, ch.noise)


def test_same_seed_same_file_other_seed_other_noise(tmp_path):
    a = make_session(Spring(), tmp_path / "a.h5", tmp_path / "a.json", 11, protocols="normal_indentation")
    make_session(Spring(), tmp_path / "b.h5", tmp_path / "b.json", 11, protocols="normal_indentation")
    c = make_session(Spring(), tmp_path / "c.h5", tmp_path / "c.json", 12, protocols="normal_indentation")
    assert _same_content(tmp_path / "a.h5", tmp_path / "b.h5")
    assert not _same_content(tmp_path / "a.h5", tmp_path / "c.h5")
    with open_experiment(tmp_path / "a.h5") as ea, open_experiment(tmp_path / "c.h5") as ec:
        ra, rc = ea.read_record("normal_indentation"), ec.read_record("normal_indentation")
    assert np.array_equal(ra.time_s, rc.time_s)
    assert not np.array_equal(ra.tip_force, rc.tip_force)
    assert a["offsets"] != c["offsets"]


def test_noise_scale_scales_every_imperfection():
    """Every declared level x4, and the recorded residuals with it (chi-square bound as above)."""
    big = simulate(Spring(), 3, "normal_indentation", noise_scale=4.0)
    assert big.truth["noise_scale"] == 4.0
    rec = big.recorded["normal_indentation"]
    for c in ("tip_position", "tip_force"):
        res = rec[c] - big.noiseless["normal_indentation"][c] * FLIP
        off = big.truth["offsets"]["normal_indentation"][c]["robot_frame"]
        for j in range(3):
            _check_noise(res[:, j], 4 * S.SensorModel(1.0).sigma(c)[j], off[j], f"{c}[{j}] x4")


@pytest.mark.parametrize("kwargs, message", [
    ({"protocols": "normal_indentation,nope"}, r"--protocols: unknown protocol\(s\) nope"),
    ({"protocols": "normal_indentation,normal_indentation"}, "named twice"),
    ({"noise_scale": 0.0}, "--noise-scale: must be positive"),
    ({"noise_scale": float("nan")}, "--noise-scale"),
    ({"noise_scale": "abc"}, "--noise-scale: expected a positive number"),
    ({"images": True}, "--images: .* not available yet"),
])
def test_bad_options_one_line_and_nothing_written(tmp_path, kwargs, message):
    with pytest.raises(LabError, match=message) as exc:
        make_session(Spring(), tmp_path / "s.h5", tmp_path / "t.json", 1, **kwargs)
    assert "\n" not in str(exc.value)
    assert list(tmp_path.iterdir()) == []


def test_bad_paths_and_failing_truth_leave_nothing(tmp_path):
    with pytest.raises(LabError, match="no such directory"):
        make_session(Spring(), tmp_path / "no" / "s.h5", tmp_path / "t.json", 1)
    (tmp_path / "old.h5").write_text("keep me")
    with pytest.raises(LabError, match="already exists"):
        make_session(Spring(), tmp_path / "old.h5", tmp_path / "t.json", 1)
    assert (tmp_path / "old.h5").read_text() == "keep me"
    with pytest.raises(LabError, match="must differ"):
        make_session(Spring(), tmp_path / "x.h5", tmp_path / "x.h5", 1)
    with pytest.raises(RuntimeError, match="blew up"):
        make_session(Broken(), tmp_path / "s.h5", tmp_path / "t.json", 1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.h5"]


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root writes into read-only directories")
def test_read_only_directory(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(LabError, match="not writable"):
            make_session(Spring(), ro / "s.h5", tmp_path / "t.json", 1)
    finally:
        ro.chmod(0o700)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ro"] and list(ro.iterdir()) == []


def test_cli_bad_options_exit_2_with_one_line(tmp_path):
    from skinkit.cli import cli

    model = tmp_path / "m.toml"
    model.write_text('[model]\nname = "m"\n')
    runner = CliRunner()
    base = ["lab", "session", str(model), "--out", str(tmp_path / "s.h5"),
            "--truth-out", str(tmp_path / "t.json"), "--seed", "1"]
    for extra, msg in ((["--protocols", "nope"], "unknown protocol"),
                       (["--noise-scale", "-2"], "--noise-scale"), (["--images"], "--images")):
        r = runner.invoke(cli, base + extra)
        assert r.exit_code == 2, r.output
        lines = [ln for ln in r.output.splitlines() if ln.strip()]
        assert len(lines) == 1 and msg in lines[0], r.output
    r = runner.invoke(cli, ["lab", "session", str(tmp_path / "none.toml"), "--out", str(tmp_path / "s.h5"),
                            "--truth-out", str(tmp_path / "t.json"), "--seed", "1"])
    assert r.exit_code == 2 and "no such model file" in r.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.toml"]


# -- a tiny finite-element truth ----------------------------------------------------------------
#: one worker runs every test of the module's finite-element truth (its fixture is a minute of solves)
_FE_GROUP = pytest.mark.xdist_group("lab_fe")


@pytest.fixture(scope="module")
def fe(tmp_path_factory):
    pytest.importorskip("skinkit_plugins")
    d = tmp_path_factory.mktemp("fe")
    vs = simulate(FE_SPEC, seed=1, workers=1)
    doc = write_session(vs, d / "s.h5", d / "t.json")
    return vs, doc, d


@pytest.mark.needs_plugins
@_FE_GROUP
def test_fe_session_layout(fe):
    vs, doc, d = fe
    from skinkit.forward import read_observations

    with open_experiment(d / "s.h5") as exp:
        assert exp.record_names() == ["in_plane_090", "normal_indentation"]
        assert exp.track_names() == ["in_plane_090", "normal_indentation"]
        assert exp.profile_names() == ["undeformed"]
        tr = exp.read_track("normal_indentation")
        attrs = exp.track_attrs("normal_indentation")
        rec = exp.read_record("normal_indentation")
    assert attrs["noise_m"] == pytest.approx([S.TRACK_SIGMA_M] * 3)
    assert tr.points.shape == (doc["protocols"][0]["points"], 6, 3) and 100 <= tr.n_points <= 300
    assert np.array_equal(tr.time_s, np.arange(6) * 2.0)
    r = np.hypot(tr.points[:, 0, 0], tr.points[:, 0, 1])
    assert r.min() > 2.9e-3 and r.max() < 8.1e-3  # around the 4 mm probe, out to 8 mm
    # the trajectory drove the truth: into the skin in the robot frame; the skin pushes back
    assert rec.tip_position[:, 2].max() == pytest.approx(1.5e-3, abs=10e-6)
    assert rec.tip_force[:, 2].max() > 20 * vs.sensors.force_sigma()[2]
    # the points under a normal indentation move down (skin frame z out of the skin)
    assert np.nanmean(tr.points[:, 3, 2] - tr.points[:, 0, 2]) < -50e-6
    assert doc["surface"]["curved"] and doc["effects"][0]["name"] == "prestress"
    assert {p["name"] for p in doc["parameters"]} >= {"skin.mu", "prestress.l1"}
    obs = read_observations(d / "s.h5")
    assert obs["in_plane_090"].channels["points"].noise_source == "tracker"


@pytest.mark.needs_plugins
@_FE_GROUP
def test_fe_session_holds_no_truth(fe):
    _, doc, d = fe
    _assert_no_truth(d / "s.h5", doc)


@pytest.mark.needs_plugins
@_FE_GROUP
def test_fe_noise_matches_declared_levels(fe):
    vs, doc, _ = fe
    for name, rec in vs.recorded.items():
        for c in ("tip_position", "tip_force"):
            true = vs.noiseless[name][c] * FLIP
            off = doc["offsets"][name][c]["robot_frame"]
            for j in range(3):
                _check_noise(rec[c][:, j] - true[:, j], vs.sensors.sigma(c)[j], off[j], f"{name}.{c}[{j}]")
        res = rec["points"] - vs.noiseless[name]["points"]
        for j in range(3):
            _check_noise(res[..., j].ravel(), S.TRACK_SIGMA_M, 0.0, f"{name}.points[{j}]")


@pytest.mark.needs_plugins
@_FE_GROUP
def test_fe_same_seed_same_file_other_seed_other_noise(fe, tmp_path):
    vs, _, d = fe
    write_session(resample(vs, 1), tmp_path / "a.h5", tmp_path / "a.json")
    write_session(resample(vs, 2), tmp_path / "b.h5", tmp_path / "b.json")
    assert _same_content(d / "s.h5", tmp_path / "a.h5")
    assert not _same_content(d / "s.h5", tmp_path / "b.h5")
    with open_experiment(tmp_path / "a.h5") as ea, open_experiment(tmp_path / "b.h5") as eb:
        assert not np.array_equal(ea.read_track("in_plane_090").points, eb.read_track("in_plane_090").points)


@pytest.mark.needs_plugins
@_FE_GROUP
def test_fe_truth_on_a_mesh_of_its_own(fe):
    """The truth file states both meshes: the truth's >= 8x the model's unknowns, its own gradings,
    and its own error, bounded from the same truth on the model's mesh, per channel against the
    noise (the model's mesh error is f/(f − 1) = 2 times the truth's bound at factor 2)."""
    from skinkit.lab.truth_mesh import mesh_figures

    _, doc, _ = fe
    mesh = doc["mesh"]
    assert mesh["mode"] == "own" and mesh["factor"] == 2
    assert mesh["truth_unknowns"] >= 8 * mesh["model_unknowns"]
    assert mesh["model_unknowns"] == mesh_figures(FE_SPEC)["unknowns"]
    model_g = FE_SPEC["geometry"]
    for key, value in mesh["gradings"].items():
        assert value != model_g.get(key, 1.6 if key == "grading" else 1.0), key
    disc = mesh["discretisation"]
    assert {"tip_force", "points"} <= set(disc)
    for row in disc.values():
        assert row["model_rms"] == pytest.approx(2 * row["truth_rms"])
        assert row["truth_over_noise"] == pytest.approx(row["truth_rms"] / row["noise"])


@pytest.mark.needs_plugins
def test_shared_mesh_keeps_the_models_mesh(tmp_path):
    """``--shared-mesh``: the truth on its model file's own mesh, said on the command line."""
    from skinkit.cli import cli

    model = tmp_path / "m.toml"
    model.write_text('''[model]
name = "tiny-truth"
[geometry]
kind = "disc"
diameter = "20 mm"
indenter_diameter = "4 mm"
n_inner = 2
n_ring = 2
[[layers]]
name = "skin"
thickness = "1.5 mm"
elements = 1
law = "neo-hookean-ni"
parameters = { mu = "13.7 kPa", K = "517 kPa" }
[[layers]]
name = "subdermal"
thickness = "3.5 mm"
elements = 1
law = "neo-hookean-enu"
parameters = { E = "9.3 kPa", nu = 0.4321 }
[boundary]
fixed = ["outer", "bottom"]
[indenter]
mode = "force"
[drive]
max_step = "2.5 s"
''')
    r = CliRunner().invoke(cli, ["lab", "session", str(model), "--out", str(tmp_path / "s.h5"),
                                 "--truth-out", str(tmp_path / "t.json"), "--seed", "0",
                                 "--protocols", "normal_indentation", "--shared-mesh"])
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "t.json").read_text())
    assert doc["mesh"]["mode"] == "shared"
    assert doc["mesh"]["truth_unknowns"] == doc["mesh"]["model_unknowns"]
    assert "truth mesh: shared" in r.output
