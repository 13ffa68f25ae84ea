"""The alternative gap benchmark on the finite-element model: its forms against closed forms, their
independence from the plugins (direct imports parsed), the rest before each protocol and the noise
colour a reader finds there.

Tolerances: the forms are exact arithmetic on the noiseless force (rounding, 1e-12 relative). The
AR(1) coefficient read from a rest segment of n samples has standard error √((1 − φ²)/n)
(Box, Jenkins & Reinsel, ch. 7): at φ 0.9 and n ≈ 3,000 that is 0.008, held to 0.04 (five
standard errors).
"""

from __future__ import annotations

import ast

import numpy as np
import pytest

from skinkit.acquisition.library import make_protocol, programme
from skinkit.bench import gap_alternative as ga
from skinkit.lab import alt_forms as af
from skinkit.lab import alternative_fe as afe
from tests.gap.test_benchmark_alternative import FORBIDDEN, ROOT


def _parts(n: int = 4, length: int = 500) -> list[dict]:
    """Four protocols of a smooth synthetic force (T, 3) [N] on a session clock with pauses."""
    out, t0 = [], 0.0
    for k in range(n):
        t = t0 + np.arange(length) / 100.0
        f = np.stack([0.1 * np.sin(t / 3.0 + j) for j in range(3)], axis=1)
        out.append({"t": t, "force": f, "index": k})
        t0 = t[-1] + afe.BETWEEN_S
    return out


def _build(name: str, parts: list[dict], seed: int = 0) -> list[np.ndarray]:
    return afe.form(name).build(parts, np.random.default_rng(seed), np.zeros(3))[0]


def test_softening_is_constant_within_a_protocol_and_follows_its_law() -> None:
    parts = _parts()
    got = _build("protocol-softening", parts)
    for p, g in zip(parts, got, strict=True):
        factor = 1 - 0.055 * -np.expm1(-p["index"] / 1.5)
        np.testing.assert_allclose(g, factor * p["force"], rtol=1e-12, atol=1e-15)


def test_drifts_restart_with_each_protocol_along_the_axis_weights() -> None:
    parts = _parts()
    for name, drift in (("warmup-drift", lambda t: af.warmup_drift(t, (0.0025, 0.004), (4.0, 60.0))),
                        ("log-settling", lambda t: 0.0012 * np.log1p(t))):
        for p, g in zip(parts, _build(name, parts), strict=True):
            d = drift(p["t"] - p["t"][0])                   # restarted by the taring at the protocol's start
            np.testing.assert_allclose(g - p["force"], d[:, None] * afe.AXIS_WEIGHTS, rtol=1e-12, atol=1e-15)


def test_clock_skew_delays_each_record_by_a_lag_growing_from_its_trigger() -> None:
    parts = _parts()
    got = _build("clock-skew", parts)
    for p, g in zip(parts, got, strict=True):
        t = p["t"] - p["t"][0]
        lag = afe.SKEW * t
        inner = slice(50, -50)
        expected = 0.1 * np.sin((p["t"] - lag) / 3.0)
        np.testing.assert_allclose(g[inner, 0], expected[inner], atol=1e-6)   # linear interpolation
        assert g[0, 0] == p["force"][0, 0]                                  # no lag at the trigger


def test_nulls_leave_the_force_alone_but_for_noise() -> None:
    parts = _parts()
    for name in ("white", "ar1-0.9", "spikes"):
        for p, g in zip(parts, _build(name, parts), strict=True):
            np.testing.assert_array_equal(g, p["force"])        # σ = 0: nothing but noise is added


def test_forms_import_no_plugin_and_no_candidate_form() -> None:
    """The forms are NumPy on the force: the module reaches the model only for its base response
    (the lab) and the reader, never the effect plugins or the forward model's forms of them."""
    tree = ast.parse((ROOT / "skinkit/lab/alternative_fe.py").read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            names.add(node.module or "")
            names |= {f"{node.module}.{a.name}" for a in node.names}
    bad = sorted(m for m in names if any(m == f or m.startswith(f + ".") for f in FORBIDDEN)
                 and not m.startswith("skinkit.bench.gap_cases"))
    assert not bad, bad
    assert "skinkit.lab.alt_forms" in names


def test_a_rest_holds_the_zero_position_before_the_sinusoid() -> None:
    plain = programme(make_protocol("in_plane_000", periods=1))
    rested = programme(make_protocol("in_plane_000", periods=1, rest=2.5))
    n_rest = int(round(2.5 * rested.rate_hz))
    assert rested.n == plain.n + n_rest
    np.testing.assert_array_equal(rested.setpoints[:n_rest], 0.0)
    np.testing.assert_array_equal(rested.setpoints[n_rest:], plain.setpoints)


def test_a_negative_rest_is_refused() -> None:
    from skinkit.acquisition.library import ProtocolError

    with pytest.raises(ProtocolError, match="'rest'"):
        programme(make_protocol("in_plane_000", rest=-1.0))


@pytest.mark.needs_plugins
def test_the_noise_colour_is_read_from_the_rest_before_each_protocol() -> None:
    obs = ga.session("ar1-0.9", 0, "quick")
    for po in obs.protocols.values():
        f = po.channels["tip_force"]
        assert f.noise_ar is not None and "rest segment" in f.noise_source, f.noise_source
        for ar in f.noise_ar:
            assert ar.shape == (1,) and abs(ar[0] - 0.9) < 0.04, ar
    white = ga.session("white", 0, "quick")
    assert all(po.channels["tip_force"].noise_ar is None for po in white.protocols.values())


def test_unknown_preset_is_refused() -> None:
    with pytest.raises(ga.BenchmarkError, match="lumped or quick"):
        ga.forms(None, "nonsense")
