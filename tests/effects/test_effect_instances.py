"""An effect added more than once: ``[[effects]]`` tables with an ``instance`` label.

``viscoelastic`` declares ``repeatable = True``: a second instance adds a second Prony term,
its parameters named after the label. On a lumped linear element under ramp-hold cycles the
prediction is checked against the two-term QLV closed form written here with numpy, and the
sensitivities to both instances' parameters against central differences. Then the errors, an
FE model with two instances, and the score step with an instance label as a candidate on a
session whose truth has two relaxation time scales (generated here, without the plugin).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

from skinkit import registry
from skinkit.errors import EffectError
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

pytestmark = pytest.mark.needs_plugins

#: a linear lumped element F = k u along x, displacement in, force out
LUMPED = {"model": {"kind": "lumped", "name": "linear-two-scales"},
          "lumped": {"axis": "x", "elastic": "linear", "parameters": {"k": 50.0}}}
K = 50.0                       # [N/m]
G, TAU = (0.3, 0.2), (1.0, 20.0)   # [1], [s]: the two Prony terms
DT = 0.05                      # [s] sampling step; every ramp starts and ends on a sample
NOISE = 1e-3                   # [N] force noise (the peak force is k u = 0.25 N)


def two_instances(g: tuple[float, float] = G, tau: tuple[float, float] = TAU) -> list[dict[str, Any]]:
    return [{"name": "viscoelastic", "g1": g[0], "tau1": tau[0]},
            {"name": "viscoelastic", "instance": "viscoelastic-2", "g1": g[1], "tau1": tau[1]}]


def load(spec: dict[str, Any]) -> Any:
    """The forward model of ``spec`` (one worker), its description checked and effects applied."""
    from skinkit.forward import load as _load

    return _load(spec, workers=1)


# ------------------------------------------------------------------------------ the closed form
def ramp_hold(n_cycles: int = 2) -> tuple[np.ndarray, np.ndarray, list[tuple[float, float]]]:
    """Ramp-hold cycles: to 5 mm in 0.5 s, hold 30 s, back in 0.5 s, rest 10 s (41 s each).

    Returns t ``(T,)`` [s], u ``(T,)`` [m] and the slope changes ``(t_j [s], Δs_j [m/s])``, so
    that u(t) = Σ_j Δs_j (t − t_j)₊."""
    U, ramp, hold, rest = 5e-3, 0.5, 30.0, 10.0
    period = 2 * ramp + hold + rest
    kinks = []
    for c in range(n_cycles):
        t0 = c * period
        r = U / ramp
        kinks += [(t0, r), (t0 + ramp, -r), (t0 + ramp + hold, -r), (t0 + 2 * ramp + hold, r)]
    t = np.round(np.arange(0, n_cycles * period + DT / 2, DT), 10)
    u = sum(s * np.maximum(t - tj, 0.0) for tj, s in kinks)
    return t, u, kinks


def qlv_closed_form(t: np.ndarray, kinks: list[tuple[float, float]], k: float,
                    g: tuple[float, ...], tau: tuple[float, ...]) -> np.ndarray:
    """Force ``(T,)`` [N] of a QLV linear element k [N/m] with relaxation function
    G(x) = g∞ + Σᵢ gᵢ exp(−x/τᵢ) under u = Σ_j Δs_j (t − t_j)₊: by superposition of the
    response to a unit ramp, k [g∞ x + Σᵢ gᵢ τᵢ (1 − exp(−x/τᵢ))] for x = t − t_j > 0."""
    ginf = 1.0 - sum(g)
    f = np.zeros_like(t)
    for tj, s in kinks:
        x = np.maximum(t - tj, 0.0)
        f += s * k * (ginf * x + sum(gi * ti * -np.expm1(-x / ti) for gi, ti in zip(g, tau, strict=True)))
    return f


def session(forces: list[np.ndarray] | None = None, n_cycles: int = 2) -> Observations:
    """One protocol of ramp-hold cycles along x: the drive and the force (zeros unless given)."""
    t, u, _ = ramp_hold(n_cycles)
    X = np.full((t.size, 3), np.nan)
    X[:, 0] = u
    F = np.full((t.size, 3), np.nan)
    F[:, 0] = forces[0] if forces is not None else 0.0
    chans = {"tip_position": Channel("tip_position", t, X, noise=1e-6),
             "tip_force": Channel("tip_force", t, F, noise=NOISE)}
    protocol = ProtocolObservations(Protocol("ramps", kind="external"), chans)
    return Observations({"ramps": protocol}, None, "test")


def _force(model: Any, params: Any, obs: Observations) -> np.ndarray:
    return model.predict(params, obs).protocols["ramps"]["tip_force"].values[:, 0]


def test_two_instances_predict_the_two_term_closed_form():
    """Two instances are two Prony terms: the prediction is the two-term QLV closed form to rounding."""
    spec = {**copy.deepcopy(LUMPED), "effects": two_instances()}
    model = load(spec)
    obs = session()
    t, _, kinks = ramp_hold()
    exact = qlv_closed_form(t, kinks, K, G, TAU)
    F = _force(model, model.parameters(), obs)
    assert np.max(np.abs(F - exact)) <= 1e-10 * np.max(np.abs(exact))
    names = model.parameters().names
    assert {"viscoelastic.g1", "viscoelastic.tau1", "viscoelastic-2.g1", "viscoelastic-2.tau1"} <= set(names)


def closed_form_derivatives(t: np.ndarray, kinks: list[tuple[float, float]], k: float,
                            g: tuple[float, ...], tau: tuple[float, ...]) -> dict[int, dict[str, np.ndarray]]:
    """Term i -> ``{"g": ∂f/∂gᵢ [N], "tau": ∂f/∂τᵢ [N/s]}`` of :func:`qlv_closed_form` ``(T,)``
    (g∞ = 1 − Σ g, so ∂/∂gᵢ of the unit-ramp response is τᵢ (1 − exp(−x/τᵢ)) − x)."""
    out = {}
    for i, (gi, ti) in enumerate(zip(g, tau, strict=True)):
        dg, dtau = np.zeros_like(t), np.zeros_like(t)
        for tj, s in kinks:
            x = np.maximum(t - tj, 0.0)
            dg += s * k * (ti * -np.expm1(-x / ti) - x)
            dtau += s * k * gi * (-np.expm1(-x / ti) - x / ti * np.exp(-x / ti))
        out[i] = {"g": dg, "tau": dtau}
    return out


def test_sensitivities_to_both_instances_are_exact():
    """The sensitivities to both instances' parameters are the closed form's derivatives to
    rounding (1e-9 of the largest), and agree with central differences with h = 1e-4 of each
    value to 1e-5 (truncation ~(h/τ)²; a smaller h meets the rounding of the Prony filter,
    whose pole exp(−Δt/τ) lies within 3e-3 of 1 for τ = 20 s)."""
    spec = {**copy.deepcopy(LUMPED), "effects": two_instances()}
    model = load(spec)
    obs = session()
    t, _, kinks = ramp_hold()
    ps = model.parameters()
    exact = closed_form_derivatives(t, kinks, K, G, TAU)
    wanted = {"viscoelastic.g1": exact[0]["g"], "viscoelastic.tau1": exact[0]["tau"],
              "viscoelastic-2.g1": exact[1]["g"], "viscoelastic-2.tau1": exact[1]["tau"],
              "lumped.k": qlv_closed_form(t, kinks, 1.0, G, TAU)}
    d = model.predict(ps, obs, sensitivities=list(wanted)).protocols["ramps"]["tip_force"].d
    for n, ex in wanted.items():
        size = np.max(np.abs(ex))
        assert np.max(np.abs(d[n][:, 0] - ex)) <= 1e-9 * size, n
        h = 1e-4 * abs(ps[n])
        fd = (_force(model, ps.with_values({n: ps[n] + h}), obs)
              - _force(model, ps.with_values({n: ps[n] - h}), obs)) / (2 * h)
        assert np.max(np.abs(d[n][:, 0] - fd)) <= 1e-5 * size, n


def test_the_prony_sum_counts_every_instance():
    """The moduli of all instances must sum below 1, on a lumped and on an FE model."""
    with pytest.raises(EffectError, match="sum below 1"):
        load({**copy.deepcopy(LUMPED), "effects": two_instances(g=(0.6, 0.5))})
    with pytest.raises(EffectError, match="sum below 1"):
        load({**copy.deepcopy(FE), "effects": two_instances(g=(0.6, 0.5))})


# ------------------------------------------------------------------------------------- errors
def _refused(tables: list[dict[str, Any]], kind: str = "fe") -> EffectError:
    from skinkit.forward.effects import resolve

    with pytest.raises(EffectError) as exc:
        resolve(tables, kind)
    return exc.value


def test_a_non_repeatable_effect_takes_no_second_instance():
    e = _refused([{"name": "prestress"}, {"name": "prestress"}])
    assert e.entry == "effects[1].name" and "given twice" in str(e)
    e = _refused([{"name": "prestress"}, {"name": "prestress", "instance": "prestress-2"}])
    assert e.entry == "effects[1].instance" and "not repeatable" in str(e)
    # a model file's description check refuses the key before any work
    with pytest.raises(EffectError) as exc:
        load({**copy.deepcopy(FE), "effects": [{"name": "prestress", "instance": "prestress-2"}]})
    assert exc.value.entry == "effects[0].instance"


def test_a_repeated_effect_needs_a_label_and_labels_are_unique():
    e = _refused([{"name": "viscoelastic"}, {"name": "viscoelastic"}])
    assert e.entry == "effects[1].name" and 'instance = "viscoelastic-2"' in str(e)
    e = _refused([{"name": "viscoelastic", "instance": "slow"}, {"name": "viscoelastic", "instance": "slow"}])
    assert e.entry == "effects[1].instance" and "given twice" in str(e)
    e = _refused([{"name": "viscoelastic"}, {"name": "viscoelastic", "instance": "viscoelastic"}])
    assert e.entry == "effects[1].instance" and "given twice" in str(e)


def test_a_label_is_no_other_installed_effect_and_heads_parameter_names():
    e = _refused([{"name": "viscoelastic"}, {"name": "viscoelastic", "instance": "force-drift"}], "lumped")
    assert e.entry == "effects[1].instance" and "another installed effect" in str(e)
    e = _refused([{"name": "viscoelastic", "instance": "a.b"}])
    assert e.entry == "effects[0].instance"


def test_applied_effects_keep_the_label_and_the_effect():
    from skinkit.forward.effects import resolve

    applied = resolve(two_instances(), "lumped")
    assert [(a.name, a.effect, a.plugin.name) for a in applied] == [
        ("viscoelastic", "viscoelastic", "viscoelastic"),
        ("viscoelastic-2", "viscoelastic", "viscoelastic-2")]
    # the installed plugin object is not renamed
    assert registry.create("skinkit.effects", "viscoelastic").name == "viscoelastic"


# ----------------------------------------------------------------------------------------- FE
#: the smallest layered disc of the FE effect tests, with an isotropic elastic skin
FE = {
    "model": {"name": "small-elastic"},
    "geometry": {"kind": "disc", "diameter": "20 mm", "indenter_diameter": "4 mm", "n_inner": 2, "n_ring": 2},
    "layers": [
        {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "neo-hookean-ni",
         "parameters": {"mu": "15 kPa", "K": "500 kPa"}},
        {"name": "subdermal", "thickness": "3.5 mm", "elements": 2, "law": "neo-hookean-enu",
         "parameters": {"E": "10 kPa", "nu": 0.45}},
    ],
    "boundary": {"fixed": ["outer", "bottom"]},
    "indenter": {"mode": "force"},
    "drive": {"max_step": "1 s"},
    "solver": {"rtol": 1e-12},
}


def _push() -> Observations:
    """A 0.1 Hz normal push of 20 mN over 10 s, the tip's position predicted."""
    t = np.arange(0, 10.0001, 0.05)
    F = np.zeros((t.size, 3))
    F[:, 2] = -0.01 * (1 - np.cos(2 * np.pi * 0.1 * t))
    chans = {"tip_force": Channel("tip_force", t, F, noise=1.7e-3),
             "tip_position": Channel("tip_position", t, 0 * F, noise=1.7e-6)}
    return Observations({"push": ProtocolObservations(Protocol("push"), chans)}, None, "test")


def test_an_fe_model_takes_two_instances_as_a_two_term_qlv():
    """Two instances on an elastic skin: a ``qlv`` skin with two terms, each instance bound to
    its own; the second instance's g1 is differentiated analytically (central differences of
    whole solves with h = 1e-4 agree to 1e-5 of the largest)."""
    from skinkit.forward.effects import apply_all

    model = load({**copy.deepcopy(FE), "effects": two_instances()})
    try:
        ps = model.parameters()
        assert {"viscoelastic-2.g1", "viscoelastic-2.tau1"} <= set(ps.names)
        described = apply_all(model.base, model.effects)
        obs = _push()
        n = "viscoelastic-2.g1"
        pred = model.predict(ps, obs, sensitivities=[n])
        up, dn = (model.predict(ps.with_values({n: ps[n] + s * 1e-4}), obs) for s in (1, -1))
    finally:
        model.close()
    skin = described["layers"][0]
    assert skin["law"] == "qlv" and skin["options"]["terms"] == 2
    assert skin["options"]["elastic"] == "neo-hookean-ni"
    assert {k: skin["parameters"][k] for k in ("g1", "tau1", "g2", "tau2")} == {
        "g1": G[0], "tau1": TAU[0], "g2": G[1], "tau2": TAU[1]}
    assert {k: v for k, v in described["bindings"].items() if k.startswith("viscoelastic")} == {
        "viscoelastic.g1": "skin.g1", "viscoelastic.tau1": "skin.tau1",
        "viscoelastic-2.g1": "skin.g2", "viscoelastic-2.tau1": "skin.tau2"}
    assert pred.methods[n] == "analytic"
    x = pred.protocols["push"]["tip_position"]
    fd = (up.protocols["push"]["tip_position"].values - dn.protocols["push"]["tip_position"].values) / 2e-4
    size = np.nanmax(np.abs(fd))
    assert size > 0 and np.nanmax(np.abs(x.d[n] - fd)) <= 1e-5 * size


# ---------------------------------------------------------------------------- the score step
def test_repeat_candidates_and_effect_tables():
    from skinkit.gap.score import effect_of, effect_table, repeat_candidates

    tables = [{"name": "viscoelastic"}, {"name": "force-offset"}]
    assert repeat_candidates(tables) == [("viscoelastic-2", "viscoelastic")]
    assert repeat_candidates(two_instances()) == [("viscoelastic-3", "viscoelastic")]
    # the model's own labels are not reused
    own = [{"name": "viscoelastic"}, {"name": "viscoelastic", "instance": "viscoelastic-3"}]
    assert repeat_candidates(own) == [("viscoelastic-4", "viscoelastic")]
    assert effect_of("viscoelastic-2") == "viscoelastic" and effect_of("force-drift") == "force-drift"
    assert effect_table("viscoelastic-2", {"viscoelastic-2.g1": 0.2, "viscoelastic.g1": 0.3}) == {
        "name": "viscoelastic", "instance": "viscoelastic-2", "g1": 0.2}
    assert effect_table("force-drift") == {"name": "force-drift"}
    assert effect_table("slow", {"slow.tau1": 20.0}, effect="viscoelastic") == {
        "name": "viscoelastic", "instance": "slow", "tau1": 20.0}


@pytest.fixture(scope="module")
def two_scales() -> dict[str, Any]:
    """A session whose truth relaxes on two time scales (closed form plus white noise), and the
    model with one viscoelastic instance calibrated on it (k, g1, tau1 free)."""
    from skinkit.inverse import fit

    t, _, kinks = ramp_hold()
    rng = np.random.default_rng(3)
    truth = qlv_closed_form(t, kinks, K, G, TAU) + NOISE * rng.standard_normal(t.size)
    obs = session([truth])
    spec = {**copy.deepcopy(LUMPED), "effects": [{"name": "viscoelastic", "g1": 0.3, "tau1": 2.0}]}
    theta = ["lumped.k", "viscoelastic.g1", "viscoelastic.tau1"]
    r = fit(load(spec), obs, theta)
    return {"spec": spec, "obs": obs, "theta": theta, "result": r}


def test_a_second_instance_is_the_most_significant_candidate(two_scales):
    """The one-term model leaves the second time scale in the residual: among every lumped
    effect, the score test of viscoelastic-2 (g1 tested, tau1 held at its null) ranks first
    (before force-drift, which would otherwise take the slow relaxation for a drift) and is
    significant after the correction."""
    from skinkit.forward.visibility import applicable_effects
    from skinkit.gap.score import collect, corrected, repeat_candidates, score_all

    spec, obs, theta = two_scales["spec"], two_scales["obs"], two_scales["theta"]
    values = two_scales["result"].parameters.values()
    (label, effect), = repeat_candidates(spec["effects"])
    assert (label, effect) == ("viscoelastic-2", "viscoelastic")
    others = [e for e in applicable_effects("lumped") if e != "viscoelastic"]
    sens = collect(spec, obs, values, theta, [label, *others], load=load)
    assert label in sens.columns and label not in sens.skipped
    assert sens.columns[label].names == ["viscoelastic-2.g1"]
    assert set(sens.columns[label].held) == {"viscoelastic-2.tau1"}
    tests = score_all(sens)
    assert tests[0].effect == label and "force-drift" in [t.effect for t in tests[1:]]
    assert corrected(tests, 0.05)[label]
    assert tests[0].step["viscoelastic-2.g1"] > 0


def test_refitting_with_the_instance_recovers_both_time_scales(two_scales):
    """Refitted with viscoelastic-2 free, the two relaxation times are the truth's (either
    instance may take either term) within their 95 % intervals, and χ² drops to the noise."""
    from skinkit.gap.score import effect_table, with_effects
    from skinkit.inverse import fit

    spec, obs, theta = two_scales["spec"], two_scales["obs"], two_scales["theta"]
    r0 = two_scales["result"]
    model = load(with_effects(spec, [effect_table("viscoelastic-2", {"viscoelastic-2.g1": 0.05})]))
    free = theta + ["viscoelastic-2.g1", "viscoelastic-2.tau1"]
    r = fit(model, obs, free, start={**{n: r0.parameters[n] for n in theta}, "viscoelastic-2.tau1": 10.0})
    taus = sorted(("viscoelastic.tau1", "viscoelastic-2.tau1"), key=lambda n: r.parameters[n])
    for n, true in zip(taus, TAU, strict=True):
        assert abs(r.parameters[n] - true) <= 1.96 * r.se[n], (n, r.parameters[n], r.se[n])
    assert r.chi2_per_dof < 1.2 < r0.chi2_per_dof


def test_diagnose_names_the_second_instance(two_scales):
    """The diagnosis names viscoelastic-2 for the second time scale, not force-drift."""
    from skinkit.gap.diagnose import diagnose

    report = diagnose(two_scales["spec"], two_scales["obs"], free=two_scales["theta"], max_effects=1,
                      workers=1, error_estimate=False)
    assert report.named == ["viscoelastic-2"]
