"""The gap report's region section as a browser shows it: headless Chromium (Debian's ``chromium``)
loads a gap report whose ``region_scan`` found a region, and from the rendered DOM and a
screenshot the per-point residual map carries the found region's outline — a circle of the
outline's colour at the region's centre and size, on the residual map and on the score map — and
a report without a scan has none. The report is built by hand in the shape ``skinkit gap diagnose
--json`` prints (a 1 mm grid of tracked points, a residual high around the region). Without
Chromium the browser test is skipped with the reason.
"""

from __future__ import annotations

import copy
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from skinkit.gap.html import write_html
from skinkit.gap.html_scan import BEST

#: the found region [mm], and the window [px] (tall enough for the whole short page)
X, Y, R = 3.0, -2.0, 3.0
WIDTH, HEIGHT = 1280, 6000
HANG_S = 300


def report() -> dict:
    g = np.arange(-8.0, 8.01, 1.0)
    xy = np.array([(a, b) for a in g for b in g])
    chi = 1.0 + 8.0 * np.exp(-((xy[:, 0] - X) ** 2 + (xy[:, 1] - Y) ** 2) / (2 * R ** 2))
    cx, cy = np.meshgrid(np.arange(-8.0, 8.01, 2.0), np.arange(-8.0, 8.01, 2.0), indexing="ij")
    centres = np.column_stack([cx.ravel(), cy.ravel()])
    regs = np.array([(a, b, s) for a, b in centres for s in (2.0, 4.0)])
    lm = 40.0 * np.exp(-((regs[:, 0] - X) ** 2 + (regs[:, 1] - Y) ** 2) / 8.0)
    names = ["inclusion.x", "inclusion.y", "inclusion.radius"]
    scan = {"round": 1, "effect": "inclusion", "parameters": names,
            "tested": ["inclusion.ratio"],
            "grid": {"spacing_m": 2e-3, "centres_m": (centres * 1e-3).tolist(), "sizes_m": [2e-3, 4e-3],
                     "regions": len(regs)},
            "regions": {"x_m": (regs[:, 0] * 1e-3).tolist(), "y_m": (regs[:, 1] * 1e-3).tolist(),
                        "size_m": (regs[:, 2] * 1e-3).tolist(), "statistic": lm.tolist(),
                        "dof": [1] * len(regs)},
            "best": {"x_m": X * 1e-3, "y_m": Y * 1e-3, "size_m": R * 1e-3, "statistic": 40.0, "dof": 1,
                     "p_value": 2.5e-10, "p_adjusted": 3e-8, "log10_p_adjusted": -7.5},
            "cost": {"n_forward": 1, "columns": len(regs) + 2, "wall_s": 12.0, "forward_equivalents": 20.0}}
    return {"model": "twopad", "session": "scar.h5",
            "fit": {"parameters": {"skin.E": 1e4}, "chi2_per_dof": 1.8},
            "gap": {"significant": True, "chi2_per_dof": 1.8, "cells": [],
                    "point_map": {"in_plane_000": chi.tolist()}},
            "points": {"in_plane_000": (xy * 1e-3).tolist()},
            "candidates": [{"effect": "inclusion", "score": 40.0, "p_value": 3e-8, "dof": 1, "refitted": True,
                            "parameters": {"inclusion.x": {"value": 3.4e-3},
                                           "inclusion.y": {"value": -2.4e-3},
                                           "inclusion.radius": {"value": 3.1e-3},
                                           "inclusion.ratio": {"value": 2.9}}}],
            "named": ["inclusion"], "region_scan": [scan]}


OUTLINES = ("scan-region", "refit-region", "rival-region")


class Outlines(HTMLParser):
    """The circles of class ``scan-region`` / ``refit-region`` inside ``section#scan``, per SVG panel."""

    def __init__(self, text: str) -> None:
        super().__init__(convert_charrefs=True)
        self.found: list[tuple[str, str, dict]] = []    # (panel, class, attributes)
        self._section: str | None = None
        self._panel: str | None = None
        self.feed(text)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "section":
            self._section = a.get("id")
        elif tag == "svg" and self._section == "scan":
            self._panel = a.get("data-panel")
        elif tag in ("circle", "ellipse") and self._section == "scan" and a.get("class") in OUTLINES:
            self.found.append((self._panel or "", a["class"], a))

    def handle_startendtag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.handle_starttag(tag, attrs)


def test_the_outline_is_in_the_page(tmp_path):
    text = write_html(report(), tmp_path / "gap.html").read_text()
    found = Outlines(text).found
    best = [(p, a) for p, c, a in found if c == "scan-region"]
    assert sorted(p for p, _ in best) == ["residual", "score"]
    for _, a in best:
        assert (float(a["data-x-mm"]), float(a["data-y-mm"]), float(a["data-size-mm"])) == (X, Y, R)
        assert float(a["r"]) > 10 and a["stroke"] == BEST
    assert sorted(p for p, c, _ in found if c == "refit-region") == ["residual", "score"]
    assert 'href="#scan"' in text
    bare = report()
    del bare["region_scan"]
    text = write_html(bare, tmp_path / "bare.html").read_text()
    assert not Outlines(text).found and "No region scan" in text


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        exe = shutil.which(name)
        if exe:
            return exe
    pytest.skip("no Chromium on PATH (Debian: apt-get install chromium)")


def _browse(exe: str, profile: Path, *args: str) -> str:
    cmd = [exe, "--headless", "--disable-gpu", "--no-sandbox", "--hide-scrollbars", "--mute-audio",
           "--no-first-run", "--disable-extensions", f"--user-data-dir={profile}", *args]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=HANG_S)
    except OSError as exc:
        pytest.skip(f"Chromium cannot be started here: {exc}")
    if res.returncode != 0 and "error while loading shared libraries" in res.stderr:
        pytest.skip(f"Chromium cannot run here: {res.stderr.strip().splitlines()[-1]}")
    assert res.returncode == 0, f"chromium failed ({res.returncode}): {res.stderr[-2000:]}"
    return res.stdout


def _outline_pixels(shot: Path) -> int:
    """Pixels of the screenshot within a few levels of the outline's colour."""
    from matplotlib.image import imread

    rgb = imread(shot)[..., :3]
    want = np.array([int(BEST[i:i + 2], 16) for i in (1, 3, 5)]) / 255.0
    return int((np.abs(rgb - want).max(axis=2) < 0.05).sum())


def test_the_browser_draws_the_outline(tmp_path):
    exe = _chromium()
    pages = {}
    bare = {k: v for k, v in report().items() if k != "region_scan"}
    for name, rep in (("scan", report()), ("bare", bare)):
        page = write_html(copy.deepcopy(rep), tmp_path / f"{name}.html")
        url = page.resolve().as_uri()
        shot = tmp_path / f"{name}.png"
        _browse(exe, tmp_path / f"profile-{name}-shot", f"--screenshot={shot}",
                f"--window-size={WIDTH},{HEIGHT}", url)
        dom = _browse(exe, tmp_path / f"profile-{name}-dom", "--dump-dom", url)
        pages[name] = (Outlines(dom).found, _outline_pixels(shot))
    print(f"screenshots: {tmp_path}")
    found, pixels = pages["scan"]
    assert sorted(p for p, c, _ in found if c == "scan-region") == ["residual", "score"]
    # two circles of r > 10 px drawn 2.5 px wide: at least 2 x 2π x 10 x 2 px of the outline's colour
    assert pixels > 250, pixels
    assert pages["bare"] == ([], 0)


def test_the_session_report_nests_the_region_section_only_when_scanned():
    from skinkit.report.gaps import _gap

    nested = _gap("scar", report())
    assert 'id="gap-scar-scan"' in nested and nested.count('class="scan-region"') == 2
    bare = {k: v for k, v in report().items() if k != "region_scan"}
    assert "scan-region" not in _gap("bare", bare) and "gap-bare-scan" not in _gap("bare", bare)


def ellipse_report() -> dict:
    """The report refitted in the inclusion's elliptical form from a shape scan at the best centre."""
    rep = report()
    names = ["inclusion.x", "inclusion.y", "inclusion.a", "inclusion.b", "inclusion.angle"]
    rep["region_scan"][0]["shape"] = {"form": "ellipse", "parameters": names}
    rep["candidates"][0]["parameters"] = {
        "inclusion.x": {"value": 3.4e-3}, "inclusion.y": {"value": -2.4e-3}, "inclusion.a": {"value": 5e-3},
        "inclusion.b": {"value": 2e-3}, "inclusion.angle": {"value": np.radians(30.0)},
        "inclusion.ratio": {"value": 2.9}}
    return rep


def test_a_refitted_ellipse_is_drawn_as_one(tmp_path):
    text = write_html(ellipse_report(), tmp_path / "gap.html").read_text()
    found = Outlines(text).found
    refit = [(p, a) for p, c, a in found if c == "refit-region"]
    assert sorted(p for p, _ in refit) == ["residual", "score"]
    for _, a in refit:
        assert (float(a["data-a-mm"]), float(a["data-b-mm"]), float(a["data-angle-deg"])) == \
            pytest.approx((5.0, 2.0, 30.0))
        assert float(a["rx"]) > float(a["ry"]) > 0 and "rotate(-30" in a["transform"]
    assert "semi-axes 5 and 2 mm" in text


def test_the_browser_draws_the_refitted_ellipse(tmp_path):
    """The page Chromium renders holds the refitted ellipse, turned, on both panels."""
    exe = _chromium()
    page = write_html(ellipse_report(), tmp_path / "gap.html")
    dom = _browse(exe, tmp_path / "profile", "--dump-dom", page.resolve().as_uri())
    refit = [a for p, c, a in Outlines(dom).found if c == "refit-region"]
    assert len(refit) == 2 and all(a.get("transform", "").startswith("rotate(") for a in refit)


def test_a_second_place_refitted_from_is_drawn_and_said(tmp_path):
    """A scan whose second place was refitted from too: an orange circle at it on both panels,
    and the sentence says the two refits fit alike when they do."""
    from skinkit.gap.html_scan import RIVAL

    rep = report()
    refits = {"best": {"values": {"x": 3.4e-3}, "chi2": 100.0},
              "rival": {"values": {"x": -5e-3}, "chi2": 104.0}, "delta_chi2": 4.0, "kept": "best",
              "separable": False}
    rep["region_scan"][0]["rival"] = {"x_m": -5e-3, "y_m": 1e-3, "size_m": 2e-3, "statistic": 30.0,
                                      "share_of_best": 0.75, "step": {"inclusion.ratio": -0.5},
                                      "refits": refits}
    text = write_html(rep, tmp_path / "gap.html").read_text()
    rival = [(p, a) for p, c, a in Outlines(text).found if c == "rival-region"]
    assert sorted(p for p, _ in rival) == ["residual", "score"]
    for _, a in rival:
        assert (float(a["data-x-mm"]), float(a["data-y-mm"]), float(a["data-size-mm"])) == (-5.0, 1.0, 2.0)
        assert a["stroke"] == RIVAL
    assert "75 % of the best" in text and "cannot tell the two apart" in text
    report_without = report()
    report_without["region_scan"][0]["rival"] = None
    text = write_html(report_without, tmp_path / "plain.html").read_text()
    assert not [c for _, c, _ in Outlines(text).found if c == "rival-region"]
