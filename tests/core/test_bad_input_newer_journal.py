"""``skinkit gap benchmark --recorded-only --journal FILE`` runs nothing, so it writes nothing:
a file that is not a journal is refused as it is, an empty one gets no header, and a journal
whose last line was cut short by a crash is read without being cut."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from skinkit.bench.gap_journal import MAGIC, VERSION, Journal, JournalError
from skinkit.cli import cli
from tests.core._cli import one_error


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


NOT_A_JOURNAL = [b"precious notes\nthe last line without its newline", b"\xff\xfe not text", b'{"a": 1}']


@pytest.mark.needs_plugins
@pytest.mark.parametrize("alternative", [[], ["--alternative"]])
@pytest.mark.parametrize("content", NOT_A_JOURNAL)
def test_recorded_only_refuses_another_file_and_leaves_it_as_it_is(tmp_path, content, alternative):
    path = tmp_path / "notes.txt"
    path.write_bytes(content)
    model = [] if alternative else ["--model", "lumped"]
    one_error(_run("gap", "benchmark", "--quick", *model, *alternative, "--recorded-only",
                   "--journal", str(path)), "not a skinkit gap benchmark journal")
    assert path.read_bytes() == content


@pytest.mark.needs_plugins
@pytest.mark.parametrize("alternative", [[], ["--alternative"]])
def test_recorded_only_writes_no_header_in_an_empty_file(tmp_path, alternative):
    path = tmp_path / "run.jsonl"
    path.write_bytes(b"")
    model = [] if alternative else ["--model", "lumped"]
    r = _run("gap", "benchmark", "--quick", *model, *alternative, "--recorded-only", "--journal", str(path),
             "--json")
    assert r.exit_code == 0, r.output
    assert path.read_bytes() == b""


def _journal_bytes(cut: bytes = b"") -> bytes:
    head = {"journal": MAGIC, "version": VERSION, "settings": {}}
    case = {"case": {"id": "null/None/1000"}}
    return (json.dumps(head) + "\n" + json.dumps(case) + "\n").encode() + cut


def test_read_only_journal_is_never_written(tmp_path):
    path = tmp_path / "run.jsonl"
    content = _journal_bytes(b'{"case": {"id": "effect/mod')
    path.write_bytes(content)
    jr = Journal(path, {}, read_only=True)
    assert list(jr.cases) == ["null/None/1000"] and path.read_bytes() == content
    with pytest.raises(JournalError, match="read-only"):
        jr.add_case({"id": "null/None/1001"})
    assert path.read_bytes() == content
    # a run that records cuts the line short, as before, to append after it
    Journal(path, {})
    assert path.read_bytes() == _journal_bytes()


@pytest.mark.parametrize("content", NOT_A_JOURNAL)
def test_a_file_that_is_not_a_journal_is_not_cut_even_by_a_recording_run(tmp_path, content):
    path = tmp_path / "notes.txt"
    path.write_bytes(content)
    with pytest.raises(JournalError, match="not a skinkit gap benchmark journal"):
        Journal(path, {})
    assert path.read_bytes() == content


def test_read_only_journal_on_an_empty_file(tmp_path):
    path = tmp_path / "run.jsonl"
    path.write_bytes(b"")
    assert not Journal(path, {}, read_only=True).cases
    assert path.read_bytes() == b""


def test_a_header_cut_short_is_read_as_no_task_and_written_again_by_a_recording_run(tmp_path):
    path = tmp_path / "run.jsonl"
    Journal(path, {"model": "m"})
    whole = path.read_bytes()
    path.write_bytes(whole[:25])
    assert not Journal(path, {"model": "m"}, read_only=True).cases
    assert path.read_bytes() == whole[:25]
    Journal(path, {"model": "m"})
    assert path.read_bytes() == whole
