"""An empty name option whose default is made later (``fit --name``, ``gap diagnose
--name``, ``vision track-3d --name``) is refused naming the option, as the import commands refuse
theirs, instead of being taken as the default. One ``error:`` line, exit 2, nothing written."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.examples import example_model
from tests.core._cli import extension_record, one_error

pytestmark = pytest.mark.needs_plugins


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


@pytest.fixture(scope="module")
def model() -> str:
    return str(example_model("extension_relaxation_lumped"))


@pytest.fixture(scope="module")
def record(tmp_path_factory) -> str:
    """One second at 100 Hz of a one-axis extension record (ramp to 1 mm)."""
    return extension_record(tmp_path_factory.mktemp("record") / "rec.csv", np.arange(100) / 100.0)


@pytest.mark.parametrize(("value", "got"), [("", "got an empty string"), ("  ", "got only blanks")])
def test_fit_and_gap_diagnose_refuse_an_empty_name(model, record, tmp_path, monkeypatch, value, got):
    monkeypatch.chdir(tmp_path)
    one_error(_run("fit", model, record, "--name", value), "--name: expected a fit name", got)
    one_error(_run("fit", model, record, "--name", value, "--out", str(tmp_path / "fit")),
              "--name: expected a fit name", got)
    one_error(_run("gap", "diagnose", model, record, "--name", value, "--max-effects", "0"),
              "--name: expected a report name", got)
    assert list(tmp_path.iterdir()) == []


def test_vision_track_3d_refuses_an_empty_name_before_reading(tmp_path):
    one_error(_run("vision", "track-3d", str(tmp_path / "s.h5"), "--name", ""),
              "--name: expected a track name", "got an empty string")


def test_vision_profile_refuses_an_empty_name_before_reading(tmp_path):
    one_error(_run("vision", "profile", str(tmp_path / "s.h5"), "--name", ""),
              "--name: expected a profile name", "got an empty string")
