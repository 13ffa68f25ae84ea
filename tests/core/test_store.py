"""The experiment store: round trips, crash safety, and one-line errors for bad files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import h5py
import numpy as np
import pytest

from skinkit.errors import SchemaError, StoreError
from skinkit.schemas import (
    CameraModel,
    CameraRig,
    FitResult,
    ImageSequence,
    Parameter,
    ParameterSet,
    Protocol,
    RobotRecord,
    SurfaceProfile,
    SurfaceTrack,
)
from skinkit.store import create_experiment, open_experiment, recover
from skinkit.store import layout as L


def _rec(n=500, name="stochastic", t0=0.0, rate=1000.0, seed=0):
    rng = np.random.default_rng(seed)
    return RobotRecord(time_s=t0 + np.arange(n) / rate, tip_force=rng.normal(size=(n, 3)),
                       tip_position=rng.normal(size=(n, 3)) * 1e-3,
                       motor_current=rng.normal(size=(n, 3)),
                       flags=rng.integers(0, 8, n).astype(np.uint32),
                       protocol=Protocol(name, kind="force", parameters={"rms": 1.0}, units={"rms": "N"}))


def test_roundtrip_everything(tmp_path):
    path = tmp_path / "s.h5"
    rec = _rec()
    rig = CameraRig(tuple(CameraModel(f"cam{i}", [[1e3, 0, 32], [0, 1e3, 24], [0, 0, 1]], np.zeros(5),
                                      np.eye(3), [0, 0, 0.1 * i], (64, 48)) for i in range(4)))
    seq = ImageSequence("indentation", np.random.default_rng(1).integers(0, 255, (3, 4, 48, 64), np.uint8),
                        rig.names, [0.0, 0.5, 1.0])
    prof = SurfaceProfile(np.random.default_rng(2).normal(size=(20, 3)), np.ones(20),
                          uncertainty_px=np.full(20, 2.0))
    track = SurfaceTrack(np.zeros((20, 3, 3)), np.ones((20, 3), bool), [0.0, 0.5, 1.0],
                         point_ids=np.arange(20))
    fit = FitResult("kv", ParameterSet([Parameter("K", 1450, "N/m", 0, 1e4)]), objective=0.5)
    with create_experiment(path) as exp:
        exp.set_metadata(subject="S01", site="forearm")
        exp.write_record(rec)
        exp.write_rig(rig)
        exp.write_images(seq)
        exp.write_profile("undeformed", prof)
        exp.write_track("indentation", track)
        exp.write_fit("kv", fit)
    with open_experiment(path) as exp:
        back = exp.read_record("stochastic")
        for c in ("time_s", "tip_force", "tip_position", "motor_current", "flags"):
            np.testing.assert_array_equal(getattr(back, c), getattr(rec, c))
        assert back.protocol == rec.protocol
        assert exp.read_rig().names == rig.names
        np.testing.assert_array_equal(exp.read_images("indentation").frames, seq.frames)
        np.testing.assert_array_equal(exp.read_profile("undeformed").points, prof.points)
        assert exp.read_track("indentation").n_frames == 3
        assert exp.read_fit("kv").parameters["K"] == 1450
        s = exp.summary()
        assert s["schema_version"] == L.SCHEMA_VERSION and s["session"]["subject"] == "S01"
        assert s["records"][0]["samples"] == 500 and s["records"][0]["complete"] is True
        assert s["records"][0]["rate_hz"] == pytest.approx(1000.0)
        assert [c["name"] for c in s["cameras"]] == rig.names


def test_incremental_blocks_and_refusals(tmp_path):
    path = tmp_path / "s.h5"
    rec = _rec(1000)
    with create_experiment(path) as exp:
        with exp.record_writer(rec.protocol, rec.channels, 1000.0) as w:
            for i in range(0, 1000, 100):
                w.append(rec.slice(i, i + 100))
            with pytest.raises(SchemaError, match="not after the last sample"):
                w.append(rec.slice(0, 10))
        with pytest.raises(StoreError, match="already exists"):
            with exp.record_writer(rec.protocol, rec.channels):
                pass
        with pytest.raises(SchemaError, match="unknown channel"):
            with exp.record_writer(Protocol("b"), ["tip_velocity"]):
                pass
    with open_experiment(path) as exp:
        np.testing.assert_array_equal(exp.read_record("stochastic").tip_force, rec.tip_force)
        with pytest.raises(StoreError, match="read-only"):
            exp.write_record(_rec(name="other"))
    with pytest.raises(StoreError, match="already exists"):
        create_experiment(path)
    with open_experiment(path, "a") as exp:
        exp.write_record(_rec(name="second"))
        assert exp.record_names() == ["second", "stochastic"]


_WRITER = textwrap.dedent("""
    import sys, numpy as np
    from skinkit.schemas import Protocol, RobotRecord
    from skinkit.store import create_experiment
    path, block = sys.argv[1], int(sys.argv[2])
    with create_experiment(path) as exp:
        with exp.record_writer(Protocol("stream", kind="force"), ["tip_force"], 1000.0) as w:
            k = 0
            while True:
                i = np.arange(k * block, (k + 1) * block)
                w.append(RobotRecord(time_s=i / 1000.0, tip_force=np.column_stack([i, -i, 2 * i]) * 1.0))
                k += 1
                print(w.n_samples, flush=True)
""")


@pytest.mark.parametrize("kill_after_blocks", [1, 7, 40])
def test_sigkill_while_appending_keeps_flushed_blocks(tmp_path, kill_after_blocks):
    """SIGKILL the writer mid-stream: the file opens and holds every block it reported flushed."""
    path = tmp_path / "crash.h5"
    script = tmp_path / "writer.py"
    script.write_text(_WRITER)
    proc = subprocess.Popen([sys.executable, str(script), str(path), "250"], stdout=subprocess.PIPE,
                            text=True)
    reported = 0
    try:
        for _ in range(kill_after_blocks):
            line = proc.stdout.readline()
            assert line, "writer died before it was killed"
            reported = int(line)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    with open_experiment(path) as exp:
        assert exp.closed_cleanly is False
        info = exp.record_info("stream")
        assert info["complete"] is False
        rec = exp.read_record("stream")
    # The writer may have committed further blocks between its last print and the kill.
    assert rec.n_samples >= reported and rec.n_samples % 250 == 0
    i = np.arange(rec.n_samples)
    np.testing.assert_array_equal(rec.tip_force, np.column_stack([i, -i, 2 * i]))
    np.testing.assert_array_equal(rec.time_s, i / 1000.0)
    out = recover(path, tmp_path / "recovered.h5")
    with open_experiment(out, "a") as exp:
        assert exp.read_record("stream").n_samples == rec.n_samples
        exp.write_record(_rec(name="after_recovery"))


def test_sigkill_during_a_block_write(tmp_path):
    """Kill at random moments (not just after a report): never a broken file or partial block."""
    script = tmp_path / "writer.py"
    script.write_text(_WRITER)
    rng = np.random.default_rng(3)
    for trial in range(4):
        path = tmp_path / f"crash{trial}.h5"
        proc = subprocess.Popen([sys.executable, str(script), str(path), "5000"], stdout=subprocess.PIPE,
                                text=True)
        assert proc.stdout.readline()  # at least one block exists
        time.sleep(rng.uniform(0.0, 0.2))
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        with open_experiment(path) as exp:
            rec = exp.read_record("stream")
        assert rec.n_samples % 5000 == 0 and rec.n_samples >= 5000
        i = np.arange(rec.n_samples)
        np.testing.assert_array_equal(rec.tip_force[:, 0], i)


def _single_line(exc: BaseException) -> str:
    msg = str(exc)
    assert "\n" not in msg, msg
    return msg


def test_truncated_file(tmp_path):
    path = tmp_path / "t.h5"
    with create_experiment(path) as exp:
        exp.write_record(_rec(20000))
    data = path.read_bytes()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(StoreError) as e:
        with open_experiment(cut) as exp:
            exp.read_record("stochastic")
    assert str(cut) in _single_line(e.value)
    tiny = tmp_path / "tiny.h5"
    tiny.write_bytes(data[:100])
    with pytest.raises(StoreError, match="truncated|cannot be opened"):
        open_experiment(tiny)


def test_not_hdf5_missing_and_directory(tmp_path):
    p = tmp_path / "x.h5"
    p.write_text("time_s,force_N\n0,1\n")
    with pytest.raises(StoreError, match="not an HDF5 file"):
        open_experiment(p)
    with pytest.raises(StoreError, match="no such file"):
        open_experiment(tmp_path / "missing.h5")
    with pytest.raises(StoreError, match="is a directory"):
        open_experiment(tmp_path)


def test_wrong_version_and_foreign_file(tmp_path):
    path = tmp_path / "v.h5"
    with create_experiment(path) as exp:
        exp.write_record(_rec())
    with h5py.File(path, "a") as f:
        f.attrs["schema_version"] = "2.0"
    with pytest.raises(StoreError, match=r"schema version 2.0 is not supported"):
        open_experiment(path)
    with h5py.File(path, "a") as f:
        del f.attrs["schema_version"]
    with pytest.raises(StoreError, match="schema_version attribute is missing"):
        open_experiment(path)
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = 1
    with pytest.raises(StoreError, match="not a skinkit experiment file"):
        open_experiment(foreign)


@pytest.mark.parametrize("damage,needle", [
    (lambda g: (g.__delitem__("tip_force"), g.create_dataset("tip_force", data=np.zeros((500, 2)))),
     "tip_force: has shape (500, 2)"),
    (lambda g: g.__delitem__("time_s"), "time_s: missing"),
    (lambda g: g["tip_position"].attrs.__setitem__("unit", "mm"), "unit 'mm' where 'm' is required"),
    (lambda g: g.attrs.__setitem__("protocol", "{not json"), "attribute 'protocol' is not valid JSON"),
    (lambda g: g["committed"].__setitem__(0, 10**6), "committed: 1000000 is outside"),
    (lambda g: g.attrs.__setitem__("channels", '["tip_velocity"]'), "malformed channel list"),
])
def test_wrong_shape_and_malformed_record(tmp_path, damage, needle):
    path = tmp_path / "d.h5"
    with create_experiment(path) as exp:
        exp.write_record(_rec())
    with h5py.File(path, "a") as f:
        damage(f["records/stochastic"])
    with open_experiment(path) as exp, pytest.raises(StoreError) as e:
        exp.read_record("stochastic")
    msg = _single_line(e.value)
    assert needle in msg and "records/stochastic" in msg


def test_missing_record_named(tmp_path):
    path = tmp_path / "m.h5"
    with create_experiment(path) as exp:
        exp.write_record(_rec())
    with open_experiment(path) as exp, pytest.raises(StoreError, match="records/nope: missing"):
        exp.read_record("nope")


# -- fuzzing the reader ----------------------------------------------------------------------
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_BASE: dict[str, bytes] = {}


def _base_file(tmp_path_factory) -> bytes:
    if "data" not in _BASE:
        path = tmp_path_factory.mktemp("fuzz") / "base.h5"
        with create_experiment(path) as exp:
            exp.write_record(_rec(64))
            exp.write_profile("p", SurfaceProfile(np.zeros((4, 3)), np.ones(4)))
        _BASE["data"] = path.read_bytes()
    return _BASE["data"]


def _read_everything(path) -> None:
    with open_experiment(path) as exp:
        exp.summary()
        for name in exp.record_names():
            exp.read_record(name)
        for name in exp.profile_names():
            exp.read_profile(name)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_fuzz_store_reader(tmp_path_factory, data):
    """Flipped bytes or a cut anywhere: the reader succeeds or raises a one-line StoreError."""
    base = bytearray(_base_file(tmp_path_factory))
    # Metadata sits in the first few kB and at the end; data chunks in between.
    pos = st.one_of(st.integers(0, min(4095, len(base) - 1)), st.integers(0, len(base) - 1))
    edits = data.draw(st.lists(st.tuples(pos, st.integers(0, 255)), min_size=1, max_size=4))
    for i, b in edits:
        base[i] = b
    if data.draw(st.booleans()):
        base = base[: data.draw(st.integers(0, len(base)))]
    path = tmp_path_factory.mktemp("fz") / "f.h5"
    path.write_bytes(bytes(base))
    try:
        _read_everything(path)
    except StoreError as exc:
        assert "\n" not in str(exc)


def test_record_attrs_and_calibrations(tmp_path):
    path = tmp_path / "a.h5"
    with create_experiment(path) as exp:
        exp.write_record(_rec())
        exp.set_record_attrs("stochastic", samples_lost=3, link={"kind": "serial", "baud": 921600})
        exp.set_record_attrs("stochastic", samples_lost=4)
        exp.write_calibration("robot", {"mass_kg": 0.025})
        with pytest.raises(StoreError, match="records/nope: missing"):
            exp.set_record_attrs("nope", a=1)
        with pytest.raises(SchemaError, match="not JSON-ready"):
            exp.set_record_attrs("stochastic", bad=object())
    with open_experiment(path) as exp:
        extra = exp.record_info("stochastic")["extra"]
        assert extra == {"samples_lost": 4, "link": {"kind": "serial", "baud": 921600}}
        assert exp.read_calibration("robot") == {"mass_kg": 0.025}
        assert exp.summary()["calibrations"] == ["robot"]
