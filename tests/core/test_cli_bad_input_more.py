"""More bad input, command by command: each bad input is one ``error:`` line
(exit 2) naming what is wrong, refused before work and leaving no file behind.

sysid's IRF size and a record declaring rows it never stored, ``--incremental`` on a record
that is not incremental, names with ``/`` or ``..``, fractional protocol counts, NaN through
float options, the board views given as skin images, and the model-file tables the forward
models read (``[session]``, ``[surface]``, ``[drive]``, ``[[instrument]]``, ``[[fields]]``,
``[[effects]]``, ``bindings``).
"""

from __future__ import annotations

import math
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from skinkit.cli import cli
from skinkit.cli._types import FiniteFloat
from skinkit.errors import SchemaError, SkinkitError
from skinkit.schemas import CameraModel, CameraRig, ImageSequence, Protocol, RobotRecord, SurfaceProfile
from skinkit.store import create_experiment, open_experiment
from tests.core._cli import commands, one_error

from ._model_files import base_spec, write

pytestmark = pytest.mark.needs_plugins


def _one_error(r, *needles: str) -> str:
    return one_error(r, *needles, warnings_ok=True)


def _tree(root: Path) -> dict[str, int]:
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in sorted(root.rglob("*"))}


def _stochastic(n: int, rate: float = 1000.0, mean: float = 1.0,
                seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A band-limited random force [N] about ``mean`` and the position [m] of a spring-damper
    (K = 100 N/m, B = 0.5 N s/m) it drives: a record sysid accepts."""
    from scipy import signal

    rng = np.random.default_rng(seed)
    f = signal.sosfiltfilt(signal.butter(4, 100, fs=rate, output="sos"), rng.standard_normal(n))
    f = 0.3 * f / f.std() + mean
    b, a = signal.bilinear([1.0], [0.5, 100.0], fs=rate)
    return f, signal.lfilter(b, a, f - mean) + mean / 100.0


def _csv(path: Path, f: np.ndarray, y: np.ndarray, rate: float = 1000.0) -> Path:
    t = np.arange(f.size) / rate
    with open(path, "w") as fh:
        fh.write("time_s,force_N,position_m\n")
        np.savetxt(fh, np.column_stack([t, f, y]), delimiter=",")
    return path


def _h5(path: Path, f: np.ndarray, y: np.ndarray, rate: float = 1000.0) -> Path:
    F = np.zeros((f.size, 3))
    P = np.zeros((f.size, 3))
    F[:, 2], P[:, 2] = f, y
    with create_experiment(path) as exp:
        exp.write_record(RobotRecord(time_s=np.arange(f.size) / rate, tip_force=F, tip_position=P,
                                     protocol=Protocol("stoch", kind="force")))
    return path


# ---- sysid: sizes that cannot be allocated are refused before allocating ------------------

def test_irf_over_the_lag_limit_is_refused_with_its_size(tmp_path, monkeypatch):
    from skinkit.sysid.checks import SysidError, check_irf_size

    # 50,001 lags: a 50,001^2 matrix of 8-byte numbers and LAPACK's workspace, 32 L^2 bytes = 80 GB
    with pytest.raises(SysidError, match=r"50,001 lags.*80 GB.*4,096 lags.*4\.095 s"):
        check_irf_size(50_001, 1000.0, 50.0)
    check_irf_size(4096, 1000.0, 4.095)  # at the limit: accepted
    # through the CLI, with a limit low enough for a small record: the same refusal, one line
    monkeypatch.setenv("SKINKIT_MAX_IRF_LAGS", "100")
    rec = _csv(tmp_path / "r.csv", *_stochastic(4000))
    before = _tree(tmp_path)
    r = CliRunner().invoke(cli, ["sysid", str(rec), "--memory", "0.2"])
    _one_error(r, "201 lags", "limit of 100 lags", "--memory", "SKINKIT_MAX_IRF_LAGS")
    assert _tree(tmp_path) == before
    monkeypatch.setenv("SKINKIT_MAX_IRF_LAGS", "none")
    _one_error(CliRunner().invoke(cli, ["sysid", str(rec), "--memory", "0.2"]), "SKINKIT_MAX_IRF_LAGS")


def test_automatic_memory_stays_under_the_lag_limit(monkeypatch):
    from skinkit.sysid.checks import check_signals
    from skinkit.sysid.linear import auto_memory

    f, y = _stochastic(20_000)
    sig = check_signals(f, y, rate_hz=1000.0)
    monkeypatch.setenv("SKINKIT_MAX_IRF_LAGS", "40")
    # the automatic memory is at most 39 / rate (one-sided) and 19 / rate (two-sided lags 2 m + 1)
    assert auto_memory(sig, False, "foh") * 1000.0 <= 39 + 1e-9
    assert auto_memory(sig, True, "foh") * 1000.0 <= 19 + 1e-9


def test_record_declaring_rows_it_never_stored_is_a_damaged_file(tmp_path):
    """A record whose datasets and committed count declare 10^11 samples (2.4 TB) that were
    never written: refused from the file's stored size, without allocating them."""
    path = _h5(tmp_path / "huge.h5", *_stochastic(2000))
    with h5py.File(path, "r+") as h:
        g = h["records/stoch"]
        for k in ("time_s", "tip_force", "tip_position", "flags"):
            g[k].resize((10**11, *g[k].shape[1:]))
        g["committed"][0] = 10**11
    before = _tree(tmp_path)
    r = CliRunner().invoke(cli, ["sysid", str(path)])
    _one_error(r, "huge.h5", "100,000,000,000 rows", "damaged")
    assert _tree(tmp_path) == before
    with open_experiment(path) as exp, pytest.raises(SkinkitError, match="never written"):
        exp.read_record("stoch")


def test_incremental_analysis_of_a_record_that_does_not_step_its_mean(tmp_path):
    f, y = _stochastic(20_000)
    r = CliRunner().invoke(cli, ["sysid", str(_csv(tmp_path / "one.csv", f, y)), "--incremental"])
    _one_error(r, "not an incremental protocol", "1 stochastic segment", "without --incremental")
    # two stochastic parts at one mean force with a hold between them: two segments, one level
    f2, y2 = _stochastic(8000, seed=1)
    hold = np.full(3000, 1.0)
    f = np.concatenate([f2[:4000], hold, f2[4000:]])
    y = np.concatenate([y2[:4000], hold / 100.0, y2[4000:]])
    r = CliRunner().invoke(cli, ["sysid", str(_csv(tmp_path / "two.csv", f, y)), "--incremental"])
    _one_error(r, "not an incremental protocol", "2 stochastic segments", "mean force")


# ---- names that are paths ------------------------------------------------------------------

@pytest.fixture
def images(tmp_path):
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(0)
    for cam in ("cam0", "cam1"):
        (tmp_path / cam).mkdir()
        for i in range(2):
            img = (rng.random((24, 32)) * 255).astype("uint8")
            cv2.imwrite(str(tmp_path / cam / f"img_{i:03d}.png"), img)
    return tmp_path


@pytest.mark.parametrize(("args", "needles"), [
    (["--name", "a/b"], ["--name", "'a/b'"]),
    (["--name", ".."], ["--name", "'..'"]),
    (["--name", "x\\y"], ["--name"]),
    (["--name", "a", "--camera", "c/0", "cam0"], ["--camera", "'c/0'"]),
    (["--fps", "nan"], ["--fps", "finite"]),
    (["--fps", "0"], ["--fps"]),
])
def test_import_images_refuses_path_like_names_before_work(images, args, needles):
    cams = ["--camera", "c0", str(images / "cam0"), "--camera", "c1", str(images / "cam1")]
    if "--camera" in args:  # the bad camera replaces the first
        cams = cams[3:]
    before = _tree(images)
    r = CliRunner().invoke(cli, ["import-images", str(images / "e.h5"), *cams, *args])
    _one_error(r, *needles)
    assert _tree(images) == before


def test_store_refuses_names_that_are_paths(tmp_path):
    prof = SurfaceProfile(points=np.zeros((3, 3)), quality=np.ones(3))
    with create_experiment(tmp_path / "e.h5") as exp:
        for bad in ("a/b", "..", "x..y", "", "a\\b"):
            with pytest.raises(SchemaError, match="profile name"):
                exp.write_profile(bad, prof)
        with pytest.raises(SchemaError, match="image sequence name"):
            with exp.image_writer("../x", ["c0"], (4, 4)):
                pass
        with pytest.raises(SchemaError, match="calibration name"):
            exp.write_calibration("a/b", {})
        exp.write_profile("ok", prof)
        assert exp.profile_names() == ["ok"] and exp.image_names() == []


def test_fractional_protocol_count_is_refused_not_truncated(tmp_path):
    for param in ("periods=1.5", "seed=2.5"):
        proto = "normal_indentation" if param.startswith("periods") else "stochastic_full_scale"
        r = CliRunner().invoke(cli, ["robot", "run", proto, "--param", param,
                                     "--out", str(tmp_path / "r.h5")])
        _one_error(r, f"parameter '{param.split('=')[0]}'", "whole number", param.split("=")[1])
        assert not (tmp_path / "r.h5").exists()


# ---- float options refuse NaN and infinities -------------------------------------------------

def test_every_float_option_is_finite_only():
    """click's FloatRange compares NaN false with every bound and lets it through: every float
    option of every command is a FiniteFloat (the contract test then tries nan and inf on each)."""
    import click

    floats = [(path, p.opts[0], p.type) for path, cmd in commands(cli, click.Context(cli))
              for p in cmd.params if isinstance(p.type, click.types.FloatParamType)]
    assert len(floats) >= 15
    assert [f for f in floats if not isinstance(f[2], FiniteFloat)] == []
    names = {(path, opt) for path, opt, _ in floats}
    assert {(("fit",), "--ftol"), (("predict",), "--until"), (("effects", "visibility"), "--threshold"),
            (("import-images",), "--fps")} <= names
    for bad in ("nan", "inf", "-inf"):
        with pytest.raises(click.BadParameter):
            FiniteFloat(min=0.0).convert(bad, None, None)


# ---- the board views are not skin images ------------------------------------------------------

def test_profile_refuses_the_calibration_board_views(tmp_path):
    K = np.array([[800.0, 0, 16], [0, 800.0, 12], [0, 0, 1]])
    rig = CameraRig(tuple(CameraModel(n, K, np.zeros(5), np.eye(3), np.array([x, 0.0, 0.1]), (32, 24))
                          for n, x in (("c0", -0.01), ("c1", 0.01))))
    frames = np.zeros((1, 2, 24, 32), np.uint8)
    path = tmp_path / "s.h5"
    with create_experiment(path) as exp:
        exp.write_rig(rig)
        exp.write_images(ImageSequence("calib", frames, ("c0", "c1"), [0.0]))
        exp.write_images(ImageSequence("skin", frames, ("c0", "c1"), [0.0]))
        exp.write_calibration("rig", {"images": "calib", "rms_px": 0.1})
    before = _tree(tmp_path)
    for sub in ("profile", "track-3d"):
        r = CliRunner().invoke(cli, ["vision", sub, str(path), "--images", "calib"])
        _one_error(r, "--images 'calib'", "board views", "skin", "(skin)")
    assert _tree(tmp_path) == before


# ---- the model-file tables the forward models read ---------------------------------------------

_FIELD = {"name": "inc", "kind": "inclusion", "x": 0, "y": 0, "radius": "1 mm", "ratio": 2, "layers": ["top"]}

# (tables set on the base model, entry named, words of the reason or the accepted range)
SPEC_CASES = [
    ({"session": {"protocol": ["normal_indentation"]}}, "session.protocol", "did you mean 'protocols'"),
    ({"session": {"protocols": ["normal_indentaton"]}}, "session.protocols[0]",
     "did you mean 'normal_indentation'"),
    ({"session": {"protocols": [3]}}, "session.protocols[0]", "string"),
    ({"session": {"protocols": ["normal_indentation"] * 2}}, "session.protocols", "twice"),
    ({"session": {"parameters": {"normal_indentation": {"period": 2}}}},
     "session.parameters.normal_indentation.period", "did you mean 'periods'"),
    ({"session": {"parameters": {"normal_indentation": {"periods": math.nan}}}},
     "session.parameters.normal_indentation.periods", "finite"),
    ({"session": {"parameters": {"normal_indentation": {"periods": 1.5}}}},
     "session.parameters.normal_indentation.periods", "whole number"),
    ({"session": 3}, "session", "expected a table"),
    ({"surface": {"fitt": True}}, "surface.fitt", "did you mean 'fit'"),
    ({"surface": {"fit": 1}}, "surface.fit", "true, false or \"auto\""),
    ({"surface": {"outside": "clip"}}, "surface.outside", "\"error\" or \"nearest\""),
    ({"drive": {"max_stp": 0.1}}, "drive.max_stp", "did you mean 'max_step'"),
    ({"drive": {"max_step": -1}}, "drive.max_step", "(0, 10000] s"),
    ({"drive": {"max_step": 1e9}}, "drive.max_step", "(0, 10000] s"),
    ({"drive": {"max_step": math.nan}}, "drive.max_step", "finite"),
    ({"drive": {"max_step": "1 mm"}}, "drive.max_step", "not a unit of 's'"),
    ({"instrument": [{"kind": "bias", "parameter": "b", "channel": "tip_force", "compnent": 2}]},
     "instrument[0].compnent", "did you mean 'component'"),
    ({"instrument": [{"kind": "bias", "parameter": "b", "channel": "tip_force", "component": True}]},
     "instrument[0].component", "0, 1 or 2"),
    ({"instrument": [{"kind": "bias", "parameter": 5, "channel": "tip_force"}]},
     "instrument[0].parameter", "string"),
    ({"instrument": [{"kind": "tilt", "parameter": "t", "value": "100 deg"}]},
     "instrument[0].value", "[-90, 90] deg"),
    ({"instrument": [{"kind": "similarity", "parameter": "s", "channel": "points", "mode": "rotation",
                      "value": "200 deg"}]}, "instrument[0].value", "[-180, 180] deg"),
    ({"instrument": [{"kind": "similarity", "parameter": "s", "channel": "points", "value": -2}]},
     "instrument[0].value", "value > -1"),
    ({"instrument": {"kind": "bias"}}, "instrument", "array of tables"),
    ({"fields": [{**_FIELD, "widht": 1}]}, "fields[0].widht", "did you mean 'width'"),
    ({"fields": [{**_FIELD, "name": 3}]}, "fields[0].name", "string"),
    ({"fields": [{**_FIELD, "kind": "inclusio"}]}, "fields[0].kind", "'inclusion'"),
    ({"fields": [{**_FIELD, "layers": [1]}]}, "fields[0].layers", "names of the layers"),
    ({"fields": [{**_FIELD, "ratio": -1}]}, "fields[0].ratio", "positive"),
    ({"fields": [{**_FIELD, "radius": "-1 mm"}]}, "fields[0].radius", "positive"),
    ({"fields": [{**_FIELD, "a": "2 mm", "b": "1 mm"}]}, "fields[0]", "either radius"),
    ({"fields": [{**{k: v for k, v in _FIELD.items() if k != "radius"}, "a": "2 mm"}]}, "fields[0]",
     "needs ['b']"),
    ({"fields": [{**{k: v for k, v in _FIELD.items() if k != "radius"}, "a": "2 mm", "b": "-1 mm"}]},
     "fields[0].b", "positive"),
    ({"fields": [{**_FIELD, "ratio": "2 kPa"}]}, "fields[0].ratio", "inconsistent units"),
    ({"fields": [{"name": "s", "kind": "softening", "softening": 1.0, "layers": ["top"]}]},
     "fields[0].softening", "[0, 1)"),
    ({"fields": [{"name": "s", "kind": "softening", "layers": ["top"]}]}, "fields[0].softening", "required"),
    ({"effects": [{"name": "prestres"}]}, "effects[0].name", "did you mean 'prestress'"),
    ({"effects": [{"name": 5}]}, "effects[0].name", "string"),
    ({"effects": [{"name": "prestress", "l11": 1.1}]}, "effects[0].l11", "did you mean 'l1'"),
    ({"effects": {"name": "prestress"}}, "effects", "array of tables"),
    ({"bindings": {"a": 3}}, "bindings.a", "parameter name"),
]


@pytest.mark.parametrize(("tables", "entry", "words"), SPEC_CASES,
                         ids=[c[1] + ":" + c[2][:20] for c in SPEC_CASES])
def test_forward_tables_are_checked_by_solve_and_by_the_forward_reader(tmp_path, tables, entry, words):
    from skinkit.forward import read_description

    spec = base_spec()
    spec.update(tables)
    model = write(spec, tmp_path / "m.toml")
    before = _tree(tmp_path)
    r = CliRunner().invoke(cli, ["solve", str(model), "--no-vtu", "--out", str(tmp_path / "out")])
    line = _one_error(r, f"{entry}:", words)
    assert _tree(tmp_path) == before
    # predict, fit, gap, effects and the lab read the description through read_description
    with pytest.raises(SkinkitError) as exc:
        read_description(spec)
    assert str(exc.value) == line.removeprefix("error: ")


def test_unknown_effect_lists_the_installed_ones(tmp_path):
    from skinkit import registry

    spec = base_spec()
    spec["effects"] = [{"name": "no-such-effect"}]
    r = CliRunner().invoke(cli, ["solve", str(write(spec, tmp_path / "m.toml")), "--no-vtu"])
    line = _one_error(r, "effects[0].name", "installed:")
    assert all(n in line for n in registry.names("skinkit.effects"))


def test_the_example_models_and_the_lab_descriptions_pass(tmp_path):
    from skinkit.forward import read_description
    from skinkit.lab.forearm import model_spec, truth_spec

    for f in sorted(Path(__file__).parents[2].joinpath("docs", "models").glob("*.toml")):
        read_description(f)
    read_description(model_spec())
    read_description(truth_spec())


def test_documented_ranges_are_the_enforced_ones():
    """The model-file reference's table of checks states the limits the readers enforce."""
    from skinkit.fem import model as M
    from skinkit.forward.spec_check import MAX_DRIVE_STEP_S

    page = Path(__file__).parents[2].joinpath("docs", "reference", "model-files.md")
    doc = page.read_text(encoding="utf-8")

    def g(x: float) -> str:  # 1e+06 as 1e6, 1e-06 as 1e-6
        return f"{x:g}".replace("e+0", "e").replace("e-0", "e-").replace("e+", "e")

    lo, hi = M.INTORDER_RANGE
    facts = [f"1 to {M.MAX_ELEMENTS_PER_DIRECTION} per direction", f"(0, {g(M.LENGTH_RANGE[1])}] m",
             f"in [{g(M.PRESTRETCH_RANGE[0])}, {g(M.PRESTRETCH_RANGE[1])}]", f"{M.MAX_UNKNOWNS:,} unknowns",
             f"at most {g(M.MAX_FORCE_N)} N", f"1 to {M.MAX_STEPS:,}", f"(0, {g(M.DURATION_RANGE[1])}] s",
             f"[{g(M.FREQUENCY_RANGE[0])}, {g(M.FREQUENCY_RANGE[1])}] Hz", f"(0, {g(M.RTOL_RANGE[1])}]",
             f"{lo} to {hi}", f"at most {g(M.MAX_MODULUS_PA)} Pa", f"(0, {g(MAX_DRIVE_STEP_S)}] s"]
    assert [f for f in facts if f not in doc] == []
