"""The self-contained HTML report of a gap diagnosis.

Report dicts are built by hand in the shape ``skinkit gap diagnose --json`` prints (Contract 2 of
the gap package): a significant gap with a named effect, per-point maps and a non-separable pair;
a session at the noise level; a dict with only the pinned keys; an empty dict. Each is written
and read back: self-contained (every image a data URI, every link an in-page anchor), balanced
HTML, the verdict, every significant cell, every candidate and the shrinkage numbers present,
every image a PNG.
"""

from __future__ import annotations

import base64
import json
import math
import re
from html.parser import HTMLParser

import numpy as np
import pytest

from skinkit.errors import SchemaError, StoreError
from skinkit.gap.html import write_html

PNG = b"\x89PNG\r\n\x1a\n"
VOID = {"meta", "img", "br", "hr", "link", "input", "col", "area", "base", "source", "wbr"}


class Checker(HTMLParser):
    """Collects every src/href and checks that every closing tag closes the innermost open one."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.refs: list[tuple[str, str, str]] = []
        self.sections: dict[str, list[str]] = {}
        self._section: str | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for k, v in attrs:
            if k in ("src", "href", "data", "action", "poster", "srcset"):
                self.refs.append((tag, k, v or ""))
        if tag == "section":
            self._section = dict(attrs).get("id")
            self.sections[self._section] = []
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag: str) -> None:
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
            return
        self.stack.pop()
        if tag == "section":
            self._section = None

    def handle_data(self, data: str) -> None:
        if self._section is not None:
            self.sections[self._section].append(data)

    def text(self, section: str) -> str:
        return " ".join(" ".join(self.sections.get(section, [])).split())


def check(path) -> tuple[str, Checker]:
    """The file's text and its parse; asserts it is balanced and needs nothing outside itself."""
    text = path.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>")
    p = Checker()
    p.feed(text)
    p.close()
    assert not p.errors, p.errors[:3]
    assert p.stack == [], p.stack
    for tag, attr, value in p.refs:
        if attr == "src":
            assert value.startswith("data:image/png;base64,"), (tag, value[:60])
        else:
            assert value.startswith("#"), (tag, attr, value)
    assert "http://" not in text and "https://" not in text
    assert "<link" not in text and "@import" not in text and "url(" not in text
    return text, p


def pngs(text: str) -> list[bytes]:
    """Every embedded image, decoded; each must be a PNG."""
    found = re.findall(r'src="data:image/png;base64,([^"]+)"', text)
    out = [base64.b64decode(m, validate=True) for m in found]
    for b in out:
        assert b.startswith(PNG)
    return out


def point_grid() -> np.ndarray:
    """A 6 × 6 grid of tracked points, 2 mm apart, centred on the probe [m]."""
    g = (np.arange(6) - 2.5) * 2e-3
    x, y = np.meshgrid(g, g)
    return np.column_stack([x.ravel(), y.ravel()])


def gap_report() -> dict:
    """A significant gap in the in-plane protocols, prestress named, not separable from fibres."""
    pts = point_grid()
    angle = np.arctan2(pts[:, 1], pts[:, 0])
    before = 1.0 + 6.0 * np.cos(angle - math.radians(30)) ** 2     # direction-dependent, as pre-stress
    after = 1.0 + 0.3 * np.cos(angle) ** 2
    before_list = [float(v) for v in before]
    before_list[7] = None   # a point never observed
    cells = [
        {"axis": "protocol", "label": "in_plane_030", "share": 0.7, "chi2_per_dof": 4.5, "p_value": 1e-30,
         "significant": True},
        {"axis": "protocol", "label": "in_plane_120", "share": 0.3, "chi2_per_dof": 2.3, "p_value": 1e-9,
         "significant": True},
        {"axis": "protocol", "label": "indentation", "share": 0.0, "chi2_per_dof": 0.98, "p_value": 0.61,
         "significant": False},
        {"axis": "channel", "label": "surface x", "share": 0.8, "chi2_per_dof": 3.9, "p_value": 1e-25,
         "significant": True},
        {"axis": "channel", "label": "tip_force", "share": 0.2, "chi2_per_dof": 1.05, "p_value": 0.2,
         "significant": False},
        {"axis": "phase", "label": "hold", "share": 0.6, "chi2_per_dof": 3.1, "p_value": 1e-12,
         "significant": True, "partition": "direction"},
        {"axis": "phase", "label": "loading", "share": 0.4, "chi2_per_dof": 1.4, "p_value": 0.004,
         "significant": False, "partition": "direction"},
        {"axis": "phase", "label": "first cycle", "share": 1.0, "chi2_per_dof": 2.2, "p_value": 1e-6,
         "significant": True, "partition": "cycle"},
        {"axis": "region", "label": "sector 30-60 deg <Langer & co>", "share": 0.5, "chi2_per_dof": 5.0,
         "p_value": 1e-20, "significant": True},
        {"axis": "frequency", "label": "0.5-2 Hz", "share": 0.1, "chi2_per_dof": 1.1, "p_value": 0.3,
         "significant": False},
    ]
    return {
        "model": "invivo-goh-qlv", "session": "virtual_prestress.h5",
        "fit": {"parameters": {"skin.mu": 1.2e4, "skin.k1": 3.4e5, "skin.k2": 12.0},
                "chi2_per_dof": 3.2, "n_forward": 57},
        "gap": {"significant": True, "chi2_per_dof": 3.2, "p_value": 1e-40, "cells": cells,
                "point_map": {"in_plane_030": before_list, "in_plane_120": [float(v) for v in before * 0.5]},
                "whiteness": {"in_plane_030/surface x": {"statistic": 412.0, "lags": 20, "p_value": 1e-60,
                                                         "white": False},
                              "indentation/tip_force": {"statistic": 18.2, "lags": 20, "p_value": 0.57,
                                                        "white": True}},
                "cross_correlation": {"in_plane_030/surface x": {"statistic": 90.0, "lags": 20,
                                                                 "p_value": 1e-9, "independent": False}}},
        "points": {"in_plane_030": pts.tolist(), "in_plane_120": pts.tolist()},
        "point_map_after": {"in_plane_030": [float(v) for v in after]},
        "candidates": [
            {"effect": "prestress", "score": 85.0, "p_value": 1e-14, "dof": 2, "refitted": True,
             "delta_aic": -160.0, "shrinkage": 0.82,
             "parameters": {"prestress.magnitude": {"value": 2100.0, "se": 250.0, "unit": "Pa"}},
             "not_separable_from": ["fibres"]},
            {"effect": "fibres", "score": 80.0, "p_value": 1e-13, "dof": 2, "refitted": True,
             "delta_aic": -150.0,
             "shrinkage": 0.77, "parameters": {"fibres.k1": {"value": 5.0e4, "se": 9.0e3}},
             "not_separable_from": ["prestress"]},
            {"effect": "viscoelastic", "score": 3.1, "p_value": 0.21, "dof": 2, "refitted": False,
             "delta_aic": None,
             "shrinkage": None, "parameters": None, "not_separable_from": []},
        ],
        "named": ["prestress"],
        "shrinkage": {"overall": 0.82, "held_out": 0.75,
                      # the diagnosis's own fraction for the first cell (from χ² − dof), none for the second
                      "cells": [{"axis": "protocol", "label": "in_plane_030", "before": 4.5, "after": 1.25,
                                 "shrinkage": 0.9},
                                {"axis": "protocol", "label": "in_plane_120", "before": 2.3, "after": 1.1}]},
        "separation": [{"effects": ["prestress", "fibres"], "protocol": "in_plane_075", "cosine": 0.97,
                        "cosine_after": 0.41, "round": 1}],
        "rounds": [{"round": 1, "model_effects": [], "chi2_per_dof": 3.2, "named": "prestress",
                    "candidates": [{"effect": "prestress", "score": 85.0}],
                    "not_named": {"fibres": "its refit lowers the AIC less than prestress's"}},
                   {"round": 2, "model_effects": ["prestress"], "chi2_per_dof": 1.3, "named": None,
                    "candidates": [], "not_named": {}}],
        "messages": ["Significant gap: χ²/ν 3.2; located in in_plane_030 (60 % of the excess).",
                     "`prestress` is a cause: it removes 82 % of the excess the noise level cannot "
                     "account for (ΔAIC -120.0; prestress.p = 2100 ± 250 Pa).",
                     "prestress and fibres are not separable on these protocols (|cos| 0.970); in_plane_075 "
                     "would separate them best (|cos| 0.410)."],
    }


def no_gap_report() -> dict:
    cells = [{"axis": "protocol", "label": p, "share": 0.0, "chi2_per_dof": r, "p_value": q,
              "significant": False} for p, r, q in (("in_plane_030", 1.02, 0.31), ("indentation", 0.97, 0.7))]
    return {"model": "invivo-goh-qlv", "session": "virtual_null.h5",
            "fit": {"parameters": {"skin.mu": 1.0e4}, "chi2_per_dof": 1.01, "n_forward": 12},
            "gap": {"significant": False, "chi2_per_dof": 1.01, "cells": cells},
            "candidates": [{"effect": "prestress", "score": 0.4, "p_value": 0.82, "refitted": False,
                            "delta_aic": None, "shrinkage": None, "parameters": None,
                            "not_separable_from": []}],
            "named": [],
            "shrinkage": {"overall": 0.0, "held_out": None, "cells": []},
            "messages": ["No significant gap: χ²/ν 1.01 is at the noise level; no effect named."]}


def minimal_report() -> dict:
    """Only the pinned keys; one significant cell, one refitted candidate."""
    return {"model": "lumped-fung", "session": "extension.csv",
            "fit": {"parameters": {"a": 0.015, "b": 320.0}, "chi2_per_dof": 2.0, "n_forward": 30},
            "gap": {"significant": True, "chi2_per_dof": 2.0,
                    "cells": [{"axis": "phase", "label": "hold", "share": 1.0, "chi2_per_dof": 2.6,
                               "p_value": 1e-8, "significant": True}]},
            "candidates": [{"effect": "viscoelastic", "score": 40.0, "p_value": 1e-9, "refitted": True,
                            "delta_aic": -35.0, "shrinkage": 0.6,
                            "parameters": {"viscoelastic.g1": {"value": 0.3, "se": 0.05}},
                            "not_separable_from": []}],
            "named": ["viscoelastic"],
            "shrinkage": {"overall": 0.6, "held_out": None,
                          "cells": [{"axis": "phase", "label": "hold", "before": 2.6, "after": 1.4}]}}


@pytest.fixture(scope="module")
def gap_html(tmp_path_factory):
    """The significant-gap report written once (the map rendering is the slow part); through JSON
    first, as the CLI hands it over (None for the unobserved point)."""
    report = json.loads(json.dumps(gap_report()))
    path = write_html(report, tmp_path_factory.mktemp("html") / "sub" / "gap.html")
    return path, report


def test_gap_report_self_contained_and_complete(gap_html):
    path, report = gap_html
    assert path.is_file() and path.name == "gap.html"
    text, p = check(path)
    verdict = p.text("verdict")
    # the verdict is the diagnosis's own sentences, the ones stdout prints
    for m in report["messages"]:
        assert m in verdict
    assert "prestress" in verdict and "2100 ± 250 Pa" in verdict    # named, with its magnitude
    assert "fibres" in verdict and "in_plane_075" in verdict               # not separable; what separates
    for c in report["gap"]["cells"]:
        if c["significant"]:
            assert c["label"] in p.text("residual")
    assert "sector 30-60 deg &lt;Langer &amp; co&gt;" in text               # labels are escaped
    assert "<Langer" not in text
    for c in report["candidates"]:
        assert c["effect"] in p.text("scores")
    # the shrinkage table: before, after and the fraction of the excess removed,
    # (excess before − excess after) / excess before with excess = χ²/dof − 1
    shrink = p.text("shrinkage")
    # the diagnosis's figure where it gives one, else the excess of χ²/dof
    for before, after, frac in ((4.5, 1.25, 0.9), (2.3, 1.1, (1.3 - 0.1) / 1.3)):
        assert f"{before:g}" in shrink and f"{after:g}" in shrink and f"{100 * frac:.1f} %" in shrink
    sep = p.text("separation")
    assert "prestress" in sep and "fibres" in sep and "in_plane_075" in sep
    assert "0.97" in sep and "0.41" in sep                                 # |cos| now, and with that protocol
    assert "phase (cycle)" in p.text("residual")                           # the partition of a two-way axis
    assert "its refit lowers the AIC less" in p.text("rounds")
    tests = p.text("tests")
    assert "in_plane_030/surface x" in tests and "not white" in tests and "not independent" in tests
    assert "rounds" in p.sections
    images = pngs(text)
    assert len(images) >= 3       # residual bars, maps (matplotlib), scores; + pyvista where VTK renders


def test_gap_report_maps_share_one_scale(gap_html):
    """The map section states the shared colour range: up to the largest χ²/dof of any point
    before or after (here 7, the peak of 1 + 6 cos²)."""
    path, report = gap_html
    _, p = check(path)
    vals = [v for v in report["gap"]["point_map"]["in_plane_030"] if v is not None]
    top = max(vals + report["gap"]["point_map"]["in_plane_120"] + report["point_map_after"]["in_plane_030"])
    assert f"to {top:.3g}" in p.text("maps")
    assert "white at 1" in p.text("maps")


def test_no_gap_says_so(tmp_path):
    text, p = check(write_html(no_gap_report(), tmp_path / "null.html", title="Null session"))
    verdict = p.text("verdict")
    assert "No significant gap" in verdict and "no effect named" in verdict
    assert verdict.count("No significant gap") == 1        # the diagnosis's own message not repeated
    assert "<title>Null session</title>" in text
    assert "prestress" in p.text("scores")
    assert "No per-point residual map" in p.text("maps")
    assert len(pngs(text)) == 2   # residual bars and scores; no maps


def test_pinned_keys_only(tmp_path):
    report = minimal_report()
    text, p = check(write_html(report, tmp_path / "min.html"))
    verdict = p.text("verdict")
    assert "Significant gap" in verdict and "viscoelastic" in verdict and "60.0 %" in verdict
    assert "hold" in p.text("residual")
    shrink = p.text("shrinkage")
    assert "2.6" in shrink and "1.4" in shrink and "75.0 %" in shrink     # excess 1.6 → 0.4
    assert "No non-separable pair" in p.text("separation")
    assert "tests" not in p.sections and "rounds" not in p.sections
    assert len(pngs(text)) == 2


def test_empty_report_still_writes(tmp_path):
    text, p = check(write_html({}, tmp_path / "empty.html"))
    assert "cannot be said" in p.text("verdict")
    assert pngs(text) == []


def test_bad_inputs(tmp_path):
    with pytest.raises(SchemaError, match="gap report"):
        write_html([1, 2], tmp_path / "x.html")
    with pytest.raises(StoreError, match="is a folder"):
        write_html(minimal_report(), tmp_path)


def test_from_the_diagnosis_objects(tmp_path):
    """The dict as the gap package's own objects serialise it (GapLocation.to_dict with NumPy
    point maps and NaN, GapReport.to_dict), and the GapReport itself, render the same report."""
    from skinkit.gap.where import Cell, GapLocation
    from skinkit.schemas.results import EffectScore, GapReport

    pts = point_grid()
    pmap = np.linspace(0.5, 3.0, len(pts))
    pmap[3] = np.nan
    cells = [Cell("protocol", "in_plane_030", 300.0, 100.0, 3.0, 1e-30, True, 1.0, 100, "protocol"),
             Cell("channel", "surface z", 250.0, 80.0, 3.125, 1e-25, True, 1.0, 80, "channel"),
             Cell("phase", "hold", 90.0, 90.0, 1.0, 0.48, False, 0.0, 90, "direction")]
    loc = GapLocation(640.0, 270.0, 640 / 270, 1e-40, True, cells, point_map={"in_plane_030": pmap},
                      whiteness={"in_plane_030/surface z": {"statistic": 50.0, "lags": 10, "p_value": 1e-6,
                                                            "white": False}})
    fit = {"parameters": {"skin.mu": 1e4}, "chi2_per_dof": 2.37, "n_forward": 9}
    after = [None if not np.isfinite(v) else 1.0 for v in pmap]
    rep = GapReport("fe-goh", "s.h5", fit=fit,
                    gap=loc.to_dict(),
                    candidates=[EffectScore("prestress", 120.0, 1e-20, 2, True, -90.0, 0.7,
                                            {"prestress.l1": {"value": 1.1, "se": 0.01}})],
                    named=["prestress"],
                    shrinkage={"overall": 0.7, "held_out": None,
                               "cells": [{"axis": "protocol", "label": "in_plane_030", "before": 3.0,
                                          "after": 1.6, "shrinkage": 0.7}]},
                    extra={"points": {"in_plane_030": pts.tolist()},
                           "point_map_after": {"in_plane_030": after},
                           "messages": ["Significant gap: χ²/ν 2.37; located in in_plane_030.",
                                        "`prestress` is a cause: it removes 70 % of the excess the noise "
                                        "level cannot account for (ΔAIC -90.0; prestress.l1 = 1.1 ± 0.02)."]})
    for i, source in enumerate((rep, json.loads(json.dumps(rep.to_dict())))):
        text, p = check(write_html(source, tmp_path / f"r{i}.html"))
        verdict = p.text("verdict")
        assert "Significant gap" in verdict and "prestress" in verdict and "70 %" in verdict
        assert verdict.count("Significant gap") == 1
        assert "in_plane_030" in p.text("residual") and "surface z" in p.text("residual")
        assert "not white" in p.text("tests")
        assert len(pngs(text)) >= 3
