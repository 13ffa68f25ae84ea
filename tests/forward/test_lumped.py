"""Lumped forward models: closed forms, sensitivities vs central differences, exact nulls, round
trips within the chi-square range, and errors that name the entry."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest
from scipy import stats

from skinkit.errors import ForwardError
from skinkit.forward.lumped import build_lumped
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

AX = {"x": 0, "y": 1, "z": 2}


def ramp_hold(t: np.ndarray, peak: float, up: float = 2.0, hold: float = 4.0) -> np.ndarray:
    """0 -> peak over ``up`` s, hold, back to 0 over ``up`` s."""
    return peak * np.clip(np.minimum(t / up, (2 * up + hold - t) / up), 0, 1)


def session(drive: str, values: list[np.ndarray], t: np.ndarray, axis: str = "x",
            predicted: list[np.ndarray] | None = None, noise: float = 1e-3) -> Observations:
    """Protocols ``p0, p1, ...`` with ``drive`` along ``axis`` (other components NaN) and the
    other tip channel (zeros or ``predicted`` along the axis)."""
    other = "tip_force" if drive == "tip_position" else "tip_position"
    j = AX[axis.lstrip("-")]
    out = {}
    for k, v in enumerate(values):
        D = np.full((t.size, 3), np.nan)
        D[:, j] = v
        P = np.full((t.size, 3), np.nan)
        P[:, j] = 0.0 if predicted is None else predicted[k]
        chans = {drive: Channel(drive, t, D, noise=noise), other: Channel(other, t, P, noise=noise)}
        out[f"p{k}"] = ProtocolObservations(Protocol(f"p{k}", kind="external"), chans)
    return Observations(out, None, "test")


T_QS = np.arange(0, 12.0 + 1e-9, 0.02)
DISP = [ramp_hold(T_QS, 6e-3), ramp_hold(T_QS, 4e-3) + 1e-3 * np.sin(2 * T_QS)]
#: a displacement-driven exponential element with everything the vocabulary offers
QS: dict[str, Any] = {
    "model": {"kind": "lumped", "name": "qs"},
    "lumped": {"axis": "x", "elastic": "exponential", "parameters": {"a": "20 mN", "b": 300.0},
               "relaxation": [{"g": 0.3, "tau": "1.5 s"}, {"g": 0.1, "tau": "20 s"}],
               "preconditioning": {"softening": 0.2}},
    "instrument": [
        {"kind": "bias", "parameter": "off.x", "value": 0.01, "channel": "tip_force", "component": 0},
        {"kind": "bias", "parameter": "drift.x", "value": 1e-3, "channel": "tip_force", "component": 0,
         "basis": "time"},
        {"kind": "bias", "parameter": "zero.x", "value": 2e-4, "channel": "tip_position", "component": 0},
        {"kind": "series", "parameter": "comp", "value": 2e-3, "channel": "tip_position",
         "source": "tip_force"},
        {"kind": "tilt", "parameter": "tilt.angle", "value": 0.05, "azimuth": 0.4,
         "azimuth_parameter": "tilt.azimuth"},
    ],
}
FORCE = [ramp_hold(T_QS, 0.4), ramp_hold(T_QS, 0.3) + 0.05 * np.sin(2 * T_QS)]
#: a force-driven cubic element along -z (indentation), measured position with a series compliance
QS_FORCE: dict[str, Any] = {
    "model": {"kind": "lumped", "name": "qs-force"},
    "lumped": {"axis": "-z", "drive": "tip_force", "elastic": "polynomial",
               "parameters": {"c1": 100.0, "c2": 5e3, "c3": 2e6},
               "relaxation": [{"g": 0.25, "tau": "2 s"}], "preconditioning": {"softening": 0.15}},
    "instrument": [
        {"kind": "bias", "parameter": "off.z", "value": 0.02, "channel": "tip_force", "component": 2},
        {"kind": "bias", "parameter": "zero.z", "value": 1e-4, "channel": "tip_position", "component": 2},
        {"kind": "series", "parameter": "comp", "value": 1e-3, "channel": "tip_position",
         "source": "tip_force"},
    ],
}
T_DYN = np.arange(0, 2.0, 1 / 500)
_rng = np.random.default_rng(3)
_white = _rng.standard_normal(T_DYN.size + 200)
DYN_FORCE = [1.0 + 0.5 * np.convolve(_white, np.ones(20) / np.sqrt(20), "same")[100:-100]]
KBI: dict[str, Any] = {"model": {"kind": "lumped", "name": "kbi"},
                       "lumped": {"family": "kbi", "axis": "-z",
                                  "parameters": {"K": "1.45 kN/m", "B": 4.76, "I": "40.5 g"}},
                       "instrument": [{"kind": "bias", "parameter": "zero.z", "value": -2e-4,
                                       "channel": "tip_position", "component": 2},
                                      {"kind": "series", "parameter": "comp", "value": 1e-4,
                                       "channel": "tip_position", "source": "tip_force"}]}
WIENER: dict[str, Any] = {"model": {"kind": "lumped", "name": "wiener"},
                          "lumped": {"family": "wiener", "axis": "-z", "hold": "foh",
                                     "parameters": {"Is": 2.8e-5, "Bs": 3.3e-3, "C1": "8.6 mm", "C2": 0.51}},
                          "instrument": [{"kind": "bias", "parameter": "off.z", "value": 0.05,
                                          "channel": "tip_force", "component": 2}]}

CASES = {"qs": (QS, "tip_position", DISP, T_QS, "x"),
         "qs-force": (QS_FORCE, "tip_force", FORCE, T_QS, "-z"),
         "kbi": (KBI, "tip_force", DYN_FORCE, T_DYN, "-z"),
         "wiener": (WIENER, "tip_force", DYN_FORCE, T_DYN, "-z")}


def case(name: str, spec: dict[str, Any] | None = None):
    s, drive, values, t, axis = CASES[name]
    sign = -1.0 if axis.startswith("-") else 1.0
    return build_lumped(copy.deepcopy(spec or s)), session(drive, [sign * v for v in values], t, axis)


def at_null(spec: dict[str, Any]) -> dict[str, Any]:
    """The spec with every instrument entry, relaxation modulus and softening at its null (0)."""
    s = copy.deepcopy(spec)
    for e in s.get("instrument", []):
        e["value"] = 0.0
    for r in s["lumped"].get("relaxation", []):
        r["g"] = 0.0
    if "preconditioning" in s["lumped"]:
        s["lumped"]["preconditioning"]["softening"] = 0.0
    return s


def values(pred) -> np.ndarray:
    return np.concatenate([cp.values.ravel() for _, _, cp in pred.items()])


# -- closed forms ------------------------------------------------------------------------------------
def test_series_compliance_on_a_displacement_drive_is_the_springs_in_series():
    """Linear element k behind a compliance c: recorded u = u_tip + c k u_tip, so f = k u/(1 + c k)."""
    k, c = 80.0, 4e-3
    spec = {"model": {"kind": "lumped"}, "lumped": {"elastic": "linear", "parameters": {"k": k}},
            "instrument": [{"kind": "series", "parameter": "c", "value": c, "channel": "tip_position",
                            "source": "tip_force"}]}
    m = build_lumped(spec)
    obs = session("tip_position", DISP, T_QS)
    f = m.predict(m.parameters(), obs).protocols["p1"]["tip_force"].values[:, 0]
    assert np.allclose(f, k * DISP[1] / (1 + c * k), rtol=1e-13, atol=0)


def test_force_drive_inverts_the_displacement_drive():
    """Force-driven prediction of the force a displacement-driven twin produced returns the
    displacement (QLV inverse filter, then the polynomial element inverted by Newton), to rounding."""
    lumped = {"axis": "x", "elastic": "polynomial", "parameters": {"c1": 100.0, "c2": 5e3, "c3": 2e6},
              "relaxation": [{"g": 0.25, "tau": "2 s"}, {"g": 0.2, "tau": "0.3 s"}],
              "preconditioning": {"softening": 0.15}}
    # softening off: under a force drive m(t) is the force's running maximum, not the displacement's
    lumped["preconditioning"]["softening"] = 0.0
    m0 = build_lumped({"model": {"kind": "lumped"}, "lumped": lumped})
    p0 = m0.predict(m0.parameters(), session("tip_position", DISP, T_QS))
    f0 = [p0.protocols[f"p{k}"]["tip_force"].values[:, 0] for k in range(2)]
    inv0 = build_lumped({"model": {"kind": "lumped"}, "lumped": {**lumped, "drive": "tip_force"}})
    back = inv0.predict(inv0.parameters(), session("tip_force", f0, T_QS))
    for k in range(2):
        assert np.allclose(back.protocols[f"p{k}"]["tip_position"].values[:, 0], DISP[k], rtol=0,
                           atol=1e-12 * 6e-3)
    assert back.inputs == {"p0": "tip_force", "p1": "tip_force"}


def test_relaxation_is_exact_on_a_nonuniform_time_base():
    """Linear element, one Prony term, ramp to x0 over T then hold: f(t > T) = k x0 [g∞ + g τ/T
    (1 − e^(−T/τ)) e^(−(t−T)/τ)]; the recurrence is exact for a piecewise-linear drive, also
    with uneven steps (the step-by-step path)."""
    t = np.unique(np.concatenate([np.linspace(0, 2, 7), np.linspace(2, 10, 301) ** 1.0]))
    x0, T, k, g, tau = 5e-3, 2.0, 60.0, 0.4, 1.3
    x = x0 * np.clip(t / T, 0, 1)
    spec = {"model": {"kind": "lumped"}, "lumped": {"elastic": "linear", "parameters": {"k": k},
                                                    "relaxation": [{"g": g, "tau": tau}]}}
    m = build_lumped(spec)
    f = m.predict(m.parameters(), session("tip_position", [x], t)).protocols["p0"]["tip_force"].values[:, 0]
    hold = t >= T
    exact = k * x0 * ((1 - g) + g * tau / T * (1 - np.exp(-T / tau)) * np.exp(-(t[hold] - T) / tau))
    assert np.allclose(f[hold], exact, rtol=1e-12, atol=0)


def test_preconditioning_follows_the_session_maximum():
    """φ = 1 − s m(t)/m_ref: the first protocol (peak 6 mm) softens as it rises, the second
    (below that peak) sees 1 − s throughout."""
    k, s = 50.0, 0.3
    m = build_lumped({"model": {"kind": "lumped"}, "lumped": {
        "elastic": "linear", "parameters": {"k": k}, "preconditioning": {"softening": s}}})
    pred = m.predict(m.parameters(), session("tip_position", DISP, T_QS))
    f0, f1 = (pred.protocols[p]["tip_force"].values[:, 0] for p in ("p0", "p1"))
    level0 = np.maximum.accumulate(np.abs(DISP[0])) / max(np.abs(d).max() for d in DISP)
    assert np.allclose(f0, k * DISP[0] * (1 - s * level0), rtol=1e-14)
    assert np.allclose(f1, k * DISP[1] * (1 - s), rtol=1e-14)


def test_indentation_along_minus_z_stiffens_into_the_skin():
    """axis = "-z": u = −z (into the skin) and the predicted z force is −a (exp(b u) − 1)."""
    a, b = 0.02, 400.0
    m = build_lumped({"model": {"kind": "lumped"}, "lumped": {"axis": "-z", "elastic": "exponential",
                                                              "parameters": {"a": a, "b": b}}})
    depth = ramp_hold(T_QS, 3e-3)
    pred = m.predict(m.parameters(), session("tip_position", [-depth], T_QS, "-z"))
    cp = pred.protocols["p0"]["tip_force"]
    assert np.allclose(cp.values[:, 2], -a * np.expm1(b * depth), rtol=1e-14, atol=0)
    assert np.all(cp.values[:, :2] == 0) and cp.predicted[:, 2].all() and not cp.predicted[:, :2].any()
    assert m.axis == "z" and m.default_protocols == ("normal_indentation",)


def test_dynamic_models_are_the_sysid_simulations():
    """K-B-I and Wiener forward models equal skinkit.sysid's simulation (robot frame: force and
    position into the skin, hence axis = "-z") to rounding."""
    from skinkit.sysid.lti import SecondOrder, simulate
    from skinkit.sysid.simulate import exponential
    f = DYN_FORCE[0]
    for name in ("kbi", "wiener"):
        spec = copy.deepcopy(CASES[name][0])
        spec.pop("instrument")
        m, obs = case(name, spec)
        y = -m.predict(m.parameters(), obs).protocols["p0"]["tip_position"].values[:, 2]
        if name == "kbi":
            ref = simulate(SecondOrder(1450.0, 4.76, 0.0405), f, 500.0)
        else:
            ref = exponential(simulate(SecondOrder.from_scaled(2.8e-5, 3.3e-3), f, 500.0), 8.6e-3, 0.51)
        assert np.allclose(y, ref, rtol=0, atol=1e-11 * np.abs(ref).max()), name
    assert m.default_protocols == ("stochastic_full_scale",)


# -- sensitivities ------------------------------------------------------------------------------------
#: step scale for parameters whose value may be 0 (instrument entries, moduli at their null)
SCALE = {"off.x": 0.01, "off.z": 0.01, "drift.x": 1e-3, "zero.x": 1e-4, "zero.z": 1e-4, "comp": 1e-3,
         "tilt.angle": 0.05, "tilt.azimuth": 1.0, "lumped.g1": 0.1, "lumped.g2": 0.1, "lumped.softening": 0.1}


@pytest.mark.parametrize("null", [False, True], ids=["typical", "null"])
@pytest.mark.parametrize("name", list(CASES))
def test_sensitivities_match_central_differences(name, null):
    """Every channel's derivative with respect to every parameter against differences with a
    step h = 1e-5 of the parameter's scale: central (truncation h²/6 f''' ≈ 1e-10 of the
    derivative's scale, rounding ≈ 1e-16 |f| / h ≈ 1e-11), or at a lower bound the second-order
    one-sided formula (truncation h²/3 f'''). Tolerance 1e-6 of the largest derivative
    plus 1e-9 |f|/scale for derivatives that vanish (a tilt at 0)."""
    spec = at_null(CASES[name][0]) if null else CASES[name][0]
    m, obs = case(name, spec)
    pset = m.parameters()
    pred = m.predict(pset, obs, sensitivities=True)
    assert set(pred.methods) == set(pset.names)
    assert all(v in ("complex-step", "analytic") for v in pred.methods.values())
    f0 = values(pred)
    worst = 0.0
    for p in pset:
        scale = max(abs(p.value), SCALE.get(p.name, 0.0))
        h = 1e-5 * scale
        cs = np.concatenate([cp.d[p.name].ravel() for _, _, cp in pred.items()])
        if p.value - h >= p.lower:
            fd = (values(m.predict(pset.with_values({p.name: p.value + h}), obs))
                  - values(m.predict(pset.with_values({p.name: p.value - h}), obs))) / (2 * h)
        else:
            f1 = values(m.predict(pset.with_values({p.name: p.value + h}), obs))
            f2 = values(m.predict(pset.with_values({p.name: p.value + 2 * h}), obs))
            fd = (-3 * f0 + 4 * f1 - f2) / (2 * h)
        tol = 1e-6 * np.abs(fd).max() + 1e-9 * np.abs(f0).max() / scale
        err = np.abs(cs - fd).max()
        worst = max(worst, err / max(np.abs(fd).max(), 1e-300))
        assert err <= tol, (p.name, err, tol)
    print(f"{name} null={null}: worst relative error {worst:.2e}")


def test_bound_effect_names_report_the_model_parameter():
    """bindings: an effect's name stands for the lumped parameter it is bound to."""
    spec = copy.deepcopy(QS)
    spec["bindings"] = {"visco.g1": "lumped.g1"}
    m, obs = case("qs", spec)
    assert "lumped.g1" not in m.parameters().names
    # without the effect registered the binding names a parameter the set does not hold
    pred = m.predict(m.parameters(), obs, sensitivities=["lumped.g2"])
    assert pred.methods == {"lumped.g2": "complex-step"}


# -- nulls ----------------------------------------------------------------------------------------
def _without(spec: dict[str, Any], what: str) -> dict[str, Any]:
    s = copy.deepcopy(spec)
    if what.startswith("instrument"):
        del s["instrument"][int(what[-1])]
    elif what == "relaxation":
        del s["lumped"]["relaxation"][-1]
    elif what == "preconditioning":
        del s["lumped"]["preconditioning"]
    return s


@pytest.mark.parametrize("name", ["qs", "qs-force", "kbi", "wiener"])
def test_every_term_at_its_null_changes_nothing(name):
    """Each instrument entry, relaxation term and the preconditioning at value 0 leaves every
    prediction unchanged to 1e-12 relative (the model without it)."""
    spec = at_null(CASES[name][0])
    whats = [f"instrument{i}" for i in range(len(spec.get("instrument", [])))]
    whats += [w for w in ("relaxation", "preconditioning") if w in spec["lumped"]]
    m, obs = case(name, spec)
    ref = values(m.predict(m.parameters(), obs))
    for what in whats:
        mw, _ = case(name, _without(spec, what))
        got = values(mw.predict(mw.parameters(), obs))
        assert np.abs(got - ref).max() <= 1e-12 * np.abs(ref).max(), what


# -- round trip ------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(CASES))
def test_round_trip_chi_square_is_within_the_noise_range(name):
    """Simulate with the true parameters, add Gaussian noise of known σ to the predicted
    channel, predict with the same parameters: Σ r²/n must lie in the chi-square distribution's
    central 99.9 % range for n degrees of freedom (no parameter is fitted)."""
    s, drive, vals, t, axis = CASES[name]
    m, obs = case(name)
    clean = m.predict(m.parameters(), obs)
    other = "tip_force" if drive == "tip_position" else "tip_position"
    j = AX[axis.lstrip("-")]
    sigma = 1e-3 if other == "tip_force" else 2e-6
    rng = np.random.default_rng(11)
    noisy = [clean.protocols[f"p{k}"][other].values[:, j] + sigma * rng.standard_normal(t.size)
             for k in range(len(vals))]
    sign = -1.0 if axis.startswith("-") else 1.0
    data = session(drive, [sign * v for v in vals], t, axis, predicted=noisy, noise=sigma)
    chi2, n = m.predict(m.parameters(), data).chi2(data)
    assert n == t.size * len(vals)
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], n) / n
    assert lo <= chi2 / n <= hi, (chi2 / n, lo, hi)


# -- errors ---------------------------------------------------------------------------------------
def test_missing_drive_channel_names_protocol_and_channel():
    m, obs = case("qs")
    po = obs["p0"]
    bad = Observations({"p0": ProtocolObservations(po.protocol, {"tip_force": po.channels["tip_force"]})})
    with pytest.raises(ForwardError, match=r"'p0'.*no 'tip_position' channel to drive"):
        m.predict(m.parameters(), bad)


@pytest.mark.parametrize("edit, entry", [
    (("lumped", "elastic", "cubic"), "lumped.elastic"),
    (("lumped", "family", "arx"), "lumped.family"),
    (("lumped", "axis", "w"), "lumped.axis"),
    (("lumped", "drive", "points"), "lumped.drive"),
    (("parameters", "a", "5 kPa"), "lumped.parameters.a"),
    (("parameters", "a", -1.0), "lumped.parameters.a"),
    (("parameters", "b", "soft"), "lumped.parameters.b"),
    (("parameters", "k", 1.0), "lumped.parameters"),
    (("relaxation", "g", 0.95), "lumped.relaxation"),
    (("relaxation", "tau", "-1 s"), "lumped.relaxation[0].tau"),
    (("lumped", "unknown", 1), "lumped"),
    (("instrument", "kind", "gain"), "instrument[0].kind"),
    (("instrument", "kind", "similarity"), "instrument[0].kind"),
])
def test_bad_descriptions_are_named(edit, entry):
    spec = copy.deepcopy(QS)
    where, key, value = edit
    if where == "lumped":
        spec["lumped"][key] = value
    elif where == "parameters":
        spec["lumped"]["parameters"][key] = value
    elif where == "relaxation":
        spec["lumped"]["relaxation"][0][key] = value
    else:
        spec["instrument"][0][key] = value
        if value == "similarity":
            spec["instrument"][0]["channel"] = "points"
    with pytest.raises(ForwardError) as err:
        build_lumped(spec)
    assert err.value.entry.startswith(entry), err.value


def test_quasi_static_terms_on_a_dynamic_model_and_bad_values_at_predict_are_refused():
    spec = copy.deepcopy(KBI)
    spec["lumped"]["relaxation"] = [{"g": 0.1, "tau": 1.0}]
    with pytest.raises(ForwardError, match="lumped.relaxation"):
        build_lumped(spec)
    m, obs = case("qs")
    with pytest.raises(ForwardError, match="lumped.relaxation.*sum"):
        m.predict(m.parameters().with_values({"lumped.g1": 0.95}), obs)
    m, obs = case("kbi")
    t = T_DYN.copy()
    t[5:] += 1e-3
    po = obs["p0"]
    uneven = Observations({"p0": ProtocolObservations(po.protocol, {
        c: Channel(c, t, ch.values, noise=ch.noise) for c, ch in po.channels.items()})})
    with pytest.raises(ForwardError, match="uniformly sampled"):
        m.predict(m.parameters(), uneven)


@pytest.mark.parametrize("kind,p", [("exponential", {"a": 0.05, "b": 900.0}), ("linear", {"k": 250.0})])
def test_a_compliance_at_its_null_is_linearised_to_rounding(kind, p):
    """Near c = 0 the series solve takes the first-order filters, not a Newton per sample:
    the force and its complex-step derivative in c agree with the per-sample solve (forced by a
    compliance just above the linearisation's bound) to the (c k)² they neglect."""
    from skinkit.forward import lumped_elements as el

    t = np.linspace(0.0, 10.0, 2001)
    u = 2e-3 * (1 - np.cos(2 * np.pi * 0.3 * t))
    g, tau = [0.3, 0.2], [0.2, 2.0]
    k = float(np.max(np.abs(el.elastic_slope(kind, p, u))))
    _, f0 = el.series_solve(t, u, 1.0, kind, p, g, tau, 0.0, "c")
    assert np.array_equal(f0, el.qlv(t, el.elastic_force(kind, p, u), g, tau))
    h = 1e-30
    _, fc = el.series_solve(t, u, 1.0, kind, p, g, tau, 1j * h, "c")
    # the per-sample solve at a compliance 100x the bound: its own second-order term is 1e-12
    c = 100 * el.LINEAR_COMPLIANCE / k
    _, fn = el.series_solve(t, u, 1.0, kind, p, g, tau, c, "c")
    slope = (fn - f0) / c
    assert np.max(np.abs(np.imag(fc) / h - slope)) <= 1e-5 * np.max(np.abs(slope))
