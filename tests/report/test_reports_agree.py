"""The HTML reports agree with their JSON and with each other, as a browser shows them: headless
Chromium loads the gap report (``gap.html`` beside ``gap.json``) and the session report, and from
the rendered DOM

* the verdict's sentences and numbers are the JSON's (χ²/ν, the noise level, an effect's share);
* pre-stress is shown in one convention wherever it appears (λ1 ≥ λ2, θ of λ1 in degrees in
  (−90°, 90°]), although the fitter's values are stored as l1 < l2 and an angle in radians;
* every protocol has its "measured against predicted" figure, in the gap report and in the
  session report's fits and gap sections;
* the calibration's reprojection error, stored beside the rig, is shown.

A screenshot of the gap report is written to the test's temporary folder (its path printed).
The session is the one of tests/report/conftest.py (a lumped model: seconds, not minutes); the
pre-stress case is that session's gap report with a pre-stress candidate named, as a
finite-element diagnosis names it. Without Chromium the tests are skipped with the reason.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest
from report_session import png_of

from skinkit.gap.html import write_html
from skinkit.gap.sentences import added_messages, prestress_display
from skinkit.report import write_report
from skinkit.schemas import GapReport
from skinkit.store import open_experiment

pytestmark = pytest.mark.xdist_group("report_session")

#: the fitter's pre-stress: l1 < l2 and the angle of l1 in radians (the state the truth writes
#: as λ1 1.102, λ2 1.029 at 19.6°)
RAW = {"l1": 1.029, "l2": 1.102, "angle": -1.229}
HANG_S = 300
WIDTH, HEIGHT = 1280, 3000


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


class Page(HTMLParser):
    """The rendered DOM: text per section id (nested sections count for each enclosing one), the
    ``<p>`` sentences of the verdict, and per ``div.series`` its protocol and images."""

    def __init__(self, text: str) -> None:
        super().__init__(convert_charrefs=True)
        self.text: dict[str, str] = {}
        self.verdict: list[str] = []
        self.series: list[tuple[str, list[str], list[str]]] = []   # (protocol, srcs, enclosing ids)
        self._sections: list[str] = []
        self._p: str | None = None
        self._div: list[Any] = []
        self.feed(text)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "section":
            self._sections.append(a.get("id") or "")
            self.text.setdefault(a.get("id") or "", "")
        elif tag == "p" and self._sections and self._sections[-1].endswith("verdict"):
            self._p = ""
        elif tag == "div":
            ser = a.get("data-protocol") if "series" in (a.get("class") or "").split() else None
            self._div.append(None if ser is None else (ser, [], list(self._sections)))
        elif tag == "img" and any(d is not None for d in self._div):
            next(d for d in reversed(self._div) if d is not None)[1].append(a.get("src") or "")

    def handle_endtag(self, tag: str) -> None:
        if tag == "section" and self._sections:
            self._sections.pop()
        elif tag == "p" and self._p is not None:
            self.verdict.append(" ".join(self._p.split()))
            self._p = None
        elif tag == "div" and self._div:
            d = self._div.pop()
            if d is not None:
                self.series.append(d)

    def handle_data(self, data: str) -> None:
        for s in self._sections:
            self.text[s] += data
        if self._p is not None:
            self._p += data

    def shown(self) -> str:
        """Every section's text but the raw JSON's (where the stored values stay as they are)."""
        return " ".join(t for s, t in self.text.items() if s and not s.endswith("raw"))


def _prestress_variant(d: dict[str, Any]) -> dict[str, Any]:
    """The session's gap report with a pre-stress candidate named and the calibration's
    parameters carrying a pre-stretch, every value in the fitter's convention (:data:`RAW`)."""
    v = json.loads(json.dumps(d))
    ses = {"l1": 0.004, "l2": 0.006, "angle": 0.02}
    units = {"l1": "1", "l2": "1", "angle": "rad"}
    cand = {"effect": "prestress", "score": 812.0, "p_value": 1e-12, "dof": 3, "refitted": True,
            "delta_aic": -790.5, "shrinkage": 0.81, "not_separable_from": [], "role": "cause", "share": 0.81,
            "parameters": {f"prestress.{k}": {"value": x, "se": ses[k], "unit": units[k]}
                           for k, x in RAW.items()}}
    v["candidates"] = [cand] + v["candidates"]
    v["named"] = ["prestress"]
    v["fit"]["parameters"].update({f"skin.prestretch.{k}": x for k, x in RAW.items()})
    v["messages"] = [m for m in v["messages"] if not m.startswith("No significant gap")] \
        + added_messages(v["candidates"], ["prestress"], 0.5)
    return v


@pytest.fixture(scope="module")
def pages(full_session, tmp_path_factory) -> dict[str, Any]:
    exe = _chromium()
    d = tmp_path_factory.mktemp("agree")
    gap_dir = full_session["dir"] / "gap"
    gap = json.loads((gap_dir / "gap.json").read_text())
    variant = _prestress_variant(gap)
    write_html(variant, d / "prestress-gap.html")
    session = d / "session.h5"   # a copy: the shared session stays as the other tests expect it
    shutil.copyfile(full_session["path"], session)
    with open_experiment(session, "a") as exp:
        exp.write_gap("gap-prestress", GapReport.from_dict(variant))
        # as the demo's surface step stores it beside the rig
        exp.write_calibration("rig", {"images": "calibration", "rms_px": 0.065,
                                      "per_camera_rms_px": [0.061, 0.069], "views": [12, 12]})
    report = write_report(session, d / "report.html")
    shot = d / "gap-screenshot.png"
    _browse(exe, d / "p0", f"--screenshot={shot}", f"--window-size={WIDTH},{HEIGHT}",
            (d / "prestress-gap.html").resolve().as_uri())
    assert shot.exists() and shot.stat().st_size > 0, "Chromium wrote no screenshot"
    print(f"\nscreenshot of the gap report: {shot}")
    dom = {k: Page(_browse(exe, d / f"p-{k}", "--dump-dom", p.resolve().as_uri()))
           for k, p in (("gap", gap_dir / "gap.html"), ("prestress", d / "prestress-gap.html"),
                        ("session", report))}
    return {"gap": gap, "variant": variant, "dom": dom, "shot": shot}


def test_the_verdict_says_the_json_numbers(pages):
    gap, page = pages["gap"], pages["dom"]["gap"]
    assert page.verdict == gap["messages"]   # the page's sentences are the JSON's, word for word
    said = " ".join(page.verdict)
    chi = gap["chi2"]["before"] / gap["chi2"]["dof_before"]
    assert f"χ²/ν {chi:.3g}" in said
    assert f"σ {gap['noise']['tip_force']['sigma']:.3g} N" in said
    var, vpage = pages["variant"], pages["dom"]["prestress"]
    assert vpage.verdict == var["messages"]
    cause = next(c for c in var["candidates"] if c["effect"] == "prestress")
    assert f"removes {100 * cause['share']:.0f} %" in " ".join(vpage.verdict)
    assert f"ΔAIC {cause['delta_aic']:.1f}" in " ".join(vpage.verdict)


def _degrees(text: str, what: str) -> list[float]:
    return [float(x) for x in re.findall(re.escape(what) + r"\s*=?\s*(−?-?[0-9.]+)", text.replace("−", "-"))]


def test_prestress_in_one_convention_in_degrees(pages):
    l1, l2, deg = prestress_display(RAW["l1"], RAW["l2"], RAW["angle"])
    assert l1 >= l2 and -90 < deg <= 90 and abs(deg - 19.58) < 0.01
    for key in ("prestress", "session"):
        shown = pages["dom"][key].shown()
        # the fitter's names and radians appear nowhere but in the raw JSON
        assert "prestress.l1" not in shown and "prestress.angle" not in shown, key
        assert "prestretch.angle" not in shown and not re.search(r"\brad\b", shown), key
        for what in ("prestress.λ1", "prestress.λ2", "prestress.θ", "skin.prestretch.θ"):
            assert what in shown, (key, what)
        thetas = _degrees(shown, "prestress.θ") + _degrees(shown, "prestretch.θ")
        assert thetas and all(abs(t - deg) < 0.01 for t in thetas), (key, thetas)
        assert all(abs(x - l1) < 1e-3 for x in _degrees(shown, "prestress.λ1")), key
        assert all(abs(x - l2) < 1e-3 for x in _degrees(shown, "prestress.λ2")), key
        assert "°" in shown
    # the stored values are the fitter's, unchanged
    raw = pages["variant"]["candidates"][0]["parameters"]
    assert {k.split(".")[1]: v["value"] for k, v in raw.items()} == RAW


def test_measured_against_predicted_for_every_protocol(pages):
    gap = pages["gap"]
    protocols = {c["label"] for c in gap["gap"]["cells"] if c["axis"] == "protocol"}
    assert protocols and set(gap["series"]) >= protocols
    for entry in gap["series"].values():
        for ch in entry["channels"].values():
            assert 2 <= len(ch["time_s"]) <= 500 and "calibrated" in ch["predicted"] and ch["unit"]
    for key in ("gap", "prestress"):
        drawn = {p for p, srcs, _ in pages["dom"][key].series if srcs}
        assert drawn >= set(gap["series"]), key
    session = pages["dom"]["session"].series
    for part in ("fits", "gaps"):
        drawn = {p for p, srcs, where in session if srcs and part in where}
        assert drawn >= set(gap["series"]), part
    for _, srcs, _ in session:
        for src in srcs:
            img = png_of(src)
            assert img.ndim == 3 and min(img.shape[:2]) >= 100


def test_the_reprojection_error_is_shown(pages):
    text = pages["dom"]["session"].text["calibration"]
    assert "0.065" in text and "0.061" in text and "0.069" in text
    assert "stores no reprojection error" not in text


def test_a_screenshot_is_kept(pages):
    from matplotlib.image import imread

    img = imread(pages["shot"])
    assert img.shape[0] >= 1000 and float(img.std()) > 0.01   # a page, not a blank
    assert math.isfinite(float(img.mean()))
