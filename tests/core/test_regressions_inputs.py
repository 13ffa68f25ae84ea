"""Regressions for correctness defects: no mutation of inputs, bugs not disguised."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from skinkit.errors import StoreError
from skinkit.schemas import Protocol, RobotRecord
from skinkit.store import create_experiment, open_experiment


def test_check_signals_leaves_the_callers_arrays_alone():
    """A force record with one NaN: the caller's array keeps its NaN and shares no memory
    with the signals returned (they were interpolated in place before)."""
    from skinkit.sysid.checks import check_signals

    rng = np.random.default_rng(0)
    f = rng.standard_normal(4000)
    y = 1e-3 * f + 1e-6 * rng.standard_normal(4000)
    f[1000] = np.nan
    f_before = f.copy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sig = check_signals(f, y, rate_hz=2000.0)
    assert np.isnan(f[1000])
    assert np.array_equal(f, f_before, equal_nan=True)
    for name in ("force_N", "position_m"):
        arr = getattr(sig, name, None)
        if isinstance(arr, np.ndarray):
            assert not np.shares_memory(arr, f)


def test_a_bug_in_a_reader_is_not_reported_as_a_damaged_file(tmp_path, monkeypatch):
    """A TypeError raised by skinkit's own reading code propagates with its traceback; the
    same kind of error raised by h5py on a damaged file becomes a one-line StoreError."""
    path = tmp_path / "s.h5"
    rec = RobotRecord(time_s=np.arange(10) / 100.0, tip_force=np.zeros((10, 3)),
                      protocol=Protocol("p", kind="external"))
    with create_experiment(path) as exp:
        exp.write_record(rec, rate_hz=100.0)
    import skinkit.store.experiment as E

    def buggy(self, g):
        raise TypeError("a bug in skinkit, not in the file")

    monkeypatch.setattr(E.Experiment, "_committed", buggy)
    with open_experiment(path) as exp, pytest.raises(TypeError, match="a bug in skinkit") as info:
        exp.read_record("p")
    # the traceback still reaches the buggy line (it was cut by `from None` before)
    assert info.traceback[-1].name == "buggy"
    assert info.value.__suppress_context__ is False
    monkeypatch.undo()
    # a damaged dataset (h5py raises) is still a StoreError naming the file
    import h5py
    with h5py.File(path, "a") as f:
        del f["records/p/time_s"]
    with open_experiment(path) as exp, pytest.raises(StoreError, match=str(path.name)):
        exp.read_record("p")


def _damaged_file(tmp_path, damage):
    """An experiment file with one record ``p``, a camera rig and a track, then ``damage(h5)``."""
    import h5py

    from skinkit.schemas import SurfaceTrack
    from skinkit.vision.rigs import ring_rig

    path = tmp_path / "d.h5"
    rec = RobotRecord(time_s=np.arange(10) / 100.0, tip_force=np.zeros((10, 3)),
                      protocol=Protocol("p", kind="external"))
    with create_experiment(path) as exp:
        exp.write_record(rec, rate_hz=100.0)
        exp.write_rig(ring_rig(2))
        exp.write_track("t", SurfaceTrack(points=np.zeros((2, 3, 3)), valid=np.ones((2, 3), bool),
                                          time_s=np.arange(3.0)))
    with h5py.File(path, "a") as f:
        damage(f)
    return path


def _set(where, key, value):
    def damage(f):
        f[where].attrs[key] = value
    return damage


def _committed(data):
    def damage(f):
        del f["records/p/committed"]
        f["records/p"]["committed"] = data
    return damage


# (damage, reader, words of the one-line error): values read from the file that skinkit's own
# code converts; before, each escaped as a bare ValueError/TypeError/AttributeError (a "bug")
FILE_DAMAGE = [
    (_set("records/p", "rate_hz", "fast"), lambda e: e.record_info("p"), "records/p@rate_hz"),
    (_set("records/p", "protocol", "[1]"), lambda e: e.record_info("p"), "records/p@protocol"),
    (_set("records/p", "channels", "5"), lambda e: e.record_info("p"), "records/p@channels"),
    (_set("records/p", "complete", "yes"), lambda e: e.record_info("p"), "records/p@complete"),
    (_committed(np.array([b"x"])), lambda e: e.read_record("p"), "records/p/committed"),
    (_committed(np.zeros(0, np.int64)), lambda e: e.read_record("p"), "records/p/committed"),
    (_set("tracks/t", "extra", "[1]"), lambda e: e.track_attrs("t"), "tracks/t@extra"),
    (_set("rig/cameras/cam0", "index", "abc"), lambda e: e.camera_names(), "cam0@index"),
    (_set("rig/cameras/cam0", "image_size", 5), lambda e: e.read_rig(), "cam0@image_size"),
    (_set("rig/cameras/cam0", "index", "abc"), lambda e: e.summary(), "cam0@index"),
]


@pytest.mark.parametrize(("damage", "read", "words"), FILE_DAMAGE,
                         ids=[w for *_, w in FILE_DAMAGE])
def test_bad_values_in_the_file_are_a_damaged_file_naming_where(tmp_path, damage, read, words):
    path = _damaged_file(tmp_path, damage)
    with open_experiment(path) as exp, pytest.raises(StoreError) as info:
        read(exp)
    line = str(info.value)
    assert "\n" not in line and str(path) in line and words in line, line


# -- plugin code: a refusal is the user's error, anything else is a bug that propagates --------

def _spec_with_law(law: str, **options):
    from ._model_files import base_spec

    spec = base_spec()
    spec["layers"][0]["law"] = law
    spec["layers"][0]["options"] = options
    return spec


@pytest.mark.needs_plugins
def test_a_law_refusing_its_options_is_a_model_error_naming_the_entry():
    from skinkit.fem.errors import ModelError
    from skinkit.fem.model import build_model

    with pytest.raises(ModelError, match=r"layers\[0\]\.options.*unexpected keyword argument 'speed'"):
        build_model(_spec_with_law("ogden", speed=2))
    with pytest.raises(ModelError, match=r"layers\[0\]\.options.*terms must be a positive integer"):
        build_model(_spec_with_law("ogden", terms=0))


@pytest.mark.needs_plugins
def test_a_bug_in_a_law_constructor_propagates(monkeypatch):
    """Before, any TypeError/KeyError/AttributeError raised inside a law's constructor was
    reported as a bad ``options`` entry of the model file."""
    from skinkit_plugins.laws.ogden import Ogden

    from skinkit import registry
    from skinkit.fem.model import build_model

    class Buggy(Ogden):
        def __init__(self, terms: int = 1) -> None:
            super().__init__(terms)
            self.terms.bit_length  # noqa: B018 - exists
            self.missing_attribute_of_the_law  # noqa: B018 - the bug

    monkeypatch.setitem(registry._cache, ("skinkit.laws", "buggy-ogden"), Buggy)
    with pytest.raises(AttributeError, match="missing_attribute_of_the_law"):
        build_model(_spec_with_law("buggy-ogden", terms=1))


@pytest.mark.needs_plugins
def test_a_bug_in_an_effect_propagates(monkeypatch):
    """Before, a KeyError raised inside an effect's ``apply`` became "cannot be applied to this
    model" (an EffectError, as if the user's model were at fault)."""
    from skinkit_plugins.effects.geometry import Thickness

    from skinkit import registry
    from skinkit.forward.effects import apply_all, resolve

    from ._model_files import base_spec

    class Buggy(Thickness):
        def apply(self, model, p):
            return {}["a bug in the effect"]

    monkeypatch.setitem(registry._cache, ("skinkit.effects", "buggy-thickness"), Buggy)
    spec = base_spec()
    effects = resolve([{"name": "buggy-thickness"}], "fe")
    with pytest.raises(KeyError, match="a bug in the effect"):
        apply_all(spec, effects)


# -- no entry point writes into its inputs: called with read-only arrays, none may fail ----------

def _read_only(a):
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def _sysid_calls():
    from skinkit import sysid as S
    from skinkit.sysid import lti

    rate = 1000.0
    f = S.gaussian_force(4.0, rate, seed=1, rms_N=0.2)
    y = lti.simulate(lti.SecondOrder(K=500.0, B=2.0, I=0.01), f, rate)
    y = y + 1e-3 * np.std(y) * np.random.default_rng(2).standard_normal(f.size)
    f_nan = f.copy()
    f_nan[100] = np.nan                       # a short NaN run: interpolated (in a copy)
    t = np.arange(f.size) / rate
    t[2000:] += 0.5                           # a gap: the longest segment is cut out
    F, Y, T, Fc = _read_only(f_nan), _read_only(y), _read_only(t), _read_only(f)
    return {
        "check_signals": lambda: S.check_signals(F, Y, time_s=T),
        "identify_linear": lambda: S.identify_linear(F, Y, rate),
        "identify_wiener": lambda: S.identify_wiener(F, Y, rate),
        "identify_hammerstein": lambda: S.identify_hammerstein(F, Y, rate),
        "estimate_irf": lambda: S.estimate_irf(Fc, Y, rate, 0.05),
        "residual_diagnostics": lambda: S.residual_diagnostics(Fc, Y, _read_only(0.9 * y), rate),
        "detect_segments": lambda: S.detect_segments(F, rate),
    }


def _geometry_calls():
    from skinkit.fem.embed import embed_points, fit_surface
    from skinkit.fem.mesh import block_mesh
    from skinkit.vision.camera import project, undistort
    from skinkit.vision.rigs import ring_rig
    from skinkit.vision.triangulation import triangulate

    rig = ring_rig()
    X = np.array([[0.001, 0.002, 0.0], [0.0, -0.003, 0.0005], [np.nan, 0.0, 0.0]])
    px = np.stack([project(c, X) for c in rig.cameras], axis=1)
    px[0, 1] = np.nan
    mesh = block_mesh((0.01, 0.01, 0.003), (2, 2, 1))
    xy = np.random.default_rng(0).uniform(0.0, 0.01, (50, 2))
    surface = _read_only(np.column_stack([xy, np.full(50, 0.0031)]))
    return {
        "project": lambda: project(rig.cameras[0], _read_only(X)),
        "undistort": lambda: undistort(rig.cameras[0], _read_only(px[:, 0])),
        "triangulate": lambda: triangulate(rig, _read_only(px)),
        "fit_surface": lambda: fit_surface(mesh, surface, 0.001),
        "embed_points": lambda: embed_points(mesh, _read_only(0.9 * mesh.nodes[:5] + 1e-4)),
    }


@pytest.mark.parametrize("name", ["check_signals", "identify_linear", "identify_wiener",
                                  "identify_hammerstein", "estimate_irf", "residual_diagnostics",
                                  "detect_segments"])
def test_sysid_entry_points_do_not_write_their_inputs(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _sysid_calls()[name]()        # a write into a read-only input raises ValueError


@pytest.mark.parametrize("name", ["project", "undistort", "triangulate", "fit_surface",
                                  "embed_points"])
def test_vision_and_fem_entry_points_do_not_write_their_inputs(name):
    _geometry_calls()[name]()
