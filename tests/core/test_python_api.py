"""The one-call Python API (``skinkit.fit``, ``skinkit.diagnose``) and what results show a person.

A model is accepted as a path, a description or a loaded forward model, a session as a path or
observations, with the same result; a one-axis CSV record is read along the model's axis;
progress goes to standard error unless turned off; results print in a few lines without arrays,
show as an HTML table in a notebook and give pandas tables.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import skinkit
from skinkit.api import Progress, description
from skinkit.examples import example_model
from skinkit.forward import load, read_description
from skinkit.schemas import FitResult, GapReport, Observations, Parameter, ParameterSet
from skinkit.schemas.display import FIT_COLUMNS, MAX_LINES
from skinkit.schemas.display_gap import CANDIDATE_COLUMNS, CELL_COLUMNS

#: the shipped lumped model: displacement in, force out, along x ([lumped] axis = "x")
MODEL = example_model("extension_relaxation_lumped")
#: what the virtual lab's truth has and the model lacks
RELAXATION = {"name": "viscoelastic", "g1": 0.3, "tau1": "2 s"}


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A virtual session of the model with a relaxation added (one in-plane record along x)."""
    pytest.importorskip("skinkit_plugins")
    from skinkit.lab.session import make_session

    d = tmp_path_factory.mktemp("api")
    truth = {**read_description(MODEL), "effects": [RELAXATION]}
    make_session(truth, d / "session.h5", d / "truth.json", seed=3, protocols="in_plane_000")
    return d / "session.h5"


@pytest.fixture(scope="module")
def csv_record(session: Path) -> Path:
    """The session's record as a CSV of one-axis columns (the x components), every 5th sample."""
    from skinkit.store import open_experiment

    with open_experiment(session) as exp:
        rec = exp.read_record("in_plane_000")
    t, x, f = rec.time_s[::5], rec.tip_position[::5, 0], rec.tip_force[::5, 0]
    out = session.parent / "record.csv"
    lines = ["time_s,displacement_mm,force_N"] + [f"{a:.4f},{b * 1e3:.6f},{c:.6f}"
                                                  for a, b, c in zip(t, x, f, strict=True)]
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return out


@pytest.fixture(scope="module")
def fitted(session: Path) -> FitResult:
    return skinkit.fit(MODEL, session, progress=False)


@pytest.fixture(scope="module")
def report(session: Path) -> GapReport:
    return skinkit.diagnose(MODEL, session, effects=["viscoelastic"], max_effects=1, progress=False)


def _same_fit(a: FitResult, b: FitResult) -> None:
    assert a.parameters.names == b.parameters.names
    np.testing.assert_allclose(list(a.parameters.values().values()), list(b.parameters.values().values()),
                               rtol=1e-9)
    assert a.objective == pytest.approx(b.objective, rel=1e-9)


# -- models and sessions in any form ------------------------------------------------------------
def test_import_skinkit_loads_no_engine_until_fit_is_asked_for():
    code = ("import sys, skinkit; assert 'skinkit.api' not in sys.modules and 'numpy' not in sys.modules; "
            "import skinkit.api; assert skinkit.fit is skinkit.api.fit and skinkit.diagnose is "
            "skinkit.api.diagnose; assert {'fit', 'diagnose'} <= set(dir(skinkit))")
    subprocess.run([sys.executable, "-c", code], check=True)
    with pytest.raises(AttributeError, match="no attribute 'fitt'"):
        skinkit.fitt   # noqa: B018


@pytest.mark.needs_plugins
def test_paths_descriptions_and_loaded_objects_give_the_same_fit(session, fitted):
    from skinkit.forward.session import read_session

    _same_fit(fitted, skinkit.fit(read_description(MODEL), str(session), progress=False))
    with load(MODEL) as model:
        obs = read_session(model, session)
        _same_fit(fitted, skinkit.fit(model, obs, progress=False))
        model.parameters()   # left open: still usable after the call
    assert fitted.converged and fitted.chi2_per_dof == pytest.approx(1.0, abs=0.1)


@pytest.mark.needs_plugins
def test_a_loaded_model_is_diagnosed_as_its_model_file(session, report):
    with load(MODEL) as model:
        again = skinkit.diagnose(model, session, effects="viscoelastic", max_effects=1, progress=False)
    assert again.named == report.named == ["viscoelastic"]
    assert again.fit["chi2_per_dof"] == pytest.approx(report.fit["chi2_per_dof"], rel=1e-9)


@pytest.mark.needs_plugins
def test_a_loaded_models_description_keeps_its_effects():
    spec = {**read_description(MODEL), "effects": [{**RELAXATION, "g1": 0.2}]}
    with load(spec) as model, load(description(model)) as back:
        assert back.parameters() == model.parameters()
        assert back.parameters()["viscoelastic.g1"] == pytest.approx(0.2)


@pytest.mark.needs_plugins
def test_a_csv_record_is_read_along_the_model_axis(session, csv_record, fitted):
    assert read_description(MODEL)["lumped"]["axis"] == "x"
    from_csv = skinkit.fit(MODEL, csv_record, progress=False)
    assert from_csv.converged and from_csv.chi2_per_dof == pytest.approx(1.0, abs=0.1)
    # the same record, a fifth of its samples: the same elastic element within its uncertainty
    a, se = fitted.parameters["lumped.a"], fitted.se["lumped.a"]
    assert abs(from_csv.parameters["lumped.a"] - a) < 5 * se
    report = skinkit.diagnose(MODEL, csv_record, effects=["viscoelastic"], max_effects=0, progress=False)
    assert report.fit["chi2_per_dof"] == pytest.approx(from_csv.chi2_per_dof, rel=0.05)


@pytest.mark.needs_plugins
def test_a_record_read_along_another_axis_is_named_as_the_cause(csv_record):
    from skinkit.forward.observations import read_observations
    from skinkit.inverse.fit import FitError, fit

    along_z = read_observations(csv_record)     # no model: the one-axis columns go to z
    with load(MODEL) as model, pytest.raises(FitError) as err:
        fit(model, along_z)
    msg = str(err.value)
    assert "hold component(s) z only" in msg and "reads x" in msg and "axis='x'" in msg


def test_a_missing_session_or_a_wrong_model_is_a_clear_error(tmp_path):
    with pytest.raises(skinkit.StoreError, match="no such session file"):
        skinkit.fit(MODEL, tmp_path / "none.h5", progress=False)
    with pytest.raises(skinkit.SkinkitError, match="no such model file"):
        skinkit.fit(tmp_path / "none.toml", tmp_path / "none.h5", progress=False)
    with pytest.raises(skinkit.SkinkitError, match="expected a model file's path"):
        skinkit.diagnose(42, tmp_path / "none.h5", progress=False)


# -- progress -----------------------------------------------------------------------------------
@pytest.mark.needs_plugins
def test_progress_goes_to_stderr_by_default_and_nowhere_with_false(session, capfd):
    skinkit.fit(MODEL, session)
    out, err = capfd.readouterr()
    lines = err.splitlines()
    assert out == "" and any(x.startswith("skinkit: fitting") for x in lines)
    assert lines[-1].startswith("skinkit: fit converged") and len(lines) <= 6, lines
    skinkit.fit(MODEL, session, progress=False)
    assert capfd.readouterr() == ("", "")
    said: list[str] = []
    skinkit.fit(MODEL, session, progress=said.append)
    assert capfd.readouterr().err == "" and any(x.startswith("fitting") for x in said)


@pytest.mark.needs_plugins
def test_the_diagnosis_says_each_stage(session, capfd):
    skinkit.diagnose(MODEL, session, effects=["viscoelastic"], max_effects=0)
    err = capfd.readouterr().err
    assert "skinkit: diagnosing extension-relaxation-lumped" in err and "skinkit: calibrating" in err
    assert "skinkit: diagnosis done" in err


def test_lines_inside_a_stage_are_spaced_in_time():
    said: list[str] = []
    p = Progress(said.append, interval_s=10.0)
    p.stage("a stage")
    p.tick("evaluation 1")      # within 10 s of the last line: not said
    assert said == ["a stage"]
    p = Progress(said.append, interval_s=0.0)
    p.tick("evaluation 2")
    assert said[-1] == "evaluation 2"
    with pytest.raises(skinkit.SkinkitError, match="progress"):
        Progress("loud")


# -- what results show --------------------------------------------------------------------------
def _short(text: str) -> None:
    assert len(text.splitlines()) <= MAX_LINES, text
    assert "array(" not in text and "[[" not in text and len(text) < 2000, text


@pytest.mark.needs_plugins
def test_results_print_in_a_few_lines_without_arrays(fitted, report):
    for obj in (fitted, report):
        _short(repr(obj))
    text = repr(fitted)
    assert text.startswith("FitResult extension-relaxation-lumped: converged")
    assert "lumped.a" in text and "±" in text and " N" in text and "objective" in text
    text = repr(report)
    assert text.startswith("GapReport extension-relaxation-lumped") and "named: viscoelastic" in text


@pytest.mark.needs_plugins
def test_sessions_and_predictions_print_in_a_few_lines(session):
    from skinkit.forward.session import read_session

    with load(MODEL) as model:
        obs = read_session(model, session)
        pred = model.predict(model.parameters(), obs, sensitivities=["lumped.a"])
    p = obs["in_plane_000"]
    for obj in (obs, p, p.channels["tip_force"], pred, pred.protocols["in_plane_000"]["tip_force"]):
        _short(repr(obj))
    assert "in_plane_000" in repr(obs) and "tip_force" in repr(pred)
    renamed = {f"p{i}": dataclasses.replace(p, protocol=dataclasses.replace(p.protocol, name=f"p{i}"))
               for i in range(30)}
    many = Observations(renamed, None, "many.h5")
    _short(repr(many))
    assert "and 22 more" in repr(many)


def test_a_fit_with_many_parameters_prints_in_a_few_lines():
    pset = ParameterSet([Parameter(f"k{i}", 1.0 + i, "Pa", 0, 100) for i in range(40)])
    r = FitResult("big", pset, 3.0, 12, se={f"k{i}": 0.1 for i in range(40)},
                  covariance=np.eye(40), correlation=np.eye(40))
    _short(repr(r))
    assert "and 32 more" in repr(r)


@pytest.mark.needs_plugins
def test_the_notebook_view_is_a_table(fitted, report):
    for obj, row in ((fitted, "lumped.a"), (report, "viscoelastic")):
        html = obj._repr_html_()
        assert html.count("<table>") == 1 and "</table>" in html and f"<td>{row}</td>" in html
        assert "array(" not in html


@pytest.mark.needs_plugins
def test_tables_of_parameters_cells_and_candidates(fitted, report):
    pytest.importorskip("pandas")
    df = fitted.to_dataframe()
    assert tuple(df.columns) == FIT_COLUMNS and len(df) == len(fitted.parameters)
    assert df.set_index("parameter").loc["lumped.a", "value"] == fitted.parameters["lumped.a"]
    cand = report.to_dataframe()
    assert tuple(cand.columns) == CANDIDATE_COLUMNS and cand["effect"].tolist() == ["viscoelastic"]
    assert bool(cand["named"].iloc[0])
    cells = report.to_dataframe("cells")
    assert tuple(cells.columns) == CELL_COLUMNS and len(cells) == len(report.gap["cells"])
    assert {"protocol", "channel"} <= set(cells["axis"])
    with pytest.raises(ValueError, match="candidates"):
        report.to_dataframe("rounds")


def test_without_pandas_a_table_names_the_extra(monkeypatch):
    r = FitResult("m", ParameterSet([Parameter("a", 1.0)]), 0.0)
    monkeypatch.setitem(sys.modules, "pandas", None)     # import pandas now fails
    with pytest.raises(ImportError, match=r"pip install skinkit\[table\]"):
        r.to_dataframe()
    with pytest.raises(ImportError, match=r"pip install skinkit\[table\]"):
        GapReport("m").to_dataframe("cells")


def test_the_table_extra_is_declared():
    text = (Path(__file__).resolve().parents[2] / "pyproject.toml").read_text(encoding="utf-8")
    assert 'table = ["pandas' in text
