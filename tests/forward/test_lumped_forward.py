"""The lumped forward model: closed form, sensitivities, exact nulls of its effects, errors, real record."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from skinkit.errors import ForwardError
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real" / \
    "healthy_skin_extension_relaxation.csv"

SPEC = {
    "model": {"kind": "lumped", "name": "ramp-hold"},
    "lumped": {"axis": "x", "elastic": "exponential", "parameters": {"a": "5 mN", "b": 420.0},
               "relaxation": [{"g": 0.3, "tau": "10 s"}], "preconditioning": {"softening": 0.1}},
}


def session(n_cycles: int = 2) -> Observations:
    """Ramp 8 mm in 5 s, hold 20 s, return, at 100 Hz, ``n_cycles`` protocols."""
    t = np.arange(0, 50.0001, 0.01)
    x = 8e-3 * np.clip(t / 5, 0, 1) * (t < 25) + 8e-3 * np.clip((30 - t) / 5, 0, 1) * (t >= 25)
    X = np.zeros((t.size, 3))
    X[:, 0] = x
    X[:, 1:] = np.nan
    out = {}
    for k in range(n_cycles):
        chans = {"tip_position": Channel("tip_position", t, X * (1 - 0.1 * k), noise=1e-6),
                 "tip_force": Channel("tip_force", t, np.where(np.isnan(X), np.nan, 0.0), noise=1e-3)}
        out[f"cycle{k}"] = ProtocolObservations(Protocol(f"cycle{k}", kind="external"), chans)
    return Observations(out, None, "test")


def test_linear_element_relaxes_as_the_closed_form():
    """A ramp to x0 over T then a hold, linear element k with one Prony term:
    F(t > T) = k x0 [g∞ + g τ/T (1 - e^(-T/τ)) e^(-(t-T)/τ)] (QLV, exact for a linear ramp)."""
    from skinkit.forward import load
    spec = {"model": {"kind": "lumped"},
            "lumped": {"axis": "x", "elastic": "linear", "parameters": {"k": 50.0},
                       "relaxation": [{"g": 0.4, "tau": 3.0}]}}
    m = load(spec)
    obs = session(1)
    F = m.predict(m.parameters(), obs).protocols["cycle0"]["tip_force"].values[:, 0]
    t = obs["cycle0"].channels["tip_force"].time_s
    hold = (t > 5) & (t < 25)
    k, x0, g, tau, T = 50.0, 8e-3, 0.4, 3.0, 5.0
    exact = k * x0 * ((1 - g) + g * tau / T * (1 - np.exp(-T / tau)) * np.exp(-(t[hold] - T) / tau))
    assert np.allclose(F[hold], exact, rtol=1e-10)


@pytest.mark.needs_plugins
def test_sensitivities_match_central_differences():
    """Complex step against central differences with h = 1e-6 of each value (truncation
    ~1e-12, rounding ~1e-10 relative): 1e-6 of the largest derivative."""
    from skinkit.forward import load
    spec = copy.deepcopy(SPEC)
    spec["effects"] = [{"name": "force-offset", "x": "10 mN"}, {"name": "force-drift", "x": "0.1 mN/s"}]
    m = load(spec)
    obs = session()
    pset = m.parameters()
    pred = m.predict(pset, obs, sensitivities=True)
    assert set(pred.methods) == set(pset.names)
    for p in pset:
        h = 1e-6 * max(abs(p.value), 1e-3)
        up = m.predict(pset.with_values({p.name: p.value + h}), obs)
        dn = m.predict(pset.with_values({p.name: p.value - h}), obs)
        for (_, _, cp), (_, _, u), (_, _, d) in zip(pred.items(), up.items(), dn.items(), strict=True):
            fd = (u.values - d.values) / (2 * h)
            size = np.abs(fd).max()
            if size:
                assert np.abs(cp.d[p.name] - fd).max() <= 1e-6 * size, p.name


@pytest.mark.needs_plugins
@pytest.mark.parametrize("effect", ["viscoelastic", "preconditioning", "force-offset", "force-drift"])
def test_lumped_effect_null_is_exact_and_typical_is_seen(effect):
    from skinkit import registry
    from skinkit.forward import load
    base = {"model": {"kind": "lumped"}, "lumped": {"axis": "x", "elastic": "exponential",
                                                    "parameters": {"a": "5 mN", "b": 420.0}}}
    obs = session()
    m0 = load(base)
    ref = m0.predict(m0.parameters(), obs)
    spec = copy.deepcopy(base)
    spec["effects"] = [{"name": effect}]
    m = load(spec)
    p = m.predict(m.parameters(), obs)
    for (_, _, x), (_, _, y) in zip(p.items(), ref.items(), strict=True):
        assert np.max(np.abs(x.values - y.values)) <= 1e-12 * np.max(np.abs(y.values))
    typ = {q.name: q.value for q in registry.create("skinkit.effects", effect).parameters()}
    spec["effects"] = [{"name": effect, **typ}]
    m = load(spec)
    p = m.predict(m.parameters(), obs)
    change = max(np.max(np.abs(x.values - y.values)) for (_, _, x), (_, _, y) in zip(p.items(), ref.items(),
                                                                                       strict=True))
    assert change > 5 * 1e-3   # more than five noise levels of a 1 mN force sensor


def test_bad_lumped_descriptions_are_named():
    from skinkit.forward import load
    for key, value, match in (("elastic", "cubic", "lumped.elastic"), ("axis", "w", "lumped.axis"),
                              ("parameters", {"a": 1.0}, "missing")):
        spec = copy.deepcopy(SPEC)
        spec["lumped"][key] = value
        with pytest.raises(ForwardError, match=match):
            load(spec)
    m = load(SPEC)
    obs = session(1)
    po = obs["cycle0"]
    bad = Observations({"cycle0": ProtocolObservations(po.protocol, {"tip_force": po.channels["tip_force"]})})
    with pytest.raises(ForwardError, match="'cycle0'.*tip_position"):
        m.predict(m.parameters(), bad)


@pytest.mark.skipif(not REAL.is_file(), reason="the real record lies beside the checkout")
def test_real_extension_relaxation_record_is_predicted():
    """The model file of docs/models on the CSV: predictions on every sample, force along x only."""
    from skinkit.forward import load, read_observations
    root = Path(__file__).resolve().parents[2]
    m = load(root / "docs" / "models" / "extension_relaxation_lumped.toml")
    obs = read_observations(REAL, axis="x")
    pred = m.predict(m.parameters(), obs, sensitivities=True)
    (proto, c, cp), = list(pred.items())
    assert c == "tip_force" and cp.values.shape == obs[proto].channels[c].values.shape
    assert np.all(np.isfinite(cp.values[:, 0])) and cp.values[:, 0].max() > 0.1
