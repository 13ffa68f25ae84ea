"""The session report in a real browser: headless Chromium (Debian's
``chromium`` package) loads the written HTML file, and from its DOM and its screenshot every
section rendered, every figure is a PNG that decodes, and the page is not blank.

The screenshot is kept as a test artefact at ``test-artifacts/report-screenshot.png`` under the
repository (ignored by git), besides the test's temporary folder. Without Chromium the test is
skipped with the reason (CI installs it: .ci/run).
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from report_session import ALL_PARTS, FIGURED, REPO, ReportDOM, png_of

from skinkit.report import write_report

#: the browser window [px]: the screenshot must come back at this size
WIDTH, HEIGHT = 1280, 4000
# one xdist worker runs these: it builds the experiment file of tests/report/conftest.py once
pytestmark = pytest.mark.xdist_group("report_session")


ARTEFACT = REPO / "test-artifacts" / "report-screenshot.png"
#: a guard against a hung browser only (no test asserts a duration)
HANG_S = 600


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        exe = shutil.which(name)
        if exe:
            return exe
    pytest.skip("no Chromium on PATH (Debian: apt-get install chromium)")


def _run(exe: str, profile: Path, *args: str) -> subprocess.CompletedProcess:
    cmd = [exe, "--headless", "--disable-gpu", "--no-sandbox", "--hide-scrollbars", "--mute-audio",
           "--no-first-run", "--disable-extensions", f"--user-data-dir={profile}", *args]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=HANG_S)
    except OSError as exc:
        pytest.skip(f"Chromium cannot be started here: {exc}")
    if res.returncode != 0 and "error while loading shared libraries" in res.stderr:
        pytest.skip(f"Chromium cannot run here: {res.stderr.strip().splitlines()[-1]}")
    assert res.returncode == 0, f"chromium {args[0]} failed ({res.returncode}): {res.stderr[-2000:]}"
    return res


@pytest.fixture(scope="module")
def browser_run(full_session, tmp_path_factory) -> dict:
    exe = _chromium()
    d = tmp_path_factory.mktemp("browser")
    page = write_report(full_session["path"], d / "report.html")
    url = page.resolve().as_uri()
    shot = d / "report-screenshot.png"
    _run(exe, d / "profile-shot", f"--screenshot={shot}", f"--window-size={WIDTH},{HEIGHT}", url)
    dom = _run(exe, d / "profile-dom", "--dump-dom", url).stdout
    assert shot.exists(), "Chromium wrote no screenshot"
    ARTEFACT.parent.mkdir(exist_ok=True)
    shutil.copyfile(shot, ARTEFACT)
    return {"shot": shot, "dom": dom}


def test_every_section_rendered_in_the_browser(browser_run):
    dom = ReportDOM(browser_run["dom"])
    assert dom.parts == ALL_PARTS, "a section is missing from the rendered DOM"
    assert [c[2] for c in dom.contents] == [f"#{p}" for p in ALL_PARTS]
    for p in FIGURED:
        imgs = [i for i in dom.imgs if i[2] == p]
        assert imgs, f"section {p}: no figure in the rendered DOM"
        for src, alt, _ in imgs:
            img = png_of(src)                     # a data: URI that decodes as a PNG
            assert img.ndim == 3 and min(img.shape[:2]) >= 10, alt
    # nothing the page would fetch: every reference is embedded or a link within the page
    assert all(r.startswith(("data:image/png;base64,", "#")) for r in dom.refs)


def test_screenshot_is_not_blank(browser_run):
    from matplotlib.image import imread

    img = imread(browser_run["shot"])
    assert img.shape[:2] == (HEIGHT, WIDTH)
    rgb = img[..., :3]
    assert float(rgb.std()) > 0.05, "the screenshot is (nearly) uniform"
    # ink (anything darker than the white page) in the top and in the bottom half: the page is
    # laid out down the whole window, not only a title
    ink = (rgb < 0.9).any(axis=2)
    for half in (ink[: HEIGHT // 2], ink[HEIGHT // 2:]):
        assert half.mean() > 0.01
    # colour: the figures rendered (a page of text alone is grey)
    chroma = rgb.max(axis=2) - rgb.min(axis=2)
    assert (chroma > 0.3).mean() > 0.001
    assert ARTEFACT.exists() and ARTEFACT.stat().st_size == browser_run["shot"].stat().st_size
    assert np.isfinite(rgb).all()
