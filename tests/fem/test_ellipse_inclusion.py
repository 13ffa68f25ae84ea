"""The elliptical form of the ``inclusion`` field and of the ``inclusion`` effect."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from skinkit.fem.errors import ModelError
from skinkit.fem.fields import Field, ellipse_distance, smooth_min

#: quadrature-like points spread over a 12 mm square around the inclusion (none at its centre)
_RNG = np.random.default_rng(3)
XQ = np.concatenate([_RNG.uniform(-6e-3, 6e-3, (40, 8, 2)), np.zeros((40, 8, 1))], axis=2)
DEPTH = np.zeros(XQ.shape[:2])
ELLIPSE = {"x": 0.7e-3, "y": -0.4e-3, "a": 3e-3, "b": 1.2e-3, "angle": 0.6, "ratio": 4.0}


def _phi(params: dict[str, float]) -> np.ndarray:
    return Field("inc", "inclusion", ["skin"], dict(params)).value(XQ, DEPTH, 0.0)


@pytest.mark.parametrize("width", [None, 0.3e-3])
@pytest.mark.parametrize("angle", [0.0, 0.9, -2.1])
def test_an_ellipse_with_equal_axes_is_the_disc(angle, width):
    """a = b = radius: the distance is r − radius whatever the angle, and the default edge width
    (a quarter of the smooth minimum of a and b) is radius/4: the same φ to rounding."""
    disc = {"x": 1e-3, "y": 0.5e-3, "radius": 2e-3, "ratio": 3.0}
    ell = {"x": 1e-3, "y": 0.5e-3, "a": 2e-3, "b": 2e-3, "angle": angle, "ratio": 3.0}
    if width is not None:
        disc["width"] = ell["width"] = width
    assert np.allclose(_phi(ell), _phi(disc), rtol=0, atol=1e-13)


def test_a_quarter_turn_swaps_the_axes():
    """Turning the a axis by π/2 puts it where the b axis was: (a, b, θ + π/2) is (b, a, θ)."""
    turned = dict(ELLIPSE, angle=ELLIPSE["angle"] + math.pi / 2)
    swapped = dict(ELLIPSE, a=ELLIPSE["b"], b=ELLIPSE["a"])
    assert np.allclose(_phi(turned), _phi(swapped), rtol=0, atol=1e-13)


def test_distance_is_exact_on_the_axes_and_the_outline_is_the_half_level():
    """Along each axis the distance is |u| − a (|v| − b); points on the outline have w = ½, so
    φ = (1 + ratio)/2 there."""
    a, b, th = 3e-3, 1e-3, 0.4
    t = np.array([0.5e-3, 2e-3, 5e-3])
    ua, ub = np.array([math.cos(th), math.sin(th)]), np.array([-math.sin(th), math.cos(th)])
    assert np.allclose(ellipse_distance(t * ua[0], t * ua[1], a, b, th), t - a, atol=1e-15)
    assert np.allclose(ellipse_distance(t * ub[0], t * ub[1], a, b, th), t - b, atol=1e-15)
    s = np.linspace(0, 2 * math.pi, 17)
    outline = np.outer(a * np.cos(s), ua) + np.outer(b * np.sin(s), ub)
    assert np.allclose(ellipse_distance(outline[:, 0], outline[:, 1], a, b, th), 0.0, atol=1e-15)


def test_smooth_minimum_lies_between_the_minimum_and_its_bound():
    """The default edge width scales with the smaller semi-axis: between min(a, b) and 2^(1/4)
    times it, equal to it for a circle."""
    a = np.array([1.0, 2.0, 5.0, 50.0]) * 1e-3
    b = np.full(4, 1e-3)
    m = smooth_min(a, b)
    assert m[0] == pytest.approx(1e-3, rel=1e-14)
    assert np.all(m >= b * (1 - 1e-14)) and np.all(m <= 2 ** 0.25 * b)


@pytest.mark.parametrize("key", ["x", "y", "a", "b", "angle", "ratio", "width"])
def test_field_derivatives_match_central_differences(key):
    """∂φ/∂p by the complex step against a central difference with a step of 1e-5 of the
    parameter's size: truncation error ~(1e-5)² φ''' p², below 1e-8 of the largest derivative
    at these sizes (the steepest feature, the edge of width 0.25 mm, is 25 steps wide)."""
    params = dict(ELLIPSE, width=0.25e-3)
    f = Field("inc", "inclusion", ["skin"], params)
    d = f.derivative(key, XQ, DEPTH, 0.0)
    h = 1e-5 * max(abs(params[key]), 1e-3)
    up = _phi(dict(params, **{key: params[key] + h}))
    dn = _phi(dict(params, **{key: params[key] - h}))
    fd = (up - dn) / (2 * h)
    assert np.max(np.abs(d)) > 0
    assert np.max(np.abs(d - fd)) <= 1e-6 * np.max(np.abs(d))


@pytest.mark.parametrize("params, problem", [
    ({"x": 0, "y": 0, "ratio": 2.0}, "either radius"),
    ({"x": 0, "y": 0, "ratio": 2.0, "radius": 1e-3, "a": 1e-3, "b": 1e-3}, "either radius"),
    ({"x": 0, "y": 0, "ratio": 2.0, "a": 1e-3}, "needs \\['b'\\]"),
    ({"x": 0, "y": 0, "ratio": 2.0, "a": 1e-3, "b": -1e-3}, "fields\\[inc\\].b: must be positive"),
])
def test_bad_inclusion_shapes_are_named(params, problem):
    with pytest.raises(ModelError, match=problem):
        Field("inc", "inclusion", ["skin"], params)


# -- through the forward model ------------------------------------------------------------------
#: a tiny layered disc, an elliptical scar off the indenter, the indenter pushed and pulled sideways
SPEC = {
    "model": {"name": "tiny-ellipse"},
    "geometry": {"kind": "disc", "diameter": "16 mm", "indenter_diameter": "4 mm", "n_inner": 1, "n_ring": 2},
    "layers": [
        {"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "neo-hookean-enu",
         "parameters": {"E": "30 kPa", "nu": 0.45}},
        {"name": "subdermal", "thickness": "3 mm", "elements": 1, "law": "neo-hookean-enu",
         "parameters": {"E": "5 kPa", "nu": 0.45}},
    ],
    "effects": [{"name": "inclusion", "form": "ellipse", "ratio": 4.0, "x": "3.5 mm", "y": "1 mm",
                 "a": "2.5 mm", "b": "1.2 mm", "angle": "35 deg"}],
    "indenter": {"mode": "displacement"},
    "drive": {"max_step": "1 s"},
    "solver": {"rtol": 1e-12},
}
POINTS = np.array([[5e-3, 0, 0], [3e-3, 3e-3, 0], [-4e-3, 1e-3, 0], [1e-3, -5e-3, 0]])


def _session():
    from skinkit.schemas import Channel, Observations, Protocol, ProtocolObservations

    T = np.arange(0, 3.0001, 0.01)
    s = 0.5 * (1 - np.cos(2 * np.pi * T / 4))
    X = 0.4e-3 * s[:, None] * np.array([1.0, 0.3, -0.5])
    tf = np.arange(0, 3.0001, 1.0)
    chans = {"tip_force": Channel("tip_force", T, 0 * X, noise=1e-4),
             "tip_position": Channel("tip_position", T, X, noise=1e-6),
             "points": Channel("points", tf, np.repeat(POINTS[:, None], tf.size, 1), noise=5e-6,
                               reference=POINTS)}
    return Observations({"push": ProtocolObservations(Protocol("push"), chans)}, None, "test")


@pytest.mark.needs_plugins
def test_forward_sensitivities_of_the_ellipse_match_whole_solves():
    """Each of the six ellipse parameters: the forward model's analytic sensitivity (the field's
    complex-step ∂φ/∂p through the tangent) against a central difference of two whole solves.

    Tolerance: steps of 1e-5 of each parameter's size give a truncation error ~1e-10 relative;
    the solver's rtol 1e-12 over the step adds ~1e-7. 1e-5 of each channel's largest value
    leaves a margin of 100."""
    from skinkit.forward import load

    m = load(copy.deepcopy(SPEC), workers=1)
    obs = _session()
    pset = m.parameters()
    names = [f"inclusion.{k}" for k in ("ratio", "x", "y", "a", "b", "angle")]
    pred = m.predict(pset, obs, sensitivities=names)
    assert {pred.methods[n] for n in names} == {"analytic"}
    for n in names:
        p0 = pset.param(n).value
        h = 1e-5 * max(abs(p0), 1e-3)
        up = m.predict(pset.with_values({n: p0 + h}), obs)
        dn = m.predict(pset.with_values({n: p0 - h}), obs)
        for (_, c, x), (_, _, u), (_, _, d) in zip(pred.items(), up.items(), dn.items(), strict=True):
            fd = (u.values - d.values) / (2 * h)
            big = np.max(np.abs(fd)) + 1e-300
            assert np.max(np.abs(x.d[n] - fd)) <= 1e-5 * big + 1e-12 * np.max(np.abs(x.values)) / h, (n, c)


@pytest.mark.needs_plugins
def test_the_effect_keeps_the_disc_by_default_and_offers_the_ellipse():
    """No form: the disc's four parameters, as before; ``form = "ellipse"``: six, written into an
    inclusion field of the skin that the forward model reads (a = b at the null outline)."""
    from skinkit.forward.effects import apply_all, effect_parameters, resolve

    disc = resolve([{"name": "inclusion", "ratio": 2.0}], "fe")
    ell = resolve(copy.deepcopy(SPEC["effects"]), "fe")
    assert sorted(effect_parameters(disc).names) == [f"inclusion.{k}" for k in ("radius", "ratio", "x", "y")]
    assert sorted(effect_parameters(ell).names) == [f"inclusion.{k}"
                                                    for k in ("a", "angle", "b", "ratio", "x", "y")]
    (field,) = apply_all(SPEC, ell)["fields"]
    assert field["kind"] == "inclusion" and field["layers"] == ["skin"]
    assert field["a"] == pytest.approx(2.5e-3) and field["angle"] == pytest.approx(math.radians(35))
    Field("inclusion", "inclusion", ["skin"], {k: field[k] for k in ("x", "y", "a", "b", "angle", "ratio")})


@pytest.mark.needs_plugins
def test_an_ellipse_angle_out_of_bounds_is_refused():
    from skinkit.errors import SkinkitError
    from skinkit.forward import load

    spec = copy.deepcopy(SPEC)
    spec["effects"][0]["angle"] = "120 deg"
    with pytest.raises(SkinkitError, match="angle"):
        load(spec, workers=1)


def test_the_centre_itself_is_finite():
    """A quadrature point exactly at the centre (a symmetric mesh can put one there): its distance
    is minus the smooth minimum of the semi-axes (between them, as everywhere inside), so φ is the
    inclusion's less the edge's tail, and every derivative is finite."""
    params = dict(ELLIPSE, width=0.25e-3)
    at = np.array([[[params["x"], params["y"], 0.0]]])
    f = Field("inc", "inclusion", ["skin"], params)
    m = smooth_min(params["a"], params["b"])
    inside = 1 + (params["ratio"] - 1) * 0.5 * (1 + math.tanh(m / params["width"]))
    assert f.value(at, np.zeros((1, 1)), 0.0)[0, 0] == pytest.approx(inside, rel=1e-14)
    for k in params:
        assert np.isfinite(f.derivative(k, at, np.zeros((1, 1)), 0.0)).all(), k
