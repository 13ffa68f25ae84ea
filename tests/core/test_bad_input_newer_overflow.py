"""A model value the law cannot evaluate over the record (``b = 1e300`` in an exponential element,
or one whose prediction is finite but whose squared residual is not) is refused by predict, fit
and gap diagnose naming the values, instead of ``chi2/sample inf`` with exit 0 and numpy warnings."""

from __future__ import annotations

import warnings

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
def record(tmp_path_factory) -> str:
    """Three seconds of a one-axis extension record (ramp to 4 mm, hold)."""
    return extension_record(tmp_path_factory.mktemp("record") / "rec.csv",
                            2.0 * np.clip(np.arange(300) / 100.0, 0.0, 2.0))


def _model(tmp_path, b: str) -> str:
    text = example_model("extension_relaxation_lumped").read_text()
    assert "\nb = 320.0" in text
    path = tmp_path / "m.toml"
    path.write_text(text.replace("\nb = 320.0", f"\nb = {b}"))
    return str(path)


# 1e300: exp overflows; 1.7e5: exp(b u) ~ 1e295 is finite, its squared residual is not
@pytest.mark.parametrize(("b", "shown"), [("1e300", "lumped.b = 1e+300"), ("1.7e5", "lumped.b = 170000")])
def test_a_value_the_law_cannot_evaluate_is_refused(record, tmp_path, b, shown):
    model = _model(tmp_path, b)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)   # no numpy overflow warning either
        r = _run("predict", model, record)
    one_error(r, "model 'extension-relaxation-lumped'", "in protocol 'rec'", "not a finite number", shown)
    out = tmp_path / "fit"
    one_error(_run("fit", model, record, "--out", str(out)), "cannot be solved at the start of the fit",
              shown, warnings_ok=True)
    r = _run("gap", "diagnose", model, record, "--max-effects", "0")   # progress lines come first
    assert r.exit_code == 2 and "Traceback" not in r.output, r.output
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("error: ") and "not a finite number" in last and shown in last, last
    one_error(_run("predict", model, record, "--set", "lumped.b=320", "--json", "--out",
                   str(tmp_path / "p.h5"), "--set", f"lumped.b={b}"), shown)


def test_a_value_it_can_evaluate_runs(record, tmp_path):
    r = _run("predict", _model(tmp_path, "320.0"), record)
    assert r.exit_code == 0, r.output
    assert "inf" not in r.output
