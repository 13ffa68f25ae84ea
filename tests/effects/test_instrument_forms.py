"""The instrument effects in the forms a lab meets them: a force sensor's zero settling after it
was switched on or tared (``force-warmup``: ``bias`` entries with ``basis = "warmup"``) and the
force channel sampled late relative to the position (``channel-lag``: a ``lag`` entry), and its zero
wandering slowly (``force-wander``: ``bias`` entries with ``basis = "spline"``).

Closed forms on a lumped model, analytic sensitivities against central differences (lumped
models driven by position and by force, and the finite-element testbed), exact nulls, and
one-line errors naming the entry for inadmissible values."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from skinkit import registry
from skinkit.errors import EffectError, ForwardError
from skinkit.forward import instrument as inst
from skinkit.forward import load
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

pytestmark = pytest.mark.needs_plugins

#: the lumped element's stiffness [N/m], the drive's amplitude [m] and angular frequency [rad/s]
K, U, OMEGA = 200.0, 5e-3, 2 * math.pi * 0.2
#: sampling step [s] (100 Hz) and record length [s]
H, DURATION = 0.01, 20.0
T = np.arange(0.0, DURATION + H / 2, H)
WARMUP = {"x": 0.012, "y": -0.007, "z": 0.004, "tau": 3.0}
LAG = 0.0137      # [s]: not a multiple of the sampling step, so samples fall between knots


def position(t: np.ndarray) -> np.ndarray:
    """The drive along x [m]: U (1 − cos ωt)/2 from rest (0 for t < 0, continuous with its slope)."""
    t = np.asarray(t, dtype=float)
    return np.where(t > 0, 0.5 * U * (1 - np.cos(OMEGA * t)), 0.0)


def session() -> Observations:
    pos = np.zeros((T.size, 3))
    pos[:, 0] = position(T)
    force = K * pos
    chans = {"tip_position": Channel("tip_position", T, pos, noise=1.7e-6),
             "tip_force": Channel("tip_force", T, force, noise=1.7e-3)}
    proto = Protocol("in_plane_000")
    return Observations({proto.name: ProtocolObservations(proto, chans)}, None, "instrument forms")


def lumped(effects: list[dict[str, Any]], drive: str = "tip_position") -> dict[str, Any]:
    return {"model": {"kind": "lumped", "name": "linear"},
            "lumped": {"axis": "x", "drive": drive, "elastic": "linear", "parameters": {"k": K}},
            "effects": effects}


def predict(spec: dict[str, Any], obs: Observations, values: dict[str, float] | None = None,
            names: list[str] | None = None) -> Any:
    with load(spec, workers=1) as m:
        ps = m.parameters()
        if values:
            ps = ps.with_values(values)
        return m.predict(ps, obs, sensitivities=names or False)


def channel(pred: Any, name: str) -> Any:
    (proto,) = pred.protocols.values()
    return proto[name]


# -- closed forms ----------------------------------------------------------------------------------------
def test_warmup_is_the_true_force_plus_a_settling_zero_per_axis():
    obs = session()
    got = channel(predict(lumped([{"name": "force-warmup", **WARMUP}]), obs), "tip_force").values
    expect = np.zeros((T.size, 3))
    expect[:, 0] = K * position(T)
    for i, a in enumerate("xyz"):
        expect[:, i] += WARMUP[a] * (1 - np.exp(-T / WARMUP["tau"]))
    np.testing.assert_allclose(got, expect, rtol=0, atol=1e-14)


def test_the_cubic_bspline_has_its_textbook_values_and_sums_to_one():
    """B(0) = 2/3, B(±1) = 1/6, B(±2) = 0, and the shifted B-splines of a uniform grid are a
    partition of unity (de Boor, A Practical Guide to Splines, ch. IX)."""
    assert inst.cubic_bspline(np.array([0.0, 1.0, -1.0, 2.0, -2.5])).tolist() == pytest.approx(
        [2 / 3, 1 / 6, 1 / 6, 0.0, 0.0], abs=1e-15)
    u = np.linspace(0.0, 5.0, 501)
    total = sum(inst.cubic_bspline(u - k) for k in range(-2, 8))
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-14)


def test_wander_is_the_true_force_plus_a_spline_through_zero_at_the_start():
    """w(t) = Σ_k c_k [B(t/S − k) − B(−k)] per axis, written here from the B-spline's pieces."""
    def b(u: np.ndarray) -> np.ndarray:   # the uniform cubic B-spline, piece by piece
        a = np.abs(u)
        out = np.zeros_like(a)
        inner, outer = a < 1, (a >= 1) & (a < 2)
        out[inner] = 2 / 3 - a[inner] ** 2 + a[inner] ** 3 / 2
        out[outer] = (2 - a[outer]) ** 3 / 6
        return out

    eff = registry.create("skinkit.effects", "force-wander")
    S, n = eff.SPACING, eff.KNOTS
    rng = np.random.default_rng(5)
    coef = {f"{a}{k}": float(rng.normal(0, 0.004)) for a in "xyz" for k in range(1, n + 1)}
    obs = session()
    got = channel(predict(lumped([{"name": "force-wander", **coef}]), obs), "tip_force").values
    expect = np.zeros((T.size, 3))
    expect[:, 0] = K * position(T)
    for i, a in enumerate("xyz"):
        for k in range(1, n + 1):
            expect[:, i] += coef[f"{a}{k}"] * (b(T / S - k) - b(np.array([-float(k)])))
    np.testing.assert_allclose(got, expect, rtol=0, atol=1e-14)
    assert np.all(got[0] == 0)                       # tared: nothing at the record's start
    # linear in every coefficient: the analytic derivative is the basis itself
    pred = predict(lumped([{"name": "force-wander", **coef}]), obs, names=["force-wander.y2"])
    d = channel(pred, "tip_force").d["force-wander.y2"]
    np.testing.assert_allclose(d[:, 1], b(T / S - 2) - b(np.array([-2.0])), rtol=0, atol=1e-15)
    assert np.all(d[:, [0, 2]] == 0)


def spline_error_bound() -> float:
    """Largest error [N] of the cubic spline through f = K u sampled every H: (5/384) H⁴ max|f⁗|
    (Hall & Meyer 1976, for clamped ends; the not-a-knot ends keep the order with a larger
    constant near the ends, hence the factor 10). Here 2.6e-10 × 10 against a peak of 1 N."""
    return 10 * 5 / 384 * H**4 * K * 0.5 * U * OMEGA**4


def test_lag_is_the_true_force_shifted_in_time_to_spline_accuracy():
    obs = session()
    got = channel(predict(lumped([{"name": "channel-lag", "lag": LAG}]), obs), "tip_force").values
    expect = K * position(T - LAG)         # at rest before the record starts
    assert spline_error_bound() < 1e-8
    np.testing.assert_allclose(got[:, 0], expect, rtol=0, atol=spline_error_bound())
    assert np.all(got[:, 1:] == 0)
    # a lag is not an offset: the same force at a later time (peak at the drive's peak + lag)
    assert abs(np.max(got[:, 0]) - np.max(expect)) < 1e-6


def test_a_lag_on_the_driving_force_reads_the_record_later():
    """Force in, position out: the skin saw the recorded force lag later, u(t) = f_rec(t + lag)/K."""
    obs = session()
    spec = lumped([{"name": "channel-lag", "lag": LAG}], "tip_force")
    got = channel(predict(spec, obs), "tip_position").values
    t_read = np.minimum(T + LAG, T[-1])    # held at the last sample after the record ends
    np.testing.assert_allclose(got[:, 0], position(t_read), rtol=0, atol=spline_error_bound() / K)


def test_shift_reproduces_cubics_and_holds_outside_the_record():
    t = np.array([0.0, 0.1, 0.1, 0.25, 0.3, 0.5, 0.8])   # uneven, with a repeated time
    y = np.stack([1 + t - 2 * t**2 + 3 * t**3, -t**2], axis=1)
    val, der = inst.shift(t, y, 0.05)
    q = np.clip(t - 0.05, 0.0, 0.8)
    np.testing.assert_allclose(val, np.stack([1 + q - 2 * q**2 + 3 * q**3, -q**2], axis=1), atol=1e-12)
    dq = np.stack([1 - 4 * q + 9 * q**2, -2 * q], axis=1) * (t - 0.05 >= 0)[:, None]
    np.testing.assert_allclose(der, dq, atol=1e-11)
    same, _ = inst.shift(t, y, 0.0)
    assert np.array_equal(same, y)


# -- sensitivities against central differences ----------------------------------------------------------
def central(spec: dict[str, Any], obs: Observations, values: dict[str, float], name: str, h: float,
            out: str) -> np.ndarray:
    up = channel(predict(spec, obs, {**values, name: values[name] + h}), out).values
    dn = channel(predict(spec, obs, {**values, name: values[name] - h}), out).values
    return (up - dn) / (2 * h)


#: (parameter, step): the amplitude is linear (any step is exact); τ and the lag are smooth, with
#: truncation errors (h²/6) |f‴| ≈ 1e-10 of the derivative at these steps; rounding, ε |f| / h,
#: is up to ~1e-8 of τ's derivative, which is small against the force it perturbs (observed:
#: 4e-9). Agreement to 1e-6 of the largest derivative leaves margin for the lag's spline, whose
#: third derivative jumps at the knots a step may cross.
STEPS = [("force-warmup.x", 1e-4), ("force-warmup.tau", 1e-5), ("channel-lag.lag", 1e-6)]


@pytest.mark.parametrize("drive", ["tip_position", "tip_force"])
def test_analytic_sensitivities_agree_with_central_differences(drive):
    obs = session()
    spec = lumped([{"name": "force-warmup", **WARMUP}, {"name": "channel-lag", "lag": LAG}], drive)
    out = "tip_force" if drive == "tip_position" else "tip_position"
    values = {f"force-warmup.{k}": v for k, v in WARMUP.items()} | {"channel-lag.lag": LAG}
    pred = predict(spec, obs, values, [n for n, _ in STEPS])
    cp = channel(pred, out)
    for name, h in STEPS:
        assert pred.methods[name] in ("analytic", "complex-step"), (name, pred.methods[name])
        fd = central(spec, obs, values, name, h * max(abs(values[name]), 1.0), out)
        scale = float(np.max(np.abs(fd)))
        assert scale > 0, name
        np.testing.assert_allclose(cp.d[name], fd, rtol=0, atol=1e-6 * scale, err_msg=name)


def test_tau_has_no_signature_at_the_null_amplitude():
    """The gap diagnosis holds τ at its null: with A = 0 its derivative is exactly 0."""
    obs = session()
    pred = predict(lumped([{"name": "force-warmup"}]), obs, None, ["force-warmup.tau", "force-warmup.x"])
    cp = channel(pred, "tip_force")
    assert np.all(cp.d["force-warmup.tau"] == 0)
    np.testing.assert_allclose(cp.d["force-warmup.x"][:, 0], 1 - np.exp(-T / 10.0), atol=1e-15)


@pytest.mark.parametrize(("effect", "name", "at"), [
    ({"name": "channel-lag", "lag": 0.05}, "channel-lag.lag", 0.05),
    ({"name": "force-warmup", "x": 0.005, "z": 0.01, "tau": 3.0}, "force-warmup.tau", 3.0),
])
def test_finite_element_drive_sensitivities_agree_with_central_differences(effect, name, at):
    """The testbed disc under force control: the lag and the warm-up move the drive, the
    solver's drive sensitivity carries them into every channel. Solves to rtol 1e-12, steps of
    1 s: differences of whole solves agree to 1e-5 of the largest derivative (observed 1e-8)."""
    from skinkit.plugin.conformance import testbeds

    obs = testbeds.fe_session()
    spec = {**testbeds.fe_model(), "effects": [effect]}
    pred = predict(spec, obs, None, [name])
    # the lag is the entry's own parameter, differentiated through the drive; the finite-element
    # model does not yet read a warm-up's second parameter (tau_parameter) as an instrument one,
    # so it differences τ: either way the derivative must match
    if name == "channel-lag.lag":
        assert pred.methods[name] == "analytic"
    (proto,) = pred.protocols.values()
    h = 1e-4
    (pu,) = predict(spec, obs, {name: at + h}).protocols.values()
    (pd,) = predict(spec, obs, {name: at - h}).protocols.values()
    for cname in ("tip_position", "points"):
        fd = (pu[cname].values - pd[cname].values) / (2 * h)
        scale = float(np.max(np.abs(fd)))
        assert scale > 0, cname
        np.testing.assert_allclose(proto[cname].d[name], fd, rtol=0, atol=1e-5 * scale, err_msg=cname)


#: a lumped indentation model and its session (preconditioning ramp-and-hold, two indentation periods)
GAP_MODEL = {
    "model": {"kind": "lumped", "name": "gap-lumped"},
    "lumped": {"test": "indentation", "family": "quasi-static", "axis": "-z", "drive": "tip_position",
               "elastic": "exponential", "parameters": {"a": "15 mN", "b": 800.0}},
    "session": {"protocols": ["preconditioning", "normal_indentation"],
                "parameters": {"preconditioning": {"hold": 15.0}, "normal_indentation": {"periods": 2}}},
}


@pytest.mark.parametrize("effect", [{"name": "channel-lag", "lag": 0.03},
                                    {"name": "force-warmup", "z": 0.02, "tau": 5.0}])
def test_the_gap_diagnosis_names_the_effect_in_a_virtual_lab_truth(effect):
    """End to end: a truth with the effect (a 30 ms lag; a 20 mN settling over 5 s), the model
    without it; the diagnosis names it first (the linear drift, its nearest rival for the
    warm-up, is not)."""
    from skinkit.gap import diagnose
    from skinkit.inverse.coverage import LabSessions

    obs = LabSessions({**GAP_MODEL, "effects": [effect]})(1)
    rep = diagnose(GAP_MODEL, obs, max_effects=1)
    assert rep.named == [effect["name"]], rep.to_dict()["rounds"]


# -- nulls and inadmissible values ---------------------------------------------------------------------
@pytest.mark.parametrize("drive", ["tip_position", "tip_force"])
def test_the_null_leaves_the_model_unchanged(drive):
    obs = session()
    out = "tip_force" if drive == "tip_position" else "tip_position"
    ref = channel(predict(lumped([], drive), obs), out).values
    for name in ("force-warmup", "channel-lag"):
        got = channel(predict(lumped([{"name": name}], drive), obs), out).values
        assert np.array_equal(got, ref), name


def test_instrument_entries_are_exact_identities_at_zero():
    rng = np.random.default_rng(3)
    f = rng.standard_normal((T.size, 3))
    entries = inst.parse([{"kind": "bias", "parameter": "a", "value": 0.0, "channel": "tip_force",
                           "basis": "warmup", "tau": 2.0, "tau_parameter": "tau"},
                          {"kind": "lag", "parameter": "lag", "value": 0.0}])
    rec, _ = inst.measure(entries, "tip_force", T, f, {}, {}, ["a", "tau", "lag"])
    true, _ = inst.drive(entries, "tip_force", T, f, ["a", "tau", "lag"])
    assert np.array_equal(rec, f) and np.array_equal(true, f)


def one_line(exc: Exception) -> bool:
    return "\n" not in str(exc)


@pytest.mark.parametrize(("table", "where"), [
    ({"basis": "warmup", "tau": 0.0}, "instrument[0].tau"),
    ({"basis": "warmup", "tau": "-2 s"}, "instrument[0].tau"),
    ({"basis": "warmup"}, "instrument[0].tau"),
    ({"basis": "constant", "tau": 2.0}, "instrument[0].tau"),
    ({"basis": "spline", "knot": 1}, "instrument[0].tau"),
    ({"basis": "spline", "tau": 50.0}, "instrument[0].knot"),
    ({"basis": "spline", "tau": 50.0, "knot": 0}, "instrument[0].knot"),
    ({"basis": "spline", "tau": 50.0, "knot": 1.5}, "instrument[0].knot"),
    ({"basis": "spline", "tau": 50.0, "knot": 1, "tau_parameter": "s"}, "instrument[0].tau_parameter"),
    ({"basis": "time", "knot": 1}, "instrument[0].knot"),
    ({"kind": "lag", "value": 0.6}, "instrument[0].value"),
    ({"kind": "lag", "value": "-600 ms"}, "instrument[0].value"),
    ({"kind": "lag", "value": 0.01, "channel": "points"}, "instrument[0].channel"),
])
def test_inadmissible_instrument_entries_name_the_entry(table, where):
    entry = {"kind": "bias", "parameter": "p", "value": 0.01, "channel": "tip_force", **table}
    with pytest.raises(ForwardError) as err:
        inst.parse([entry])
    assert err.value.entry == where, err.value
    assert one_line(err.value)


@pytest.mark.parametrize(("effect", "values", "where"), [
    ("force-warmup", {"x": 0.01, "tau": 0.0}, "effects[0].tau"),
    ("force-warmup", {"x": 0.01, "tau": -1.0}, "effects[0].tau"),
    ("channel-lag", {"lag": 0.6}, "effects[0].lag"),
    ("channel-lag", {"lag": "-501 ms"}, "effects[0].lag"),
])
def test_inadmissible_effect_values_name_the_entry(effect, values, where):
    with pytest.raises(EffectError) as err:
        load(lumped([{"name": effect, **values}]), workers=1)
    assert err.value.entry == where, err.value
    assert "outside the admissible range" in err.value.problem and one_line(err.value)


def test_the_effects_are_documented_and_declared_as_promised():
    warm = registry.create("skinkit.effects", "force-warmup")
    lag = registry.create("skinkit.effects", "channel-lag")
    assert {p.name: p.unit for p in warm.parameters()} == {"x": "N", "y": "N", "z": "N", "tau": "s"}
    assert warm.null() == {"x": 0.0, "y": 0.0, "z": 0.0, "tau": 10.0}
    assert [(p.name, p.unit, p.value, p.lower, p.upper) for p in lag.parameters()] == \
        [("lag", "s", pytest.approx(0.01), pytest.approx(-0.5), pytest.approx(0.5))]
    assert lag.null() == {"lag": 0.0}
    for e in (warm, lag):
        doc = type(e).__doc__ or ""
        assert "Not covered" in doc and "Phenomenon" in doc, e.name
