"""The protocol library: thesis parameters, programme shapes and clear errors (core only)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import welch

from skinkit.acquisition import ProtocolError, catalogue, direction, make_protocol, names, programme_for


def test_catalogue_has_table_12_and_the_stochastic_protocols() -> None:
    n = names()
    assert [x for x in n if x.startswith("in_plane_")] == [f"in_plane_{t:03d}" for t in range(0, 360, 30)]
    assert [x for x in n if x.startswith("out_of_plane_")] == [
        "out_of_plane_330",
        "out_of_plane_285",
        "out_of_plane_240",
    ]
    for p in catalogue():
        assert p.duration_s > 0 and set(p.units) <= set(p.parameters)


@pytest.mark.parametrize(
    "name,theta,phi",
    [
        ("normal_indentation", 0, 90),
        ("in_plane_150", 150, 0),
        ("normal_retraction", 0, -90),
        ("out_of_plane_240", 240, 45),
    ],
)
def test_sinusoid_protocols_are_one_sided_along_their_direction(name: str, theta: float, phi: float) -> None:
    prog = programme_for(make_protocol(name))
    sp = prog.setpoints
    assert prog.kind == "trajectory" and prog.duration_s == pytest.approx(30.0)
    amp = sp @ direction(theta, phi)
    np.testing.assert_allclose(sp, amp[:, None] * direction(theta, phi), atol=1e-15)
    assert amp.min() == pytest.approx(0, abs=1e-15) and amp.max() == pytest.approx(1.5e-3)
    # three periods at 0.1 Hz: maxima at 5, 15, 25 s
    peaks = prog.time_s[1:-1][(amp[1:-1] > amp[:-2]) & (amp[1:-1] >= amp[2:])]
    np.testing.assert_allclose(peaks, [5, 15, 25])


def test_preconditioning_holds_2_mm() -> None:
    prog = programme_for(make_protocol("preconditioning"))
    z = prog.setpoints[:, 2]
    assert z.max() == pytest.approx(2e-3) and z[0] == 0 and z[-1] == pytest.approx(0, abs=1e-15)
    assert np.sum(z >= 2e-3 - 1e-12) / prog.rate_hz == pytest.approx(30.0, abs=0.02)


def test_stochastic_force_is_band_limited_and_in_range() -> None:
    prog = programme_for(make_protocol("stochastic_full_scale", duration=20.0))
    f = prog.setpoints
    assert prog.kind == "force" and np.all(f >= 0) and np.all(f <= 3.5 + 1e-12)
    assert np.all(f[:, 0] == f[:, 1])  # normal: all motors together
    freq, pxx = welch(f[:, 0] - f[:, 0].mean(), fs=prog.rate_hz, nperseg=2048)
    # 4th-order Butterworth applied forward and back: -48 dB/octave beyond 200 Hz, so the
    # band 300-500 Hz holds under 1e-3 of the power below 200 Hz
    assert pxx[freq > 300].sum() < 1e-3 * pxx[freq < 200].sum()
    one = programme_for(make_protocol("stochastic_full_scale", duration=2.0, axis=2, hold_force=0.7))
    assert np.all(one.setpoints[:, [0, 2]] == 0.7) and one.setpoints[:, 1].std() > 0.1


@pytest.mark.parametrize("variant", ["a", "b"])
def test_incremental_protocols_step_up_then_down(variant: str) -> None:
    p = make_protocol(f"incremental_{variant}", increment_duration=1.0, precondition_duration=0.5)
    prog = programme_for(p)
    assert prog.duration_s == pytest.approx(30 * 1.5)
    f = prog.setpoints[:, 0]
    n_pre, n_inc = 500, 1000
    means = [f[k * 1500 + n_pre : (k + 1) * 1500].mean() for k in range(30)]
    assert np.all(np.diff(means[:15]) > 0) and np.all(np.diff(means[15:]) < 0)
    pre = f[1500 + 0 : 1500 + n_pre]
    if variant == "a":  # zero - max - zero triangle
        # the apex falls between two of the 500 samples: within 2/500 of full scale
        assert pre.max() == pytest.approx(3.5, rel=2 / n_pre) and pre[0] == pytest.approx(0)
    else:  # holds the step's mean: 20 % scale, means from 0.1 to 0.9 of full scale
        assert np.ptp(pre) == 0 and pre[0] == pytest.approx(3.5 * (0.1 + 0.8 / 14))
    assert n_inc == 1000


def test_bad_names_and_parameters_are_named() -> None:
    with pytest.raises(ProtocolError, match="unknown protocol 'x'"):
        make_protocol("x")
    with pytest.raises(ProtocolError, match=r"no parameter\(s\) \['amplitude'\]"):
        make_protocol("normal_indentation", amplitude=1)
    with pytest.raises(ProtocolError, match="'frequency' must be > 0"):
        make_protocol("normal_indentation", frequency=0)
    with pytest.raises(ProtocolError, match="must be a number"):
        make_protocol("normal_indentation", frequency="fast")
