"""Bad options of the model commands that used to run anyway: an empty --free (fit,
profile-likelihood, design refuse it as gap diagnose does), predict along an axis the model
does not predict, effects visibility of effects that do not apply to the model. One ``error:``
line naming the option, exit 2, nothing written."""

from __future__ import annotations

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


@pytest.fixture(scope="module")
def model() -> str:
    return str(example_model(LUMPED))


@pytest.fixture(scope="module")
def record(tmp_path_factory) -> str:
    """Three seconds of a one-axis extension record (ramp to 4 mm, hold) the lumped model
    predicts along x."""
    return extension_record(tmp_path_factory.mktemp("record") / "rec.csv",
                            2.0 * np.clip(np.arange(300) / 100.0, 0.0, 2.0))


@pytest.mark.parametrize("free", ["", " , "])
def test_fit_refuses_an_empty_free_as_gap_diagnose_does(model, record, tmp_path, free):
    out = tmp_path / "fit"
    # an empty value is refused while the command line is parsed, a list of blanks once read
    why = "no free parameter" if free else "an empty value"
    line = one_error(_run("fit", model, record, "--free", free, "--out", str(out)), "--free", why)
    assert not out.exists()
    again = one_error(_run("gap", "diagnose", model, record, "--free", free, "--max-effects", "0"),
                      "--free", why)
    assert again.split(" (see ")[0] == line.split(" (see ")[0]


def test_profile_likelihood_and_design_refuse_an_empty_free(model, record, tmp_path):
    out = tmp_path / "profile"
    one_error(_run("profile-likelihood", model, record, "--parameter", "lumped.a", "--free", "",
                   "--out", str(out)), "--free", "an empty value")
    assert not out.exists()
    one_error(_run("design", model, record, "--free", ""), "--free", "an empty value")


@pytest.mark.parametrize("as_json", [[], ["--json"]])
def test_predict_on_an_axis_the_model_does_not_predict(model, record, tmp_path, as_json):
    out = tmp_path / "p.h5"
    one_error(_run("predict", model, record, "--axis", "y", "--out", str(out), *as_json),
              "--axis y", "no sample", "predicted on that axis", "the x axis")
    assert list(tmp_path.iterdir()) == []
    ok = _run("predict", model, record, "--axis", "x", *as_json)
    assert ok.exit_code == 0, ok.output
    assert ('"samples": 300' if as_json else "over 300 samples") in ok.output


@pytest.mark.parametrize("as_json", [[], ["--json"]])
def test_effects_visibility_refuses_when_no_effect_applies(model, record, as_json):
    args = ("effects", "visibility", model, "--session", record, *as_json)
    one_error(_run(*args, "--effects", "prestress"), "--effects 'prestress'", "does not apply",
              "'lumped' model")
    one_error(_run(*args, "--effects", "prestress,fascia"), "prestress, fascia", "none applies",
              "'lumped' model")


def test_effects_visibility_names_an_empty_or_unknown_effect(model, record):
    args = ("effects", "visibility", model, "--session", record)
    one_error(_run(*args, "--effects", ""), "--effects", "an empty value")
    one_error(_run(*args, "--effects", "force-offset,relaxation"), "--effects 'relaxation'", "no such effect")


def test_effects_visibility_reports_an_inapplicable_effect_beside_one_that_applies(model, record):
    r = _run("effects", "visibility", model, "--session", record, "--effects", "prestress,force-offset")
    assert r.exit_code == 0, r.output
    assert "prestress" in r.output and "does not apply" in r.output and "force-offset" in r.output
