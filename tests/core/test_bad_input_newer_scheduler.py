"""``--scheduler ADDRESS`` is checked before any work starts by every command that has it: an
address that does not parse, or whose port does not answer, is refused in one line naming the
option and the address, even when the model would not have used the cluster. Only loopback
addresses are used."""

from __future__ import annotations

import socket

import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.examples import example_model
from tests.core._cli import extension_record, one_error

pytestmark = pytest.mark.needs_plugins

LUMPED = "extension_relaxation_lumped"


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


def _unused_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def model() -> str:
    return str(example_model(LUMPED))


@pytest.fixture(scope="module")
def record(tmp_path_factory) -> str:
    """Two seconds of a one-axis extension record (ramp to 2 mm) the lumped model predicts."""
    return extension_record(tmp_path_factory.mktemp("record") / "rec.csv",
                            np.clip(np.arange(200) / 100.0, 0.0, 2.0))


@pytest.mark.parametrize("extra", [[], ["--protocols", "rec,rec", "--workers", "2"]])
def test_predict_refuses_an_address_that_does_not_parse(model, record, extra):
    one_error(_run("predict", model, record, "--scheduler", "garbage", *extra),
              "--scheduler 'garbage'", "not a Dask scheduler address", "port")


@pytest.mark.parametrize("extra", [[], ["--workers", "2"]])
def test_predict_refuses_an_unreachable_scheduler(model, record, tmp_path, extra):
    address = f"tcp://127.0.0.1:{_unused_port()}"
    out = tmp_path / "p.h5"
    one_error(_run("predict", model, record, "--scheduler", address, "--out", str(out), *extra),
              f"--scheduler '{address}'", "cannot reach the Dask scheduler")
    assert not out.exists()


def test_predict_refuses_an_empty_address(model, record):
    one_error(_run("predict", model, record, "--scheduler", " "), "--scheduler ' '",
              "expected a Dask scheduler")


def test_predict_takes_an_address_that_answers(model, record):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        r = _run("predict", model, record, "--scheduler", f"tcp://127.0.0.1:{s.getsockname()[1]}")
    assert r.exit_code == 0, r.output
    assert "over 200 samples" in r.output


@pytest.mark.parametrize("alternative", [[], ["--alternative"]])
def test_gap_benchmark_refuses_a_bad_scheduler_before_any_case(tmp_path, alternative):
    journal = tmp_path / "run.jsonl"
    one_error(_run("gap", "benchmark", "--quick", *alternative, "--scheduler", "garbage",
                   "--journal", str(journal)), "--scheduler 'garbage'", "not a Dask scheduler address")
    address = f"tcp://127.0.0.1:{_unused_port()}"
    one_error(_run("gap", "benchmark", "--quick", *alternative, "--scheduler", address,
                   "--journal", str(journal)), f"--scheduler '{address}'", "cannot reach")
    assert not journal.exists()


def test_the_benchmark_pool_refuses_an_unreachable_scheduler_by_name():
    """A Python caller that skips the command line's check: a prompt, named refusal, no hang."""
    from skinkit.bench.gap_cases import BenchmarkError
    from skinkit.bench.task_pool import TaskPool

    address = f"tcp://127.0.0.1:{_unused_port()}"
    with pytest.raises(BenchmarkError, match="cannot reach the Dask scheduler"):
        TaskPool(1, address)


@pytest.mark.parametrize("command", [["fit"], ["gap", "diagnose"]])
def test_fit_and_diagnose_refuse_a_bad_scheduler_before_any_work(model, record, tmp_path, command):
    out = tmp_path / "out"
    one_error(_run(*command, model, record, "--scheduler", "garbage", "--out", str(out)),
              "--scheduler 'garbage'", "not a Dask scheduler address")
    address = f"tcp://127.0.0.1:{_unused_port()}"
    one_error(_run(*command, model, record, "--scheduler", address, "--out", str(out)),
              f"--scheduler '{address}'", "cannot reach the Dask scheduler")
    assert not out.exists()
