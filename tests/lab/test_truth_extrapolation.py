"""The virtual lab's truth extrapolated to a vanishing element size from three of its own meshes."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit.lab.truth_extrapolation import (
    ORDER_MAX,
    ORDER_MIN,
    extrapolate,
    members,
    observed_order,
)
from skinkit.lab.truth_mesh import TruthMeshError, check_mode, own_gradings


def _sequence(p: float, ks=(1, 2, 3), seed: int = 0):
    """Members following the asymptotic error model exactly: y_k = y∞ + C k^−p."""
    rng = np.random.default_rng(seed)
    y_inf = rng.normal(size=(40, 3))
    C = rng.normal(size=(40, 3))
    return y_inf, C, {k: {"p": {"points": y_inf + C * float(k) ** -p,
                                 "tip_position": np.arange(5.0)}} for k in ks}


@pytest.mark.parametrize("p", [0.8, 1.4, 2.0, 3.0])
def test_the_order_and_limit_of_an_asymptotic_sequence_are_recovered(p):
    """On y_k = y∞ + C k^−p the observed order is p and the limit y∞ (to round-off), the limit's
    estimated error nil and the correction the finest member's own error, C 3^−p."""
    y_inf, C, solved = _sequence(p)
    got, clipped = observed_order(solved[1]["p"]["points"], solved[2]["p"]["points"],
                                  solved[3]["p"]["points"], (1, 2, 3))
    assert got == pytest.approx(p, abs=1e-5) and not clipped
    values, rep = extrapolate(solved, (1, 2, 3), {"points": 0.5})
    np.testing.assert_allclose(values["p"]["points"], y_inf, atol=1e-8)
    row = rep["channels"]["points"]
    assert row["truth_rms"] == pytest.approx(0.0, abs=1e-8)
    assert row["correction_rms"] == pytest.approx(np.sqrt(np.mean((C * 3.0 ** -p) ** 2)), rel=1e-6)
    assert row["correction_over_noise"] == pytest.approx(row["correction_rms"] / 0.5)
    # a drive channel, the same on every member, is kept as solved and not reported
    np.testing.assert_array_equal(values["p"]["tip_position"], np.arange(5.0))
    assert "tip_position" not in rep["channels"]


def test_tracked_points_are_extrapolated_in_their_motion():
    """Points ``(P, F, 3)``: each member embeds them with a static offset of its own (a curved top
    approximated per mesh) that does not converge; their motion since the first frame does, at
    order 2. The order and the limit of the motion are recovered, the first frame is the finest
    member's, and the offsets are not counted as error."""
    rng = np.random.default_rng(5)
    ref = rng.normal(size=(20, 1, 3))
    motion, C = rng.normal(size=(2, 20, 4, 3))
    motion[:, 0] = C[:, 0] = 0.0
    solved = {k: {"p": {"points": ref + 1e-3 * rng.normal(size=(20, 1, 3)) + motion + C * float(k) ** -2}}
              for k in (1, 2, 3)}
    values, rep = extrapolate(solved, (1, 2, 3), {"points": 1.0})
    assert rep["orders"]["p/points"]["order"] == pytest.approx(2.0, abs=1e-5)
    got = values["p"]["points"]
    np.testing.assert_array_equal(got[:, 0], solved[3]["p"]["points"][:, 0])
    np.testing.assert_allclose(got - got[:, :1], motion, atol=1e-8)


def test_other_members_than_one_two_three():
    """Non-integer ratios (2, 3, 4): the generalised form still recovers order and limit."""
    y_inf, _, solved = _sequence(1.3, ks=(2, 3, 4))
    values, rep = extrapolate(solved, (2, 3, 4), {"points": 1.0})
    np.testing.assert_allclose(values["p"]["points"], y_inf, atol=1e-8)
    assert rep["orders"]["p/points"]["order"] == pytest.approx(1.3, abs=1e-5)


@pytest.mark.parametrize("second", [1.0, 0.3, 0.1])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_an_error_whose_shape_changes_is_estimated_not_hidden(second, seed):
    """A second error term of order 2.5 beside one of order 1 (a coarse member before the
    asymptotic range; ``second``: its size against the first's on the coarsest member) is what
    the single-order form misses: the limit's error is then non-zero, at most its estimate, and
    at most 0.7 of the finest member's error (a tenth when the second term is small)."""
    rng = np.random.default_rng(seed)
    y_inf, C1, C2 = rng.normal(size=(3, 200))
    solved = {k: {"p": {"f": y_inf + C1 * k ** -1.0 + second * C2 * k ** -2.5}} for k in (1, 2, 3)}
    values, rep = extrapolate(solved, (1, 2, 3), {"f": 1.0})
    true_err = np.sqrt(np.mean((values["p"]["f"] - y_inf) ** 2))
    finest_err = np.sqrt(np.mean((solved[3]["p"]["f"] - y_inf) ** 2))
    est = rep["channels"]["f"]["truth_rms"]
    assert 0 < true_err <= est
    assert true_err < (0.7 if second == 1.0 else 0.25 if second == 0.3 else 0.1) * finest_err


def test_members_outside_the_asymptotic_range_are_not_extrapolated():
    """Changes that do not shrink (the second as large as the first): a limit at the lowest
    accepted order would amplify the last change several-fold, so the finest member is kept, its
    error stated as an order 1 would make it (2 |y3 − y2| for members 1, 2, 3), and said."""
    y = np.linspace(0.0, 1.0, 30)
    solved = {k: {"p": {"f": y + 1e-3 * k}} for k in (1, 2, 3)}
    values, rep = extrapolate(solved, (1, 2, 3), {"f": 1e-3})
    np.testing.assert_array_equal(values["p"]["f"], solved[3]["p"]["f"])
    assert rep["orders"]["p/f"] == {"order": ORDER_MIN, "clipped": True, "extrapolated": False}
    row = rep["channels"]["f"]
    assert row["correction_rms"] == 0.0
    assert row["truth_rms"] == pytest.approx(2e-3) and row["truth_over_noise"] == pytest.approx(2.0)


def test_a_sequence_outside_the_asymptotic_range_is_clipped_and_said():
    """Changes that grow with refinement (no convergence): the order takes the nearer end and the
    report says it was clipped; equal members (nothing to extrapolate) give no order."""
    y = np.ones(10)
    p, clipped = observed_order(y, y + 1.0, y + 3.0, (1, 2, 3))
    assert p == ORDER_MIN and clipped
    p, clipped = observed_order(y, y + 1.0, y + 1.0 + 1e-9, (1, 2, 3))
    assert p == ORDER_MAX and clipped
    assert observed_order(y, y, y, (1, 2, 3)) == (None, False)


def test_the_family_scales_every_count_and_moves_every_grading():
    spec = {"geometry": {"kind": "disc", "n_inner": 1, "n_ring": 2, "grading": 1.6},
            "layers": [{"name": "a", "elements": 1}, {"name": "b", "elements": 2}]}
    s = own_gradings(spec, 3)
    g = s["geometry"]
    assert (g["n_inner"], g["n_ring"]) == (3, 6)
    assert [L["elements"] for L in s["layers"]] == [3, 6]
    assert g["grading"] != 1.6 and g["inner_grading"] != 1.0 and g["layer_grading"] != 1.0
    # the members differ only in size: every grading is the same on each
    g1 = own_gradings(spec, 1)["geometry"]
    assert all(g1[k] == g[k] for k in g if k.endswith("grading"))
    assert spec["geometry"]["n_inner"] == 1   # the description itself is left alone


def test_an_extrapolated_truth_needs_three_members():
    with pytest.raises(TruthMeshError, match="at least 3"):
        members(2)
    with pytest.raises(TruthMeshError, match=">= 3"):
        check_mode("extrapolated", 2)
    assert members(4) == (2, 3, 4)
    check_mode("own", 2)


#: one element through one layer, one short indentation: three members of 441, 2,535 and 7,581
#: unknowns, a few seconds
TINY = {
    "model": {"name": "tiny-extrapolated"},
    "session": {"protocols": ["normal_indentation"],
                "parameters": {"normal_indentation": {"periods": 1, "camera_rate": 0.5}}},
    "geometry": {"kind": "disc", "diameter": "20 mm", "indenter_diameter": "4 mm", "n_inner": 1, "n_ring": 1},
    "layers": [{"name": "skin", "thickness": "3 mm", "elements": 1, "law": "neo-hookean-enu",
                "parameters": {"E": "30 kPa", "nu": 0.45}}],
    "boundary": {"fixed": ["outer", "bottom"]},
    "indenter": {"mode": "displacement"},
    "drive": {"max_step": "2.5 s"},
}


@pytest.mark.needs_plugins
def test_the_lab_solves_three_members_and_records_their_limit():
    """``mesh="extrapolated"``: the truth file names the three members, their unknowns and observed
    orders; the tip force's limit moves from the finest member by the correction it reports, and
    its own estimated error is below that correction (the extrapolation helps where it converges)."""
    import copy

    from skinkit.lab.session import simulate
    from skinkit.lab.truth_mesh import mesh_figures

    vs = simulate(copy.deepcopy(TINY), seed=0, mesh="extrapolated", mesh_factor=3, workers=1)
    mesh = vs.truth["mesh"]
    assert mesh["mode"] == "extrapolated" and mesh["factor"] == 3
    ext = mesh["extrapolation"]
    assert ext["members"] == [1, 2, 3]
    assert ext["member_unknowns"] == [mesh_figures(own_gradings(TINY, k))["unknowns"] for k in (1, 2, 3)]
    assert mesh["truth_unknowns"] == ext["member_unknowns"][-1]
    assert mesh["model_unknowns"] == mesh_figures(TINY)["unknowns"]
    assert set(ext["orders"]) == {"normal_indentation/tip_force", "normal_indentation/points"}
    force = mesh["discretisation"]["tip_force"]
    assert 0 < force["truth_rms"] < force["correction_rms"] < force["model_rms"]
    assert force["truth_over_noise"] == pytest.approx(force["truth_rms"] / force["noise"])


TINY_TOML = """
[model]
name = "tiny-extrapolated"
[session]
protocols = ["normal_indentation"]
parameters = { normal_indentation = { periods = 1, camera_rate = 0.5 } }
[geometry]
kind = "disc"
diameter = "20 mm"
indenter_diameter = "4 mm"
n_inner = 1
n_ring = 1
[[layers]]
name = "skin"
thickness = "3 mm"
elements = 1
law = "neo-hookean-enu"
parameters = { E = "30 kPa", nu = 0.45 }
[boundary]
fixed = ["outer", "bottom"]
[indenter]
mode = "displacement"
[drive]
max_step = "2.5 s"
"""


@pytest.mark.needs_plugins
def test_lab_session_extrapolated_truth_says_so(tmp_path):
    """``skinkit lab session --extrapolated-truth``: the truth file's mode and members, and the
    command's lines name the members and the truth's *estimated* error; with ``--shared-mesh``
    it is refused naming both options, nothing written."""
    import json

    from click.testing import CliRunner

    from skinkit.cli import cli

    model = tmp_path / "tiny.toml"
    model.write_text(TINY_TOML)
    args = ["lab", "session", str(model), "--out", str(tmp_path / "s.h5"), "--truth-out",
            str(tmp_path / "t.json"), "--seed", "0"]
    r = CliRunner().invoke(cli, [*args, "--extrapolated-truth", "--shared-mesh"])
    assert r.exit_code == 2 and "--extrapolated-truth" in r.output and "--shared-mesh" in r.output
    assert not (tmp_path / "t.json").exists()
    r = CliRunner().invoke(cli, [*args, "--extrapolated-truth"])
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "t.json").read_text())
    assert doc["mesh"]["mode"] == "extrapolated" and doc["mesh"]["extrapolation"]["members"] == [1, 2, 3]
    assert "truth mesh: extrapolated" in r.output
    assert "extrapolated from 441, 2,535, 7,581 unknowns" in r.output
    assert "own error estimated at" in r.output
