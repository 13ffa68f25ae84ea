"""Pre-stress as the reports show it: one convention (λ1 ≥ λ2, θ of λ1 in degrees, folded into
(−90°, 90°]) for any of the fitter's equivalent ``(l1, l2, angle)``; the raw values untouched."""

from __future__ import annotations

import math

import pytest

from skinkit.gap.sentences import display_parameters, parameter_text, prestress_display


@pytest.mark.parametrize("raw", [(1.10, 1.03, math.radians(20.0)), (1.03, 1.10, math.radians(-70.0)),
                                 (1.10, 1.03, math.radians(200.0)), (1.03, 1.10, math.radians(110.0)),
                                 (1.03, 1.10, math.radians(-250.0))])
def test_equivalent_states_read_the_same(raw):
    l1, l2, deg = prestress_display(*raw)
    assert (round(l1, 2), round(l2, 2)) in ((1.10, 1.03),) and l1 >= l2
    assert deg == pytest.approx(20.0, abs=1e-9)


def test_the_fold_keeps_90_and_turns_minus_90():
    assert prestress_display(1.2, 1.0, math.pi / 2)[2] == pytest.approx(90.0)
    assert prestress_display(1.2, 1.0, -math.pi / 2)[2] == pytest.approx(90.0)
    assert prestress_display(1.2, 1.0, -1e-9)[2] == pytest.approx(0.0, abs=1e-6)


def test_display_parameters_swaps_the_errors_with_their_stretch_and_keeps_the_rest():
    pars = {"c": {"value": 3e3, "se": 10.0, "unit": "Pa"},
            "prestress.l1": {"value": 1.029, "se": 0.004, "unit": "1"},
            "prestress.l2": {"value": 1.102, "se": 0.006, "unit": "1"},
            "prestress.angle": {"value": -1.229, "se": 0.02, "unit": "rad"}, "k1": {"value": 2.0, "se": 0.1}}
    shown = display_parameters(pars)
    assert list(shown) == ["c", "prestress.λ1", "prestress.λ2", "prestress.θ", "k1"]
    assert shown["prestress.λ1"]["value"] == 1.102 and shown["prestress.λ1"]["se"] == 0.006
    assert shown["prestress.λ2"]["value"] == 1.029 and shown["prestress.λ2"]["se"] == 0.004
    assert shown["prestress.θ"]["unit"] == "°"
    assert shown["prestress.θ"]["se"] == pytest.approx(math.degrees(0.02))
    assert pars["prestress.angle"]["value"] == -1.229   # the input is not changed
    text = parameter_text(pars)
    assert "prestress.θ = 19.58" in text and "rad" not in text and "l1" not in text


def test_plain_values_and_no_prestress():
    assert display_parameters({"a": 1.0}) == {"a": 1.0}
    shown = display_parameters({"skin.prestretch.l1": 1.0, "skin.prestretch.l2": 1.2,
                                "skin.prestretch.angle": 0.0})
    assert shown == pytest.approx({"skin.prestretch.λ1": 1.2, "skin.prestretch.λ2": 1.0,
                                   "skin.prestretch.θ": 90.0})


def test_the_verdict_warns_of_the_parameters_the_models_mesh_cannot_render():
    """The verdict warns of the final model's parameters over the resolution limit, the worst
    first (one only the refined mesh sees, null in JSON, said so), and of nothing else."""
    from skinkit.gap.sentences import final_mesh_messages

    err = {"member": "model", "factor": 2, "unknowns": 7395, "unknowns_refined": 50787,
           "resolution": {"skin.E": 0.06, "inclusion.a": 1.15, "inclusion.x": 0.97, "offset.x": 0.0}}
    (warn,) = final_mesh_messages(err)
    assert warn.startswith("Warning: the model's mesh (7,395 unknowns) cannot render")
    assert "inclusion.a (1.1), inclusion.x (0.97) do" in warn and "skin.E" not in warn
    assert "refined 2x (50,787 unknowns) renders them" in warn
    (only,) = final_mesh_messages(dict(err, resolution={"inclusion.y": None, "skin.E": 0.3}))
    assert "inclusion.y (only the refined mesh sees it) does" in only and "skin.E" not in only
    # before JSON the summary holds infinity where JSON writes null
    (inf,) = final_mesh_messages(dict(err, resolution={"inclusion.y": float("inf")}))
    assert "inclusion.y (only the refined mesh sees it) does" in inf
    assert final_mesh_messages(dict(err, resolution={"skin.E": 0.3})) == []
    assert final_mesh_messages(None) == []
