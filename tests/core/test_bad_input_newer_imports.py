"""Bad input of the import commands that used to be taken: a tracks CSV whose frame is not a
non-negative whole number or whose ``valid`` is not 0/1, and empty name options (refused
naming the option, not by the schema a level below). One ``error:`` line, exit 2, no file
written."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.store import open_experiment
from tests.core._cli import one_error


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


@pytest.mark.parametrize(("body", "line", "needles"), [
    ("-1,1,0,0\n0,1,1,1\n", 2, ["column 'frame'", "'-1'", "non-negative whole number"]),
    ("0,1,0,0\n1.5,1,1,1\n", 3, ["column 'frame'", "'1.5'", "non-negative whole number"]),
    ("0,1,0,0\ninf,1,1,1\n", 3, ["column 'frame'", "'inf'"]),
])
def test_import_tracks_refuses_a_frame_that_is_not_an_index(tmp_path, body, line, needles):
    csv = tmp_path / "dic.csv"
    csv.write_text("frame,point,x_mm,y_mm\n" + body)
    exp = tmp_path / "s.h5"
    one_error(_run("import-tracks", str(exp), str(csv)), f"dic.csv:line {line}", *needles)
    assert not exp.exists()


@pytest.mark.parametrize(("flag", "shown"), [("2", "'2'"), ("-1", "'-1'"), ("0.5", "'0.5'"), ("", "''")])
def test_import_tracks_refuses_a_valid_flag_other_than_0_or_1(tmp_path, flag, shown):
    csv = tmp_path / "dic.csv"
    csv.write_text(f"frame,point,x_mm,y_mm,valid\n0,1,0,0,1\n1,1,1,1,{flag}\n")
    exp = tmp_path / "s.h5"
    one_error(_run("import-tracks", str(exp), str(csv)), "dic.csv:line 3", "column 'valid'", shown, "0 or 1")
    assert not exp.exists()


def test_import_tracks_takes_0_and_1(tmp_path):
    csv = tmp_path / "dic.csv"
    csv.write_text("frame,point,x_mm,y_mm,valid\n0,1,0,0,1\n1,1,1,1,0\n2,1,2,2,1.0\n")
    exp = tmp_path / "s.h5"
    r = _run("import-tracks", str(exp), str(csv))
    assert r.exit_code == 0, r.output
    with open_experiment(exp) as e:
        assert e.read_track("dic").valid.tolist() == [[True, False, True]]


@pytest.mark.parametrize(("value", "got"), [("", "an empty value"), ("  ", "got only blanks")])
def test_empty_protocol_and_name_options_are_named(tmp_path, value, got):
    def expected(option: str, what: str) -> str:
        # an empty value is refused while the command line is parsed; blanks as a bad name
        return f"'{option}'" if not value else f"{option}: expected {what}"

    folder = tmp_path / "raw"
    folder.mkdir()
    exp = tmp_path / "s.h5"
    one_error(_run("import-extensometer", str(exp), str(folder), "--protocol", value),
              expected("--protocol", "a protocol name"), got)
    csv = tmp_path / "rec.csv"
    csv.write_text("time_s,force_N\n0,0\n0.01,0.1\n")
    one_error(_run("import-csv", str(exp), str(csv), "--protocol", value),
              expected("--protocol", "a protocol name"), got)
    tracks = tmp_path / "dic.csv"
    tracks.write_text("frame,point,x_mm,y_mm\n0,1,0,0\n")
    one_error(_run("import-tracks", str(exp), str(tracks), "--name", value),
              expected("--name", "a track name"), got)
    one_error(_run("import-images", str(exp), "--name", value, "--camera", "c0", str(folder)),
              expected("--name", "an image sequence name"), got)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dic.csv", "raw", "rec.csv"]
