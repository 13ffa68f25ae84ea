"""``--until`` that cuts a record before its second sample is refused naming the option, the value
and the record's time span (not the session, for a channel the cut removed), by every command that
cuts: fit, predict, gap diagnose."""

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


@pytest.mark.parametrize("until", ["1e-6", "0.005"])
def test_a_cut_that_leaves_no_sample_is_named(model, record, tmp_path, until):
    needles = (f"--until {float(until):g} s", "leaves no samples", "'rec'", "spans 0 to 0.99 s")
    out = tmp_path / "fit"
    line = one_error(_run("fit", model, record, "--until", until, "--out", str(out)), *needles)
    assert "channel" not in line.split("(")[0] and not out.exists()
    one_error(_run("predict", model, record, "--until", until), *needles)
    one_error(_run("gap", "diagnose", model, record, "--until", until, "--max-effects", "0"), *needles)


def test_a_cut_that_keeps_samples_runs(model, record):
    r = _run("predict", model, record, "--until", "0.01")
    assert r.exit_code == 0, r.output
    assert "over 2 samples" in r.output
