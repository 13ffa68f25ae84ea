"""Every effect plugin through the FE forward model: exact at its null value, differentiable
at its null and at its typical magnitude, refused where it does not fit."""

from __future__ import annotations

import copy
import zlib

import _directional
import numpy as np
import pytest

from skinkit import registry
from skinkit.errors import EffectError
from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

pytestmark = pytest.mark.needs_plugins

#: a small layered disc with an isotropic elastic skin (so that every FE effect applies); one
#: quadratic element per layer: the checks compare the discrete model with itself (its null,
#: its own differences), which needs no resolution of the fields
BASE = {
    "model": {"name": "small-elastic"},
    "geometry": {"kind": "disc", "diameter": "20 mm", "indenter_diameter": "4 mm", "n_inner": 2, "n_ring": 2},
    "layers": [
        {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "neo-hookean-ni",
         "parameters": {"mu": "15 kPa", "K": "500 kPa"}},
        {"name": "subdermal", "thickness": "3.5 mm", "elements": 1, "law": "neo-hookean-enu",
         "parameters": {"E": "10 kPa", "nu": 0.45}},
    ],
    "boundary": {"fixed": ["outer", "bottom"]},
    "indenter": {"mode": "force"},
    # five steps over the push, ten with the points' frames: the derivative checks compare
    # solves of the same steps, which need not resolve the sinusoid finely
    "drive": {"max_step": "2 s"},
    "solver": {"rtol": 1e-12},
}
REF = np.array([[r * np.cos(a), r * np.sin(a), 0.0] for r in (3e-3, 5e-3) for a in np.linspace(0, 6, 4)])


def fe_effects() -> list[str]:
    return [n for n in registry.names("skinkit.effects")
            if "fe" in registry.create("skinkit.effects", n).kinds]


def session() -> Observations:
    """An oblique 0.1 Hz push (normal and in-plane at once: every effect has a channel to move)."""
    T = np.arange(0, 10.0001, 0.02)
    s = 0.5 * (1 - np.cos(2 * np.pi * 0.1 * T))
    F = 0.02 * s[:, None] * np.array([0.4, 0.2, -1.0])
    tf = np.arange(0, 10.0001, 1.0)
    chans = {"tip_force": Channel("tip_force", T, F, noise=1.7e-3),
             "tip_position": Channel("tip_position", T, 0 * F, noise=1.7e-6),
             "points": Channel("points", tf, np.repeat(REF[:, None], tf.size, 1), noise=4e-6, reference=REF)}
    return Observations({"oblique": ProtocolObservations(Protocol("oblique"), chans)}, None, "test")


@pytest.fixture(scope="module")
def reference():
    from skinkit.forward import load
    m = load(copy.deepcopy(BASE), workers=1)
    return m.predict(m.parameters(), session())


def _with(effect: str, **values) -> dict:
    spec = copy.deepcopy(BASE)
    spec["effects"] = [{"name": effect, **values}]
    return spec


@pytest.fixture(scope="module")
def solved():
    """``(effect, where) -> (model, parameter names, prediction with their sensitivities)``, each
    solved once: the null value's serves both the null-value test and the derivative check."""
    from skinkit.forward import load
    cache = {}

    def get(effect: str, where: str):
        if (effect, where) not in cache:
            plugin = registry.create("skinkit.effects", effect)
            values = {} if where == "null" else {p.name: p.value for p in plugin.parameters()}
            m = load(_with(effect, **values), workers=1)
            names = [f"{effect}.{p.name}" for p in plugin.parameters()]
            cache[effect, where] = (m, names, m.predict(m.parameters(), session(), sensitivities=names))
        return cache[effect, where]
    return get


def _per_effect() -> list:
    """The FE effects, each effect's tests on one worker (they share its null-value solve)."""
    return [pytest.param(e, marks=pytest.mark.xdist_group(f"effect-{e}")) for e in fe_effects()]


@pytest.mark.parametrize("effect", _per_effect())
def test_null_value_is_the_model_without_the_effect(effect, reference, solved):
    """At its null value an effect changes no prediction by more than 1e-12 of its size (the
    prediction with sensitivities: they are found after each step has converged, so the values
    are the bits of the plain prediction)."""
    _, _, pred = solved(effect, "null")
    for (_, c, x), (_, _, y) in zip(pred.items(), reference.items(), strict=True):
        scale = np.max(np.abs(y.values))
        assert np.max(np.abs(x.values - y.values)) <= 1e-12 * scale, (effect, c)


@pytest.mark.parametrize("effect", _per_effect())
@pytest.mark.parametrize("where", ["null", "typical"])
def test_effect_sensitivities_match_central_differences(effect, where, solved):
    """Analytic (or the model's own differences) against differences of whole solves along a
    random direction of the effect's parameters (:mod:`_directional`), with h = 1e-6 of each
    parameter's scale (its value, or 1 % of its range at 0) times its component: central inside
    the bounds, the second-order one-sided formula when a parameter is at a bound.

    Tolerance 2e-5 of the channel's largest directional derivative, as in test_fe_forward:
    the truncation error ~(step)² ≤ 1e-8 relative, the solver error ~rtol / h = 1e-6 relative.
    Against the model's own differences (step 1e-5) 1e-3. A direction that moves a channel by
    less than 1e-7 of its size per unit (every parameter over half its scale or more) is
    compared in absolute terms at that level (fibres' k2 when hardly any fibre is stretched)."""
    m, names, pred = solved(effect, where)
    scale = {}
    for nm in names:
        p = m.parameters().param(nm)
        scale[nm] = abs(p.value) if p.value != 0 else 0.01 * (p.upper - p.lower)
    _directional.check(m, session(), names, scale, seed=zlib.crc32(f"{effect}/{where}".encode()),
                       tol=2e-5, tol_for=lambda method: 1e-3 if method == "central-difference" else 0.0,
                       floor=1e-7, pred=pred)
    for nm in names:   # no effect parameter is differentiated by whole solves
        geometry = nm.partition(".")[2] in registry.create("skinkit.effects", effect).geometry
        assert pred.methods[nm] == ("analytic (shape)" if geometry else "analytic"), nm


def test_effect_that_does_not_fit_is_refused():
    from skinkit.forward import load
    spec = _with("fibres")
    spec["layers"][0]["law"] = "mooney-rivlin"
    spec["layers"][0]["parameters"] = {"c1": "5 kPa", "c2": "1 kPa", "K": "500 kPa"}
    with pytest.raises(EffectError, match="fibres"):
        load(spec, workers=1)


def test_unknown_effect_and_out_of_range_value_are_named():
    from skinkit.forward import load
    with pytest.raises(EffectError, match=r"effects\[0\].name.*unknown effect 'scarring'"):
        load(_with("scarring"), workers=1)
    with pytest.raises(EffectError, match=r"effects\[0\].l1.*outside the admissible range"):
        load(_with("prestress", l1=3.0), workers=1)


def test_fe_only_effect_on_a_lumped_model_is_refused():
    from skinkit.forward.effects import resolve
    with pytest.raises(EffectError, match="prestress.*not to a 'lumped' model"):
        resolve([{"name": "prestress"}], "lumped")
