"""``--protocols``: read only the records a model describes (an experiment file may also hold
records of another test, as the demo's holds stochastic records beside the FE protocols)."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from tests.core._cli import one_error

# the laws, effects and optimisers these tests use are built-in plugins
pytestmark = pytest.mark.needs_plugins

MODEL = """[model]
kind = "lumped"
name = "relax"

[lumped]
test = "indentation"
family = "quasi-static"
axis = "-z"
drive = "tip_position"
elastic = "exponential"
relaxation = [{ g = 0.3, tau = "3 s" }]

[lumped.parameters]
a = "15 mN"
b = 800.0

[session]
protocols = ["preconditioning", "normal_indentation"]
"""
WANTED = "preconditioning,normal_indentation"


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    from skinkit.lab.lumped import LumpedTruth, stochastic_session
    from skinkit.lab.session import make_session
    from skinkit.pipelines.acquire import stream_records

    d = tmp_path_factory.mktemp("protocols")
    model = d / "relax.toml"
    model.write_text(MODEL)
    s = d / "s.h5"
    make_session(model, s, d / "truth.json", seed=1)
    # a stochastic force record of another (lumped dynamic) test in the same file
    stream_records(s, [stochastic_session(LumpedTruth(), wiener=False, seed=0)], block=1000, append=True)
    return model, s


def test_predict_and_fit_read_only_the_named_records(session, tmp_path):
    model, s = session
    run = CliRunner().invoke
    # every record read: the stochastic one too (along z, as this model reads it; its x and y are
    # stored as zeros, which this model does not read), though the model does not describe it
    res = run(cli, ["predict", str(model), str(s), "--json"])
    assert res.exit_code == 0, res.output
    assert set(json.loads(res.stdout)["protocols"]) == {"preconditioning", "normal_indentation",
                                                        "stochastic_linear"}
    res = run(cli, ["predict", str(model), str(s), "--protocols", WANTED, "--json"])
    assert res.exit_code == 0, res.output
    assert set(json.loads(res.stdout)["protocols"]) == {"preconditioning", "normal_indentation"}
    res = run(cli, ["fit", str(model), str(s), "--protocols", WANTED, "--free", "lumped.a",
                    "--out", str(tmp_path / "fit"), "--name", "fit-a", "--json"])
    assert res.exit_code == 0, res.output
    fit = json.loads(res.stdout)
    # the model is the truth: chi2 per degree of freedom at the noise level (62,000 samples:
    # +-0.02 at 3 sigma, plus about 1 % from the recorded drive's own noise), and a = 15 mN to
    # within the bias that recorded drive leaves (errors in variables: a fraction of a percent)
    assert 0.95 < fit["chi2_per_dof"] < 1.05, fit["chi2_per_dof"]
    assert abs(fit["parameters"]["lumped.a"]["value"] / 0.015 - 1) < 0.01, fit["parameters"]["lumped.a"]


def test_a_record_the_file_lacks_is_named(session):
    model, s = session
    run = CliRunner().invoke
    for cmd in (["predict"], ["fit"], ["gap", "diagnose"]):
        one_error(run(cli, [*cmd, str(model), str(s), "--protocols", "nope"]), "nope", "normal_indentation")
