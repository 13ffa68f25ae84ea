"""``skinkit import-extensometer`` on a synthetic record folder in the device's layout: a value
that is not a number is named by its file and line (not the folder), and images that go on
after the force record ends can be imported up to where it ends with ``--frames N``, which the
refusal names."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.store import open_experiment
from tests.core._cli import one_error
from tests.core._extensometer import write_record


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


def _replace_line(path, line: int, text: str) -> None:
    lines = path.read_text().splitlines()
    lines[line - 1] = text
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize(("file", "line", "text", "where"), [
    ("reactionforce/f_moving_pad.dat", 7, "nan", "f_moving_pad.dat:line 7"),
    ("reactionforce/u_moving_pad.dat", 30, "inf", "u_moving_pad.dat:line 30"),
    ("displacement/x0_ref_2.dat", 2, "nan", "x0_ref_2.dat:line 2"),
])
def test_a_value_that_is_not_finite_is_named_by_file_and_line(tmp_path, file, line, text, where):
    folder = write_record(tmp_path / "rec")
    _replace_line(folder / file, line, text)
    out = tmp_path / "e.h5"
    one_error(_run("import-extensometer", str(out), str(folder)), str(folder / file), where,
              f"{text} is not a finite number")
    assert not out.exists()


def test_a_pad_mark_that_is_not_finite_is_named_by_line_and_column(tmp_path):
    folder = write_record(tmp_path / "rec")
    path = folder / "displacement" / "yt_ref_1.dat"
    rows = [ln.split() for ln in path.read_text().splitlines()]
    rows[1][3] = "nan"
    path.write_text("\n".join("\t".join(r) for r in rows) + "\n")
    one_error(_run("import-extensometer", str(tmp_path / "e.h5"), str(folder)),
              "yt_ref_1.dat:line 2, column 4: nan is not a finite number")


def test_images_beyond_the_force_record_are_refused_naming_frames_and_imported_with_it(tmp_path):
    # 12 images out to 5 mm, the device to 4 mm: images 0..8 (0 to 3.6 mm) are covered
    folder = write_record(tmp_path / "rec", device_mm=4.0, images_mm=5.0, frames=12)
    out = tmp_path / "e.h5"
    one_error(_run("import-extensometer", str(out), str(folder)), "beyond the device's 4 mm",
              "covers the first 9 of the 12 frames", "--frames 9")
    assert not out.exists()
    r = _run("import-extensometer", str(out), str(folder), "--frames", "9")
    assert r.exit_code == 0, r.output
    assert "x 9 frames" in r.output
    with open_experiment(out) as exp:
        track = exp.read_track("extension")
        assert track.n_frames == 9 and track.time_s[-1] <= exp.read_record("extension").time_s[-1]
    one_error(_run("import-extensometer", str(tmp_path / "f.h5"), str(folder), "--frames", "10"),
              "covers the first 9 of the 10 frames", "--frames 9")
    one_error(_run("import-extensometer", str(tmp_path / "f.h5"), str(folder), "--frames", "13"),
              "--frames 13", "the 12 frames the images have")
    one_error(_run("import-extensometer", str(tmp_path / "f.h5"), str(folder), "--frames", "1"), "--frames")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["e.h5", "rec"]


def test_a_record_that_covers_the_images_is_imported_whole(tmp_path):
    folder = write_record(tmp_path / "rec")
    r = _run("import-extensometer", str(tmp_path / "e.h5"), str(folder))
    assert r.exit_code == 0, r.output
    assert "25 points x 12 frames" in r.output
