"""``skinkit report``: one self-contained HTML file with every result an
experiment file holds, checked against the file it was made from (tests/report/conftest.py
builds the file with the real commands) and against what the file's objects are by construction.
"""

from __future__ import annotations

import hashlib
import html
import os
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from report_session import (
    ALL_PARTS,
    CENTRES_MM,
    FIGURED,
    MISSING,
    REPROJECTION,
    STRAIN,
    ReportDOM,
    png_of,
    track_grid,
)

from skinkit.cli import cli
from skinkit.errors import StoreError
from skinkit.report import render_report, write_report
from skinkit.report.common import num
from skinkit.store import create_experiment, open_experiment

# one xdist worker runs these: it builds the experiment file of tests/report/conftest.py once
pytestmark = pytest.mark.xdist_group("report_session")


@pytest.fixture(scope="module")
def report(full_session) -> tuple[str, ReportDOM]:
    text = render_report(full_session["path"])
    return text, ReportDOM(text)


def _part(text: str, part: str) -> str:
    """The HTML of top-level section ``part``."""
    opening = f'<section id="{part}" class="part">'
    start = text.index(opening)
    nxt = text.find('class="part">', start + len(opening))
    return text[start:nxt if nxt > 0 else len(text)]


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# ---------------------------------------------------------------------------- structure

def test_every_section_rendered_in_order_with_contents(report):
    text, dom = report
    assert dom.parts == ALL_PARTS
    assert [c[2] for c in dom.contents] == [f"#{p}" for p in ALL_PARTS]
    assert not any("omitted" in c[0] for c in dom.contents)
    assert len(dom.ids) == len(set(dom.ids)), "ids must be unique (two reports' sections nested in one page)"
    # headings: the contents and one per part at h2; the gap report's own sections sit one level down
    assert dom.h2 == ["Contents", "Session", "Robot records", "Lumped fits (system identification)",
                      "Calibration", "Images", "Surface profiles", "Surface tracks",
                      "Model fits (identification)", "Gap reports"]


def test_figures_are_embedded_pngs_and_nothing_is_loaded_from_outside(report):
    text, dom = report
    by_part = {p: [i for i in dom.imgs if i[2] == p] for p in ALL_PARTS}
    for p in FIGURED:
        assert by_part[p], f"section {p} has no figure"
    for src, alt, _ in dom.imgs:
        img = png_of(src)
        assert img.shape[0] >= 10 and img.shape[1] >= 10
        assert float(np.ptp(img[..., :3])) > 0, f"figure {alt!r} is uniform"
    assert all(r.startswith(("data:image/png;base64,", "#")) for r in dom.refs), \
        [r[:40] for r in dom.refs if not r.startswith(("data:", "#"))]
    assert "@import" not in text and "url(" not in text and "<script src" not in text


# ---------------------------------------------------------------------------- content against the file

def test_records_table_and_statistics(full_session, report):
    text, _ = report
    sec = _part(text, "records")
    with open_experiment(full_session["path"]) as exp:
        for name in exp.record_names():
            info = exp.record_info(name)
            assert f'id="record-{name}"' in sec
            assert f">{info['samples']}<" in sec
            rec = exp.read_record(name)
            z = rec.tip_force[:, 2]
            # the statistics are the record's, not a subsample's
            for q in (z.mean(), z.std(), z.min(), z.max(), np.ptp(z)):
                assert f">{num(q, 4)}<" in sec
        n_trig = int(((exp.read_record("normal_indentation").flags & (1 << 4)) != 0).sum())
    assert f"camera_trigger {n_trig}" in sec and n_trig > 0


def test_lumped_fits(full_session, report):
    text, _ = report
    sec = _part(text, "lumped")
    for name, fit in full_session["lumped"].items():
        assert f'id="lumped-{name}"' in sec
        for i, p in enumerate(fit.parameters):
            se = float(np.sqrt(fit.covariance[i][i]))
            assert f">{num(p.value, 5)}<" in sec and f">{num(se, 2)}<" in sec
        assert f"VAF <b>{num(fit.extra['vaf_pct'], 4)} %</b>" in sec
    assert "ExampleWarning: a warning the report must show" in sec     # the Wiener fit's warning
    assert "No warning was raised while identifying." in sec            # the linear fit has none
    assert "fit-extension-relaxation-lumped" not in sec                 # a model fit is not lumped


def test_calibration_rig_and_reprojection(full_session, report):
    from skinkit.report.calibration import _centres

    text, _ = report
    sec = _part(text, "calibration")
    with open_experiment(full_session["path"]) as exp:
        rig = exp.read_rig()
    centres, axes = _centres(rig)
    for c_mm, c, a in zip(CENTRES_MM.values(), centres, axes, strict=True):
        # imported as t = -R C in mm: the centre comes back to rounding of the YAML's digits
        np.testing.assert_allclose(c * 1e3, c_mm, atol=1e-9)
        # each camera looks at the origin (conftest's look_at)
        np.testing.assert_allclose(a, -np.asarray(c_mm) / np.linalg.norm(c_mm), atol=1e-12)
        assert ", ".join(num(x, 4) for x in c * 1e3) in sec
    rows = re.findall(r"<tr><td>stereo</td><td>per_camera_rms_px</td><td>(\w+)</td><td[^>]*>([\d.]+)</td>",
                      sec)
    want = zip(CENTRES_MM, REPROJECTION["per_camera_rms_px"], strict=True)
    assert rows == [(cam, num(v, 4)) for cam, v in want]
    assert "rig_import" in sec and "x_cam = R X_world + t (OpenCV)" in html.unescape(sec)


def test_track_displacements_are_the_imposed_field(full_session, report):
    from skinkit.report.tracks import displacements

    text, _ = report
    ref_mm, pos_mm = track_grid()
    with open_experiment(full_session["path"]) as exp:
        track = exp.read_track("dic")
    ref, u = displacements(track)
    order = np.argsort(track.point_ids) if track.point_ids is not None else np.arange(track.n_points)
    ref, u = ref[order], u[order]
    np.testing.assert_allclose(ref * 1e3, ref_mm, atol=1e-9)
    want = pos_mm - ref_mm[:, None, :]
    seen = np.ones(want.shape[:2], bool)
    seen[MISSING] = False
    np.testing.assert_allclose(u[seen] * 1e3, want[seen], atol=1e-9)
    assert np.isnan(u[MISSING]).all()          # not observed: no displacement invented
    # the largest displacement, at a corner in the last frame: |(ε x, -0.3 ε y)| at x = 10, y = 6 mm
    largest = float(np.hypot(STRAIN * 10, 0.3 * STRAIN * 6))
    sec = _part(text, "tracks")
    assert f"<td>largest displacement [mm]</td><td>{num(largest, 4)}</td>" in sec


def test_model_fit_parameters_correlation_and_identifiability(full_session, report):
    text, _ = report
    sec = html.unescape(_part(text, "fits"))
    with open_experiment(full_session["path"]) as exp:
        fit = exp.read_fit("fit-extension-relaxation-lumped")
    assert f"χ²/ν = <b>{num(fit.chi2_per_dof, 4)}</b>" in sec
    ident = fit.identifiability["identifiable"]
    rows = dict(re.findall(r"<tr(?: class=\"sig\")?><td data-v=\"([\w.]+)\">.*?<td[^>]*>([^<]*)</td></tr>",
                           sec))
    for name in fit.parameters.free_names:
        assert rows[name] == ("determined" if ident[name] else "NOT identifiable from these protocols")
    for pr in fit.identifiability["problems"]:
        assert pr["message"] in sec
    assert "correlation matrix" in sec
    for proto in fit.residual_by_protocol:
        assert f">{proto}<" in sec


def test_gap_reports_drawn_by_the_gap_renderers(full_session, report):
    from skinkit.gap.html import _verdict

    text, dom = report
    sec = html.unescape(_part(text, "gaps"))
    with open_experiment(full_session["path"]) as exp:
        (name,) = exp.gap_names()
        rep = exp.read_gap(name)
    kind, sentences = _verdict(rep)
    for s in sentences:
        assert s in sec
    for inner in ("verdict", "fit", "residual", "scores"):
        assert f"gap-{name}-{inner}" in dom.ids


# ---------------------------------------------------------------------------- files and the command line

def test_session_file_is_only_read(full_session, tmp_path):
    src = tmp_path / "ro.h5"
    shutil.copy(full_session["path"], src)
    src.chmod(0o444)
    before, mtime = _sha(src), src.stat().st_mtime_ns
    out = write_report(src, tmp_path / "ro.html")
    assert out.stat().st_size > 0
    assert _sha(src) == before and src.stat().st_mtime_ns == mtime


def test_cli_default_out_refuses_to_overwrite(full_session, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(cli, ["report", str(full_session["path"])])
    assert r.exit_code == 0, r.output
    out = tmp_path / "session-report.html"
    assert out.exists() and str(out) in r.output
    stamp = _sha(out)
    r = CliRunner().invoke(cli, ["report", str(full_session["path"])])
    assert r.exit_code == 2 and "already exists" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert _sha(out) == stamp
    nested = tmp_path / "x" / "r.html"
    r = CliRunner().invoke(cli, ["report", str(full_session["path"]), "--out", str(nested)])
    assert r.exit_code == 0 and nested.exists()
    r = CliRunner().invoke(cli, ["report", str(full_session["path"]), "--overwrite"])
    assert r.exit_code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["session-report.html", "x"]   # no temporary left
    # a report is made to be shared: its mode follows the umask like any file the user writes
    # (mkstemp's 0600 would survive the rename)
    umask = os.umask(0)
    os.umask(umask)
    assert (out.stat().st_mode & 0o777) == (0o666 & ~umask)


def _damaged(full_session, tmp_path: Path) -> dict[str, tuple[Path, str]]:
    """Bad inputs and the words their one-line error must contain."""
    cases = {}
    js = tmp_path / "truth.json"
    js.write_text('{"a": 1}')
    cases["json"] = (js, "not an HDF5 file")
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = np.arange(3)
    cases["foreign"] = (foreign, "not a skinkit experiment file")
    trunc = tmp_path / "trunc.h5"
    trunc.write_bytes(full_session["path"].read_bytes()[:4000])
    cases["truncated"] = (trunc, "truncated")
    broken = tmp_path / "broken.h5"
    shutil.copy(full_session["path"], broken)
    with h5py.File(broken, "a") as f:
        del f["records/stochastic_linear/tip_force"]
    cases["object"] = (broken, "/records/stochastic_linear/tip_force: missing")
    cases["missing"] = (tmp_path / "nope.h5", "no such file")
    return cases


def test_cli_damaged_or_foreign_files_one_line_exit_2(full_session, tmp_path):
    for kind, (path, words) in _damaged(full_session, tmp_path).items():
        out = tmp_path / f"{kind}.html"
        r = CliRunner().invoke(cli, ["report", str(path), "--out", str(out)])
        assert r.exit_code == 2, (kind, r.output)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and words in lines[0], (kind, r.stderr)
        assert not out.exists(), kind


def test_two_gap_reports_keep_their_ids_apart(full_session, tmp_path):
    two = tmp_path / "two.h5"
    shutil.copy(full_session["path"], two)
    with h5py.File(two, "a") as f:
        (name,) = list(f["gaps"])
        f.copy(f[f"gaps/{name}"], f["gaps"], name="second-opinion")
    dom = ReportDOM(render_report(two))
    assert len(dom.ids) == len(set(dom.ids))
    assert {f"gap-{name}-verdict", "gap-second-opinion-verdict"} <= set(dom.ids)


def test_sections_for_what_the_file_lacks_are_omitted_and_listed(tmp_path):
    """A file with metadata and one record only (no plugins needed)."""
    from skinkit.schemas import Protocol, RobotRecord

    path = tmp_path / "bare.h5"
    t = np.arange(0, 2, 1e-3)
    pos = np.zeros((t.size, 3))
    pos[:, 2] = 1e-3 * np.sin(2 * np.pi * t)
    force = np.zeros((t.size, 3))
    force[:, 2] = 0.2 * np.sin(2 * np.pi * t)
    with create_experiment(path) as exp:
        exp.set_metadata(subject="S01", site="volar forearm")
        exp.write_record(RobotRecord(time_s=t, tip_position=pos, tip_force=force,
                                     protocol=Protocol("sine", kind="trajectory")))
    text = render_report(path)
    dom = ReportDOM(text)
    assert dom.parts == ["session", "records"]
    omitted = [c for c in dom.contents if "omitted" in c[0]]
    assert len(dom.contents) == len(ALL_PARTS) and len(omitted) == len(ALL_PARTS) - 2
    assert all(c[2] is None for c in omitted)     # nothing to link to
    texts = [c[1] for c in omitted]
    for what in ("no lumped", "no camera rig", "no image sequence", "no surface profile", "no surface track",
                 "no model identification", "no gap report"):
        assert sum(what in x for x in texts) == 1, what
    # the sine's amplitude: 1 mm, 0.2 N, so peak to peak 2 mm and 0.4 N to sampling
    sec = _part(text, "records")
    assert ">2<" in sec and ">0.4<" in sec
    out = tmp_path / "bare.html"
    out.write_text("mine")
    with pytest.raises(StoreError, match="already exists"):
        write_report(path, out)
    assert out.read_text() == "mine"
