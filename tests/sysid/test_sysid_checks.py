"""Bad records give a clear error or a named warning, never a silent wrong fit."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skinkit.errors import SkinkitError
from skinkit.schemas.robot import FLAG_SATURATED
from skinkit.sysid import (
    ClippedForceWarning,
    GapWarning,
    MemoryWarning,
    NaNWarning,
    NarrowbandInputWarning,
    NonCausalWarning,
    NonUniformSamplingWarning,
    PoorFitWarning,
    ShortRecordWarning,
    SysidError,
    check_signals,
    identify_linear,
    identify_wiener,
)
from skinkit.sysid.simulate import simulate_record

REAL = Path("/work/shared/data/real/healthy_skin_extension_relaxation.csv")


@pytest.fixture(scope="module")
def rec(total):
    return simulate_record(total, seed=21)


def test_sysid_error_is_a_skinkit_error():
    assert issubclass(SysidError, SkinkitError)


def test_gap_uses_longest_segment_and_still_fits(rec, total):
    t = rec.time_s.copy()
    t[3000:] += 0.5  # a 0.5 s gap after 1.5 s
    with pytest.warns(GapWarning, match="gap"):
        m = identify_linear(rec.force_N, rec.position_m, time_s=t)
    assert m.n_samples == rec.force_N.size - 3000
    assert abs(m.total.K / total.K - 1) < 0.03
    assert any(i.startswith("GapWarning") for i in m.issues)


def test_non_uniform_sampling_is_resampled(rec):
    rng = np.random.default_rng(0)
    t = rec.time_s + rng.uniform(-0.1, 0.1, rec.time_s.size) / 2000.0
    with pytest.warns(NonUniformSamplingWarning, match="resampled"):
        sig = check_signals(rec.force_N, rec.position_m, time_s=t)
    assert sig.rate_hz == pytest.approx(2000.0, rel=1e-3)


def test_isolated_nans_interpolated_long_run_cut(rec):
    f = rec.force_N.copy()
    y = rec.position_m.copy()
    f[100] = np.nan
    with pytest.warns(NaNWarning, match="1 short run"):
        sig = check_signals(f, y, rate_hz=2000.0)
    assert sig.n == f.size and np.isfinite(sig.force_N).all()
    y[2000:2500] = np.nan
    with pytest.warns(NaNWarning, match="cut out"):
        sig = check_signals(f, y, rate_hz=2000.0)
    assert sig.n == f.size - 2500


def test_constant_input_is_an_error(rec):
    with pytest.raises(SysidError, match="force_N is constant"):
        identify_linear(np.full(rec.force_N.size, 1.2), rec.position_m, 2000.0)
    with pytest.raises(SysidError, match="position_m is constant"):
        identify_linear(rec.force_N, np.zeros(rec.force_N.size), 2000.0)


def test_too_short_for_memory(rec):
    with pytest.raises(SysidError, match="too short for an IRF memory of 0.5 s"):
        identify_linear(rec.force_N[:4000], rec.position_m[:4000], 2000.0, memory_s=0.5)
    with pytest.warns(ShortRecordWarning, match="memory lengths"):
        check_signals(rec.force_N[:1500], rec.position_m[:1500], rate_hz=2000.0, memory_s=0.1)
    with pytest.raises(SysidError, match="at least"):
        identify_linear(rec.force_N[:10], rec.position_m[:10], 2000.0)


def test_clipped_force_warns(rec):
    f = np.clip(rec.force_N, -np.inf, 0.6)  # a saturating amplifier
    with pytest.warns(ClippedForceWarning, match="at the maximum 0.6"):
        check_signals(f, rec.position_m, rate_hz=2000.0)
    flags = np.zeros(f.size, np.uint32)
    flags[:50] = FLAG_SATURATED
    with pytest.warns(ClippedForceWarning, match="flagged saturated"):
        check_signals(rec.force_N, rec.position_m, rate_hz=2000.0, flags=flags)


def test_bad_shapes_and_arguments(rec):
    with pytest.raises(SysidError, match="samples but position_m"):
        check_signals(rec.force_N, rec.position_m[:-1], rate_hz=2000.0)
    with pytest.raises(SysidError, match="exactly one of rate_hz"):
        check_signals(rec.force_N, rec.position_m)
    with pytest.raises(SysidError, match="infinite"):
        check_signals(np.r_[np.inf, rec.force_N[1:]], rec.position_m, rate_hz=2000.0)
    with pytest.raises(SysidError, match="hold"):
        identify_linear(rec.force_N, rec.position_m, 2000.0, hold="cubic")


@pytest.mark.filterwarnings("ignore::skinkit.sysid.PoorFitWarning")
def test_memory_too_short_warns(rec):
    with pytest.warns(MemoryWarning, match="not decayed"):
        identify_linear(rec.force_N, rec.position_m, 2000.0, memory_s=0.02)


@pytest.mark.filterwarnings("ignore::skinkit.sysid.PoorFitWarning")
def test_position_leading_force_warns(rec):
    # swap cause and effect: a "force" that follows the position by 10 ms
    y = rec.position_m
    f = np.r_[np.zeros(20), y[:-20]] * 1e3
    with pytest.warns(NonCausalWarning, match="position leads force"):
        identify_linear(f, y, 2000.0, memory_s=0.1)


@pytest.mark.skipif(not REAL.exists(), reason="real data file not present")
def test_real_relaxation_test_is_flagged_not_fitted():
    from skinkit.store import read_robot_csv

    record = read_robot_csv(REAL)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        m = identify_linear(record)
    names = {w.category.__name__ for w in caught}
    # a ramp-and-hold extensometer test is not a stochastic input; its IRF is no sinusoid
    assert NarrowbandInputWarning.__name__ in names
    assert PoorFitWarning.__name__ in names
    assert MemoryWarning.__name__ in names  # the force relaxes over tens of seconds
    assert not m.valid and m.to_dict()["valid"] is False
    with pytest.raises(SysidError, match="not a stable under-damped"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        identify_wiener(record)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(nan_at=st.lists(st.integers(0, 1999), max_size=30),
       gap_at=st.lists(st.integers(1, 1999), max_size=3),
       jitter=st.sampled_from([0.0, 1e-2]))
def test_check_signals_never_returns_bad_samples(nan_at, gap_at, jitter):
    # whatever the damage, the result is finite and uniform, or a SysidError says why
    rng = np.random.default_rng(len(nan_at) + 7 * len(gap_at))
    f = rng.standard_normal(2000)
    y = np.convolve(f, np.ones(8) / 8, mode="same") + 0.01 * rng.standard_normal(2000)
    f[nan_at] = np.nan
    t = np.arange(2000) / 1000.0 + jitter * rng.uniform(-0.5, 0.5, 2000) / 1000.0
    for g in gap_at:
        t[g:] += 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            sig = check_signals(f, y, time_s=t)
        except SysidError:
            return
    assert np.isfinite(sig.force_N).all() and np.isfinite(sig.position_m).all()
    assert sig.force_N.size == sig.position_m.size >= 64
    assert sig.rate_hz == pytest.approx(1000.0, rel=0.02)


def test_nonphysical_names_each_bad_parameter():
    from skinkit.sysid.checks import nonphysical

    assert nonphysical(1450.0, 4.76, 0.0155) == {}
    bad = nonphysical(-1.0, 0.0, float("nan"))
    assert bad == {"K": "negative stiffness", "B": "zero damping", "I": "mass is not finite"}


def test_not_stochastic_reason_from_the_warnings(rec):
    from skinkit.sysid.checks import NotStochasticError, not_stochastic_reason, refuse_if_not_stochastic

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ok = check_signals(rec.force_N, rec.position_m, rate_hz=rec.rate_hz)
        slow = check_signals(np.sin(np.linspace(0, 6, 5000)) + 1e-3 * np.cos(np.arange(5000)),
                             rec.position_m[:5000], rate_hz=rec.rate_hz)
    assert not_stochastic_reason(ok.issues) is None
    refuse_if_not_stochastic(ok.issues, "ok.csv")  # a broadband record passes
    assert "of the force variance lies above" in not_stochastic_reason(slow.issues)
    with pytest.raises(NotStochasticError, match=r"^slow.csv is not a broadband stochastic force"):
        refuse_if_not_stochastic(slow.issues, "slow.csv")
