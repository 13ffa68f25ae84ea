"""The calibrated model is an output: ``skinkit fit`` and ``skinkit gap diagnose`` write
``model.toml`` into --out, a model file that loads like any other and predicts the session exactly
as the fit did; its ``[calibration]`` table records the session and the 95 % intervals."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli as main
from skinkit.forward import load, read_description, read_observations

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

pytestmark = pytest.mark.needs_plugins

LUMPED = Path(__file__).resolve().parents[2] / "docs" / "models" / "extension_relaxation_lumped.toml"
#: the truth: the lumped extension model with a relaxation term its model file lacks
TRUTH_EFFECT = '\n[[effects]]\nname = "viscoelastic"\ng1 = 0.4\ntau1 = 2.0\n'
#: predictions read back from a file written with 17 significant digits: equal to rounding
RTOL = 1e-10


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    """A virtual-lab session (one 30 s in-plane protocol along x) of the lumped model with a
    viscoelastic term: a second or two to make."""
    d = tmp_path_factory.mktemp("calibrated")
    (d / "truth.toml").write_text(LUMPED.read_text() + TRUTH_EFFECT)
    r = CliRunner().invoke(main, ["lab", "session", str(d / "truth.toml"), "--out", str(d / "s.h5"),
                                  "--truth-out", str(d / "t.json"), "--seed", "3",
                                  "--protocols", "in_plane_000"])
    assert r.exit_code == 0, r.output
    return d / "s.h5"


def _predict_file(model_file: Path, session: Path, out: Path) -> dict[str, np.ndarray]:
    """``skinkit predict MODEL SESSION --out``: channel -> predicted values, read from its HDF5."""
    r = CliRunner().invoke(main, ["predict", str(model_file), str(session), "--out", str(out), "--json"])
    assert r.exit_code == 0, r.output
    with h5py.File(out) as f:
        return {f"{p}/{c}": f[f"{p}/{c}/values"][()] for p in f for c in f[p]}


def _predict_at(spec, values: dict[str, float], session: Path) -> dict[str, np.ndarray]:
    """The original description's prediction at the fitted values, in this process."""
    with load(spec, workers=1) as model:
        pred = model.predict(model.parameters().with_values(values), read_observations(session))
    return {f"{p}/{c}": cp.values for p, c, cp in pred.items()}


def _same(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    assert a.keys() == b.keys() and a
    for k in a:
        scale = float(np.max(np.abs(b[k])))
        assert np.max(np.abs(a[k] - b[k])) <= RTOL * scale, k


def test_fit_writes_the_calibrated_model(session, tmp_path):
    out = tmp_path / "fit"
    r = CliRunner().invoke(main, ["fit", str(LUMPED), str(session), "--out", str(out), "--json"])
    assert r.exit_code == 0, r.output
    fit = json.loads(r.stdout)
    path = out / "model.toml"
    assert fit["calibrated_model"] == str(path)
    values = {n: p["value"] for n, p in fit["parameters"].items() if p["free"]}

    with load(path, workers=1) as model:    # a model file like any other
        ps = model.parameters()
    assert {n: ps[n] for n in values} == values

    doc = tomllib.loads(path.read_text())
    cal = doc["calibration"]
    assert cal["session"] == str(session.resolve()) and cal["objective"] == "noise"
    assert cal["command"] == "skinkit fit" and cal["skinkit_version"] and cal["date"]
    for n, p in fit["parameters"].items():
        if not p["free"]:
            continue
        c = cal["parameters"][n]
        assert c["value"] == p["value"] and c["unit"] == p["unit"] and c["se"] == p["se"]
        assert c["low"] == pytest.approx(p["value"] - 1.96 * p["se"], rel=1e-12)
        assert c["low"] < c["value"] < c["high"]
    _same(_predict_file(path, session, tmp_path / "p.h5"), _predict_at(LUMPED, values, session))

    # an earlier calibrated model is not replaced silently
    (out / "fit.json").unlink()
    r = CliRunner().invoke(main, ["fit", str(LUMPED), str(session), "--out", str(out), "--name", "again"])
    assert r.exit_code == 2 and "already holds model.toml" in r.output


def test_gap_diagnose_writes_the_model_with_the_added_effect(session, tmp_path):
    out = tmp_path / "gap"
    r = CliRunner().invoke(main, ["gap", "diagnose", str(LUMPED), str(session), "--out", str(out),
                                  "--effects", "viscoelastic,force-drift", "--max-effects", "1", "--json"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.stdout)
    assert rep["named"] == ["viscoelastic"]
    path = out / "model.toml"
    doc = tomllib.loads(path.read_text())
    final = rep["final_parameters"]
    assert doc["effects"] == [{"name": "viscoelastic", "g1": final["viscoelastic.g1"],
                               "tau1": final["viscoelastic.tau1"]}]
    assert doc["calibration"]["effects_added"] == ["viscoelastic"]
    g1 = doc["calibration"]["parameters"]["viscoelastic.g1"]
    assert g1["low"] < 0.4 < g1["high"]     # the truth's relaxation inside its 95 % interval
    spec = read_description(LUMPED)
    spec["effects"] = [{"name": "viscoelastic"}]
    _same(_predict_file(path, session, tmp_path / "p.h5"), _predict_at(spec, final, session))


def test_values_land_in_a_finite_element_description(tmp_path):
    """Law parameters, a pre-stretch, a field: each fitted value is
    written where the loader reads it; a name no entry holds is refused, no file written."""
    from skinkit.errors import SkinkitError
    from skinkit.inverse.calibrated import write_calibrated

    spec = tomllib.loads("""
[model]
name = "tiny"
[geometry]
kind = "block"
size = ["10 mm", "10 mm"]
n = [1, 1]
indenter_diameter = "4 mm"
[[layers]]
name = "skin"
thickness = "2 mm"
elements = 1
law = "neo-hookean-enu"
parameters = { E = "40 kPa", nu = 0.45 }
prestress = { stretch = [1.1, 1.0], angle = 0.0 }
[[fields]]
name = "lump"
kind = "inclusion"
x = 0.0
y = 0.0
radius = "2 mm"
ratio = 2.0
layers = ["skin"]
[boundary]
fixed = ["bottom"]
compliance = { sets = ["bottom"], value = "1 mm/MPa" }
[indenter]
mode = "displacement"
""")
    values = {"skin.E": 12345.678901234567, "skin.prestretch.l2": 1.05, "lump.ratio": 3.25}
    path = write_calibrated(tmp_path, spec, values, {"skin.E": 100.0}, session=tmp_path / "s.h5",
                            objective="noise", command="test")
    with load(path, workers=1) as model:
        ps = model.parameters()
    assert {n: ps[n] for n in values} == values
    cal = tomllib.loads(path.read_text())["calibration"]["parameters"]
    assert cal["skin.E"]["unit"] == "Pa" and cal["lump.ratio"]["interval"] == "undetermined"
    with pytest.raises(SkinkitError, match="nowhere.x"):
        write_calibrated(tmp_path / "no", spec, {"nowhere.x": 1.0}, {}, session="s.h5", objective="noise",
                         command="test")
    assert not (tmp_path / "no" / "model.toml").exists()


def test_predict_of_the_calibrated_model_reports_the_fits_chi2_per_dof(session, tmp_path):
    """χ² / (samples − fitted parameters) of the calibrated file's prediction is the fit's own
    figure (the same residual at the same values: equal to rounding); a model file without a
    [calibration] table reports no such figure."""
    out = tmp_path / "fit"
    # a name of its own: the module's session may already hold the other tests' fits
    r = CliRunner().invoke(main, ["fit", str(LUMPED), str(session), "--out", str(out), "--json",
                                  "--name", "chi2-per-dof"])
    assert r.exit_code == 0, r.output
    fit = json.loads(r.stdout)
    r = CliRunner().invoke(main, ["predict", str(out / "model.toml"), str(session), "--json"])
    assert r.exit_code == 0, r.output
    pred = json.loads(r.stdout)
    n_free = sum(1 for p in fit["parameters"].values() if p["free"])
    assert pred["calibration"]["fitted_parameters"] == n_free
    assert pred["chi2_per_dof"] == pytest.approx(fit["chi2_per_dof"], rel=1e-9)
    r = CliRunner().invoke(main, ["predict", str(LUMPED), str(session), "--json"])
    assert "chi2_per_dof" not in json.loads(r.stdout)
