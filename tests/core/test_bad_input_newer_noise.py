"""A record measured along x alone whose unmeasured y and z components are stored as zeros (not
NaN) is read for a model that reads x only: the noise of a component the model does not read
need not be estimable. A constant component the model reads is still refused, naming it."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.errors import SchemaError
from skinkit.examples import example_model
from skinkit.forward.observations import channels_from_record
from skinkit.schemas import Protocol, RobotRecord
from skinkit.store import create_experiment
from tests.core._cli import one_error

pytestmark = pytest.mark.needs_plugins


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


def _record(constant_force: bool = False) -> RobotRecord:
    """Three seconds at 100 Hz of a pull along x (ramp to 4 mm, hold); y and z stored as 0."""
    t = np.arange(300) / 100.0
    d = 2e-3 * np.clip(t, 0.0, 2.0)
    f = np.zeros_like(t) if constant_force else 0.015 * np.expm1(320 * d) - 0.077 + 1e-3 * np.sin(7 * t)
    z = np.zeros_like(t)
    return RobotRecord(time_s=t, tip_position=np.column_stack([d, z, z]),
                       tip_force=np.column_stack([f, z, z]), protocol=Protocol("pull", kind="external"))


def _session(tmp_path, constant_force: bool = False) -> str:
    path = tmp_path / "s.h5"
    with create_experiment(path) as exp:
        exp.write_record(_record(constant_force), rate_hz=100.0)
    return str(path)


@pytest.fixture(scope="module")
def model() -> str:
    return str(example_model("extension_relaxation_lumped"))


def test_unread_components_stored_as_zeros_need_no_noise(model, tmp_path):
    session = _session(tmp_path)
    r = _run("predict", model, session)
    assert r.exit_code == 0, r.output
    assert "over 300 samples" in r.output
    r = _run("fit", model, session, "--out", str(tmp_path / "fit"))
    assert r.exit_code == 0, r.output


def test_a_constant_component_the_model_reads_is_refused(model, tmp_path):
    one_error(_run("predict", model, _session(tmp_path, constant_force=True)),
              "tip_force", "cannot estimate the noise of tip_force component x (constant signal)")


def test_only_the_components_read_are_spared():
    with pytest.raises(SchemaError, match="component y"):
        channels_from_record(_record())          # every component read: y is constant
    chans = channels_from_record(_record(), components="x")
    assert chans["tip_force"].noise[0] < 0.01 and chans["tip_force"].noise[1:].tolist() == [1.0, 1.0]
    with pytest.raises(SchemaError, match="tip_force component x"):
        channels_from_record(_record(constant_force=True), components="x")
