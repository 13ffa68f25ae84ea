"""Regressions for the correctness defects of issue 13: no mutation of inputs, bugs not disguised."""

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
    with open_experiment(path) as exp, pytest.raises(TypeError, match="a bug in skinkit"):
        exp.read_record("p")
    monkeypatch.undo()
    # a damaged dataset (h5py raises) is still a StoreError naming the file
    import h5py
    with h5py.File(path, "a") as f:
        del f["records/p/time_s"]
    with open_experiment(path) as exp, pytest.raises(StoreError, match=str(path.name)):
        exp.read_record("p")
