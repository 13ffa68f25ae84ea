"""The diagnosis's choice between a region candidate refitted from its scan's best place and from
its second place (:func:`skinkit.gap.scan_step.rival_refit`): the lower χ² is kept, two refits
within the AIC margin are reported as not separable, and a refit that fails leaves the other.

The refits are stand-ins that return what a refit returns (a state with its χ², the effect's table
and the fit's evaluation count): the choice is arithmetic on those, tested here apart from the
finite-element refits the whole diagnosis makes (``skinkit bench scar``)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from skinkit.errors import SkinkitError
from skinkit.gap.candidates import AIC_MARGIN
from skinkit.gap.scan_step import Rival, rival_refit
from skinkit.gap.score import ScoreTest

pytestmark = pytest.mark.needs_plugins


def run() -> SimpleNamespace:
    return SimpleNamespace(say=lambda _m: None, n_forward=0, warnings=[], held_regions={}, held_forms={})


def state(chi2: float, x: float, ratio: float) -> dict:
    return {"chi2": chi2, "table": {"name": "inclusion", "x": x, "y": 0.0, "a": 4e-3, "b": 3e-3,
                                    "angle": 0.3, "ratio": ratio},
            "result": SimpleNamespace(n_forward=7)}


TEST = ScoreTest("inclusion", 100.0, 1, 1e-20, math.log(1e-20), {"inclusion.ratio": -0.8}, None,
                 ["inclusion.ratio"], {}, [], {}, False)


def rival(entry: dict) -> Rival:
    entry["rival"] = {"x_m": 6e-3}
    return Rival({"inclusion.x": 6e-3, "inclusion.y": 0.0, "inclusion.radius": 6e-3}, "ellipse",
                 {"inclusion.x": 6e-3, "inclusion.a": 8e-3}, {"inclusion.ratio": 0.9}, entry)


def test_the_lower_chi2_is_kept_and_the_second_place_starts_on_its_own_side():
    r, scan_entry, entry = run(), {}, {"round": 1}
    seen = {}

    def refit(start, form, test):
        seen.update(start=start, form=form, step=test.step)
        return state(900.0, 8e-3, 5.4)
    kept = rival_refit(r, TEST, state(1000.0, -6e-3, 0.1), rival(scan_entry), entry, refit)
    assert kept["table"]["x"] == 8e-3
    assert seen["step"] == {"inclusion.ratio": 0.9}           # stiffer, as its own score said
    assert seen["form"][0] == "ellipse" and seen["start"]["inclusion.x"] == 6e-3
    rec = entry["rivals"]["inclusion"]
    assert rec["kept"] == "rival" and rec["delta_chi2"] == -100.0 and rec["separable"]
    assert scan_entry["rival"]["refits"] is rec and r.n_forward == 8 and not r.warnings
    assert r.held_regions["inclusion.x"] == 6e-3 and r.held_forms["inclusion"][0] == "ellipse"


def test_two_places_within_the_aic_margin_are_not_separable():
    r, entry = run(), {"round": 1}
    best = state(1000.0, -6e-3, 0.1)
    kept = rival_refit(r, TEST, best, rival({}), entry,
                       lambda *_: state(1000.0 + 0.5 * AIC_MARGIN, 8e-3, 5.4))
    assert kept is best and entry["rivals"]["inclusion"]["separable"] is False
    (w,) = r.warnings
    assert w["kind"] == "region-not-separable"
    assert "x -6 mm" in w["message"] and "x 8 mm" in w["message"] and "angle 17.2 deg" in w["message"]


def test_a_failed_refit_leaves_the_other():
    def fails(*_):
        raise SkinkitError("gave up at load t = 4")
    r, entry = run(), {"round": 1}
    best = state(1000.0, -6e-3, 0.1)
    assert rival_refit(r, TEST, best, rival({}), entry, fails) is best
    assert "inclusion (second place)" in entry["refit_failures"]
    r, entry = run(), {"round": 1}
    kept = rival_refit(r, TEST, None, rival({}), entry, lambda *_: state(900.0, 8e-3, 5.4))
    assert kept["table"]["x"] == 8e-3 and entry["rivals"]["inclusion"]["delta_chi2"] is None
    assert rival_refit(r, TEST, None, rival({}), {"round": 1}, fails) is None
