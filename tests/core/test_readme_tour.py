"""The README's tour "From a session to a calibrated model", run as written from a fresh folder.

A virtual session of the small forearm disc, the fit, the prediction of the calibrated model file
with its fields for ParaView, and the FEBio export. Checked afterwards: the calibrated model file
predicts exactly what the input model predicts at the fitted values (1e-10 relative: the values
are written with 17 significant digits); the field series reads back in meshio and pyvista with
the displacement, strain and stress arrays; the FEBio file, read back by plain XML parsing, holds
the fitted values in FEBio's conventions (both uncoupled neo-Hookean layers as Mooney–Rivlin with
c1 = μ/2, c2 = 0 and k the bulk modulus, the subdermal layer's μ and K from its E and ν; MPa).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

# one worker runs the tour (a module fixture of minutes) and every test on it
pytestmark = [pytest.mark.needs_plugins, pytest.mark.xdist_group("readme_tour")]

ROOT = Path(__file__).resolve().parents[2]
RTOL = 1e-10


def _tour_commands() -> list[list[str]]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = re.search(r"## From a session to a calibrated model\n.*?```sh\n(.*?)```", text, re.S)
    assert block, "the README has no tour 'From a session to a calibrated model'"
    lines = [ln.split("  #")[0].strip() for ln in block.group(1).splitlines()]
    return [shlex.split(ln) for ln in lines if ln]


@pytest.fixture(scope="module")
def tour(tmp_path_factory) -> Path:
    """The tour's folder after its commands ran there, as written (``skinkit`` from this venv;
    ``docs/models`` reached through a link, as from the checkout's root)."""
    d = tmp_path_factory.mktemp("tour")
    (d / "docs").mkdir()
    (d / "docs" / "models").symlink_to(ROOT / "docs" / "models")
    exe = Path(sys.executable).with_name("skinkit")
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    for cmd in _tour_commands():
        assert cmd[0] == "skinkit", cmd
        r = subprocess.run([str(exe), *cmd[1:]], cwd=d, env=env, capture_output=True, text=True,
                           timeout=900)
        assert r.returncode == 0, (cmd, r.stdout[-2000:], r.stderr[-2000:])
    return d


def test_the_calibrated_model_predicts_as_the_fit(tour):
    from skinkit.forward import load, read_observations

    fit = json.loads((tour / "tour-fit" / "fit.json").read_text())
    values = {n: p["value"] for n, p in fit["parameters"].items() if p["free"]}
    assert set(values) == {"skin.mu", "subdermal.E"}
    obs = read_observations(tour / "tour.h5")
    with load(tour / "docs" / "models" / "forearm_small.toml", workers=1) as model:
        a = model.predict(model.parameters().with_values(values), obs)
    with load(tour / "tour-fit" / "model.toml", workers=1) as model:
        assert {n: model.parameters()[n] for n in values} == values
        b = model.predict(model.parameters(), obs)
    for (p, c, x), (_, _, y) in zip(a.items(), b.items(), strict=True):
        assert np.max(np.abs(x.values - y.values)) <= RTOL * np.max(np.abs(x.values)), (p, c)


def test_the_fit_lands_near_the_truth_with_the_mesh_error_carried(tour):
    """The model's mesh errs by several noise levels against the truth's own mesh; carried as
    noise, it keeps the fit within three standard errors of the truth (one seed: not a coverage
    figure, a check that the intervals are not the noise's alone)."""
    fit = json.loads((tour / "tour-fit" / "fit.json").read_text())
    truth = {p["name"]: p["value"] for p in json.loads((tour / "tour-truth.json").read_text())["parameters"]}
    for name in ("skin.mu", "subdermal.E"):
        p = fit["parameters"][name]
        assert abs(p["value"] - truth[name]) < 3 * p["se"], (name, p, truth[name])


def test_the_fields_read_back_in_meshio_and_pyvista(tour):
    import meshio
    import pyvista as pv

    pvd = tour / "tour-fields" / "normal_indentation.pvd"
    steps = [tour / "tour-fields" / ds.get("file")
             for ds in ET.parse(pvd).getroot().iter("DataSet")]
    assert len(steps) >= 3
    m = meshio.read(steps[-1])
    assert m.cells[0].type == "hexahedron27"
    for name, width in (("displacement", 3), ("green_lagrange_strain", 9), ("cauchy_stress", 9)):
        assert m.point_data[name].shape == (len(m.points), width), name
    # pushed into the skin: the loaded state's top moves down somewhere
    assert m.point_data["displacement"][:, 2].min() < 0
    g = pv.read(str(steps[-1]))
    assert g.n_points == len(m.points)
    np.testing.assert_array_equal(g.point_data["displacement"], m.point_data["displacement"])


def test_the_febio_file_holds_the_fitted_values(tour):
    fit = json.loads((tour / "tour-fit" / "fit.json").read_text())
    mu = fit["parameters"]["skin.mu"]["value"]          # Pa
    E = fit["parameters"]["subdermal.E"]["value"]       # Pa
    root = ET.parse(tour / "tour.feb").getroot()
    assert root.tag == "febio_spec" and root.get("version") == "4.0"
    mats = {m.get("name"): m for m in root.iter("material")}
    skin, sub = mats["skin"], mats["subdermal"]
    assert skin.get("type") == sub.get("type") == "Mooney-Rivlin"   # both uncoupled
    assert float(skin.findtext("c1")) == pytest.approx(mu / 2 * 1e-6, rel=1e-12)
    assert float(skin.findtext("c2")) == 0.0
    assert float(skin.findtext("k")) == pytest.approx(500e3 * 1e-6, rel=1e-12)
    nu = 0.45
    assert float(sub.findtext("c1")) == pytest.approx(E / (2 * (1 + nu)) / 2 * 1e-6, rel=1e-12)
    assert float(sub.findtext("k")) == pytest.approx(E / (3 * (1 - 2 * nu)) * 1e-6, rel=1e-12)
