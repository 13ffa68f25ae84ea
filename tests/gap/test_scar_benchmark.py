"""The scar benchmark's scoring and bookkeeping (``skinkit bench scar``, :mod:`skinkit.bench.scar`).

A real case is a twenty-minute diagnosis, run by the benchmark itself; here: the centre is
scored inside the true outline exactly within one semi-axis along each of the scar's axes,
whatever its angle; the ratio is covered exactly within 1.96 standard errors; a report without
the effect scores nothing found; the journal keeps finished cases so a second run runs none;
no case at all is refused in one line.
"""

from __future__ import annotations

import math

import pytest
from click.testing import CliRunner

from skinkit.bench import scar as S
from skinkit.cli import cli

SCAR = {"x_m": 4e-3, "y_m": -1e-3, "a_m": 5e-3, "b_m": 2e-3, "angle_rad": math.radians(30.0),
        "ratio": 6.0}


def _along(axis: str, frac: float) -> tuple[float, float]:
    """The point ``frac`` semi-axes from the centre along the scar's ``a`` or ``b`` axis."""
    c, s = math.cos(SCAR["angle_rad"]), math.sin(SCAR["angle_rad"])
    if axis == "a":
        d = (frac * SCAR["a_m"] * c, frac * SCAR["a_m"] * s)
    else:
        d = (-frac * SCAR["b_m"] * s, frac * SCAR["b_m"] * c)
    return SCAR["x_m"] + d[0], SCAR["y_m"] + d[1]


@pytest.mark.parametrize("axis", ["a", "b"])
def test_the_centre_is_inside_within_one_semi_axis_along_each_axis(axis):
    assert S.inside_outline(_along(axis, 0.99), SCAR)
    assert not S.inside_outline(_along(axis, 1.01), SCAR)
    assert S.inside_outline(_along(axis, -0.99), SCAR)


def _report(x, y, ratio, se, named=("inclusion",)):
    return {"named": list(named), "minor": [], "fit": {"chi2_per_dof": 1.2},
            "final_parameters": {"skin.E": 1e4, "inclusion.x": x, "inclusion.y": y,
                                 "inclusion.ratio": ratio, "inclusion.radius": 3e-3},
            "final_se": {"skin.E": 1e2, "inclusion.x": 1e-4, "inclusion.y": 1e-4, "inclusion.ratio": se}}


def test_the_ratio_is_covered_within_its_95_percent_interval():
    inside = _along("a", 0.5)
    got = S.score_case(_report(*inside, ratio=6.0 + 1.95 * 0.5, se=0.5), SCAR)
    assert got["inclusion_named"] and got["centre_inside"] and got["ratio_covered"]
    assert got["centre_error_mm"] == pytest.approx(2.5, rel=1e-9)
    assert not S.score_case(_report(*inside, ratio=6.0 + 1.97 * 0.5, se=0.5), SCAR)["ratio_covered"]


def test_a_report_without_the_effect_found_nothing():
    rep = {"named": ["prestress"], "minor": [], "final_parameters": {"prestress.l1": 1.1}}
    got = S.score_case(rep, SCAR)
    assert not got["inclusion_named"] and not got["centre_inside"] and not got["ratio_covered"]
    assert not S.score_case(rep, None)["inclusion_named"]        # a healthy case: no false alarm
    assert S.score_case(_report(0, 0, 1, 1), None)["inclusion_named"]   # ... and one


def _fake(task):
    """A case whose outcome follows its seed: found on even seeds, named on healthy seed 1."""
    even = task["seed"] % 2 == 0
    return {"id": S.case_id(task), "seed": task["seed"], "healthy": task["healthy"],
            "inclusion_named": (not task["healthy"]) or task["seed"] == 1,
            "centre_inside": even, "ratio_covered": even, "wall_s": 0.0}


def test_the_journal_keeps_finished_cases(tmp_path):
    journal = tmp_path / "scar.jsonl"
    res = S.run(4, 2, journal=journal, case=_fake)
    assert res["named"]["count"] == 4 and res["centre_inside"]["count"] == 2
    assert res["false_alarms"] == {**res["false_alarms"], "count": 1, "n": 2}
    lo, hi = res["named"]["interval_95"]
    assert hi == 1.0 and 0.39 < lo < 0.40          # Clopper-Pearson for 4/4: 0.398

    def never(task):
        raise AssertionError(f"{task} was recorded and must not run again")

    again = S.run(4, 2, journal=journal, case=never)
    assert [c["id"] for c in again["cases"]] == [c["id"] for c in res["cases"]]
    # the page of a run read back says so, and how long the cases took when they ran
    assert again["from_journal"] == 6 and "6 cases read from the journal" in S.summary_lines(again)[0]
    assert "0.0 min (median)" in S.summary_lines(again)[0]
    more = S.run(5, 2, journal=journal, case=_fake)      # one seed more: only it runs
    assert more["scar_cases"] == 5 and more["named"]["count"] == 5


def test_no_case_is_refused_in_one_line():
    r = CliRunner().invoke(cli, ["bench", "scar", "--seeds", "0", "--healthy", "0"])
    assert r.exit_code == 2 and "no case to run" in r.output
