"""Protocol solves kept on disk for a second run (``skinkit.forward.solve_cache``).

A second prediction of the same model on the same session reads every protocol back, to the
bit, without solving; any change of a parameter or of the code is a miss; a damaged entry is
solved again; the directory keeps at most its size, least recently used entries going first;
without the environment variable nothing is written.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from skinkit.forward import fe, solve_cache
from skinkit.schemas import Observations, Protocol, ProtocolObservations
from tests.forward._bilayer import SPEC, channels

pytestmark = pytest.mark.needs_plugins

def _session() -> Observations:
    chans = channels()
    return Observations({"a": ProtocolObservations(Protocol("a"), chans),
                         "b": ProtocolObservations(Protocol("b"), dict(chans))}, None, "test")


@pytest.fixture
def counted(monkeypatch, tmp_path):
    """The cache in ``tmp_path``, and the number of protocol solves made so far."""
    monkeypatch.setenv(solve_cache.ENVIRONMENT, str(tmp_path / "cache"))
    calls = []
    real = fe.solve_protocol

    def solve(job, *a, **k):
        calls.append(job.name)
        return real(job, *a, **k)

    monkeypatch.setattr(fe, "solve_protocol", solve)
    return calls


def _predict(params=None, sens=None):
    from skinkit.forward import load
    with load(SPEC, workers=1) as model:
        p = model.parameters() if params is None else params(model.parameters())
        return model.predict(p, _session(), sensitivities=sens)


def _same(a, b):
    for name, chans in a.protocols.items():
        for c, pred in chans.items():
            np.testing.assert_array_equal(pred.values, b.protocols[name][c].values)
            for k, d in pred.d.items():
                np.testing.assert_array_equal(d, b.protocols[name][c].d[k])


def test_a_second_prediction_is_read_back_to_the_bit(counted, tmp_path):
    first = _predict(sens=["skin.E"])
    assert sorted(counted) == ["a", "b"]
    second = _predict(sens=["skin.E"])
    assert sorted(counted) == ["a", "b"]           # nothing solved again
    _same(first, second)
    assert len(list((tmp_path / "cache").glob("*.npz"))) == 2


def test_another_parameter_value_or_code_is_a_miss(counted, monkeypatch):
    _predict()
    _predict(params=lambda p: p.with_values({"skin.E": 41e3}))
    assert len(counted) == 4
    monkeypatch.setattr(solve_cache, "code_fingerprint", lambda: "another release")
    _predict()
    assert len(counted) == 6


def test_a_damaged_entry_is_solved_again(counted, tmp_path):
    first = _predict()
    for p in (tmp_path / "cache").glob("*.npz"):
        p.write_bytes(b"not an archive")
    again = _predict()
    assert len(counted) == 4
    _same(first, again)
    assert _predict() is not None and len(counted) == 4     # replaced by good entries


def test_the_directory_keeps_its_size(tmp_path):
    """Over its size, the least recently used entry goes, and a read makes an entry recent."""
    from types import SimpleNamespace
    jobs = [SimpleNamespace(name=n, options={}) for n in ("x", "y", "z")]
    result = {"times": np.zeros(1000), "info": {}}
    probe = solve_cache.SolveCache(tmp_path / "probe")
    probe.put(jobs[0], result)
    size = next((tmp_path / "probe").glob("*.npz")).stat().st_size
    cache = solve_cache.SolveCache(tmp_path / "c", max_bytes=int(2.5 * size))
    for age, job in zip((30, 20), jobs[:2], strict=True):
        cache.put(job, result)
        path = cache._path(cache.key(job))
        os.utime(path, (path.stat().st_mtime - age,) * 2)
    assert cache.get(jobs[0]) is not None          # x is now the most recently used
    cache.put(jobs[2], result)                     # three entries: one must go, the oldest (y)
    assert cache.get(jobs[1]) is None
    assert cache.get(jobs[0]) is not None and cache.get(jobs[2]) is not None


def test_without_the_variable_nothing_is_written(monkeypatch, tmp_path):
    monkeypatch.delenv(solve_cache.ENVIRONMENT, raising=False)
    monkeypatch.chdir(tmp_path)
    _predict()
    assert not list(tmp_path.rglob("*.npz"))


def test_a_size_that_is_not_a_positive_number_is_refused(monkeypatch, tmp_path):
    from skinkit.errors import SkinkitError
    monkeypatch.setenv(solve_cache.ENVIRONMENT, str(tmp_path))
    monkeypatch.setenv(solve_cache.ENVIRONMENT_SIZE, "0.5")
    assert solve_cache.SolveCache.from_environment().max_bytes == 1024**3 // 2
    for bad in ("lots", "-1", "nan"):
        monkeypatch.setenv(solve_cache.ENVIRONMENT_SIZE, bad)
        with pytest.raises(SkinkitError, match="SKINKIT_SOLVE_CACHE_GB"):
            solve_cache.SolveCache.from_environment()


def test_a_results_page_is_written_without_the_cache(monkeypatch, tmp_path):
    """A command writing a results page measures its work: the cache variable is dropped."""
    import os

    import click
    from click.testing import CliRunner

    from skinkit.cli._bench_out import page_option

    @click.command()
    @page_option
    def cmd(page):
        click.echo(os.environ.get(solve_cache.ENVIRONMENT, "unset"))

    monkeypatch.setenv(solve_cache.ENVIRONMENT, str(tmp_path / "c"))
    assert CliRunner().invoke(cmd, []).output.strip() == str(tmp_path / "c")
    assert CliRunner().invoke(cmd, ["--page", str(tmp_path / "p.md")]).output.strip() == "unset"
