"""Smooth factors φ(X, t) on a layer's elastic response (``[[fields]]`` in a model file).

The elastic stress and tangent of every quadrature point of the field's layers are
multiplied by φ; inside a viscoelastic law the factor acts on the elastic response, so
relaxation acts on the softened or stiffened material. φ = 1 is the model without the
field, exactly. Several fields on one layer multiply. Every numeric parameter is
differentiable: φ is analytic in its parameters, so ∂φ/∂p comes from the complex step
(exact to rounding).

Kinds (see ``docs/guide/effects.md``):

* ``inclusion``, a disc (``radius``): φ = 1 + (ratio − 1) w, w = ½ [1 − tanh(s/δ)], s = r − radius,
  r the in-plane distance from (x, y), δ = ``width`` (default radius/4); or an ellipse (semi-axes
  ``a``, ``b``, the ``a`` axis at ``angle`` from x): the same w with s the ellipse's first-order
  distance (:func:`ellipse_distance`: r − radius when a = b = radius), δ = ``width`` (default
  :func:`smooth_min` (a, b)/4);
* ``band``: φ = 1 + (ratio − 1) w, w = ½ [tanh((d − depth + hw)/δ) − tanh((d − depth − hw)/δ)],
  d the depth below the top surface, hw = ``half_width``, δ = ``width`` (default hw/2);
* ``softening``: φ(t) = 1 − softening · level(t), level(t) in [0, 1] set by whoever drives the
  model (the largest load seen so far over the largest of the session); with a ``cycles``
  parameter φ(t) = 1 − softening (1 − exp(−strokes(t)/cycles)), strokes(t) ≥ 0 set likewise
  (the loading strokes so far: increases of the drive magnitude summed over the session, over
  its largest), so the softening develops cycle after cycle and levels off.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.fem.errors import ModelError

_CS = 1e-30
#: q of a point 1e-12 semi-axes from an ellipse's centre: below it the distance's √(q/h) tends
#: to the smooth minimum of the semi-axes instead of 0/0 (above it the term is below rounding)
_CENTRE = 1e-24

#: kind -> (required parameters, optional parameters); an inclusion also needs the keys of one
#: of its :data:`SHAPES`
KINDS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "inclusion": (("x", "y", "ratio"), ("radius", "a", "b", "angle", "width")),
    "band": (("depth", "half_width", "ratio"), ("width",)),
    "softening": (("softening",), ("cycles",)),
}
#: an inclusion's outline: shape -> (its required keys, its optional keys)
SHAPES: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "disc": (("radius",), ()),
    "ellipse": (("a", "b"), ("angle",)),
}
UNITS = {"x": "m", "y": "m", "radius": "m", "ratio": "1", "width": "m", "depth": "m",
         "half_width": "m", "softening": "1", "cycles": "1", "a": "m", "b": "m", "angle": "rad"}
#: exponent of the power mean that stands for the smaller semi-axis (:func:`smooth_min`)
SMOOTH_MIN_POWER = 4.0


def smooth_min(a: Any, b: Any) -> Any:
    """(2 / (a^−p + b^−p))^(1/p), p = :data:`SMOOTH_MIN_POWER` [m] of semi-axes ``a``, ``b`` [m]
    (scalars or arrays, real or complex): ``a`` when a = b, between min(a, b) and 2^(1/p) = 1.19
    times it otherwise, and analytic where min is not (a complex step through it is exact)."""
    p = SMOOTH_MIN_POWER
    return (2.0 / (a ** -p + b ** -p)) ** (1.0 / p)


def ellipse_distance(dx: Any, dy: Any, a: Any, b: Any, angle: Any) -> Any:
    """Signed first-order distance [m] of in-plane offsets ``dx``, ``dy`` [m] (any shape) from the
    centre to the outline of the ellipse of semi-axes ``a``, ``b`` [m], the ``a`` axis at ``angle``
    [rad] from x: negative inside.

    With u, v the offsets along the axes, q = (u/a)² + (v/b)² and ρ = √q the outline's level
    (ρ = 1 on it), the distance is (ρ − 1)/|∇ρ| = (ρ − 1) √(q/h), h = u²/a⁴ + v²/b⁴: the distance
    to the outline to first order near it, exact along both axes (|u| − a and |v| − b) and exactly
    r − a for a circle. √(q/h) lies between the semi-axes; at the centre, where it is 0/0, the tiny
    :data:`_CENTRE` added to q and (over m², m the :func:`smooth_min`) to h makes it m (a for a
    circle, exactly, everywhere). Analytic in every argument: a complex step through it is exact."""
    c, s = np.cos(angle), np.sin(angle)
    u = c * dx + s * dy
    v = -s * dx + c * dy
    q = (u / a) ** 2 + (v / b) ** 2
    h = u ** 2 / a ** 4 + v ** 2 / b ** 4
    m = smooth_min(a, b)
    return (np.sqrt(q) - 1.0) * np.sqrt((q + _CENTRE) / (h + _CENTRE / m ** 2))


def inclusion_shape(params: Mapping[str, Any]) -> str:
    """``"disc"`` or ``"ellipse"``: the :data:`SHAPES` entry whose keys ``params`` uses (one,
    complete, not mixed with the other's); a :class:`ModelError` naming what is wrong otherwise."""
    used = [k for k, (need, opt) in SHAPES.items() if any(n in params for n in need + opt)]
    if len(used) != 1:
        raise ModelError("inclusion", "needs either radius (a disc) or a, b and optionally angle (an "
                         f"ellipse), got {sorted(k for k in params if k in UNITS)}")
    missing = [k for k in SHAPES[used[0]][0] if k not in params]
    if missing:
        raise ModelError("inclusion", f"an {used[0]} needs {missing} as well")
    return used[0]


@dataclass
class Field:
    """One field: ``name`` (its parameters are ``"<name>.<key>"``), ``kind``, the ``layers``
    it acts on and its parameter values [SI]. ``level`` gives the softening level at time t
    [s], ``strokes`` the loading strokes so far (a softening field with ``cycles``)."""

    name: str
    kind: str
    layers: list[str]
    params: dict[str, float]
    level: Callable[[float], float] = field(default=lambda t: 0.0)
    strokes: Callable[[float], float] = field(default=lambda t: 0.0)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ModelError(f"fields[{self.name}].kind",
                             f"must be one of {sorted(KINDS)}, got {self.kind!r}")
        need, opt = KINDS[self.kind]
        missing = [k for k in need if k not in self.params]
        if missing:
            raise ModelError(f"fields[{self.name}]", f"missing parameter(s) {missing}")
        extra = sorted(set(self.params) - set(need) - set(opt))
        if extra:
            raise ModelError(f"fields[{self.name}]", f"unknown parameter(s) {extra} for kind {self.kind!r}")
        p = self.params
        if self.kind == "inclusion":
            try:
                inclusion_shape(p)
            except ModelError as exc:
                raise ModelError(f"fields[{self.name}]", exc.problem) from None
        if "ratio" in p and not p["ratio"] > 0:
            raise ModelError(f"fields[{self.name}].ratio", f"must be positive, got {p['ratio']}")
        for k in ("radius", "a", "b", "half_width", "width", "cycles"):
            if k in p and not p[k] > 0:
                raise ModelError(f"fields[{self.name}].{k}", f"must be positive, got {p[k]}")
        if self.kind == "softening" and not 0 <= p["softening"] < 1:
            raise ModelError(f"fields[{self.name}].softening", f"must be in [0, 1), got {p['softening']}")

    @property
    def parameter_names(self) -> list[str]:
        """Differentiable parameters, as ``"<field>.<key>"``."""
        return [f"{self.name}.{k}" for k in self.params]

    def _phi(self, p: Mapping[str, Any], Xq: np.ndarray, depth: np.ndarray, t: float):
        if self.kind == "softening" and "cycles" in p:
            a = float(self.strokes(t))
            return 1.0 - p["softening"] * (1.0 - np.exp(-a / p["cycles"])) + 0.0 * depth
        if self.kind == "softening":
            return 1.0 - p["softening"] * float(self.level(t)) + 0.0 * depth
        if self.kind == "inclusion" and "radius" in p:
            # sqrt of the squares, not hypot: complex-step safe (quadrature points never sit on r = 0)
            r = np.sqrt((Xq[..., 0] - p["x"]) ** 2 + (Xq[..., 1] - p["y"]) ** 2)
            d = p.get("width", p["radius"] / 4)
            w = 0.5 * (1 - np.tanh((r - p["radius"]) / d))
        elif self.kind == "inclusion":
            dist = ellipse_distance(Xq[..., 0] - p["x"], Xq[..., 1] - p["y"], p["a"], p["b"],
                                    p.get("angle", 0.0))
            d = p.get("width", smooth_min(p["a"], p["b"]) / 4)
            w = 0.5 * (1 - np.tanh(dist / d))
        else:
            hw = p["half_width"]
            d = p.get("width", hw / 2)
            w = 0.5 * (np.tanh((depth - p["depth"] + hw) / d) - np.tanh((depth - p["depth"] - hw) / d))
        return 1.0 + (p["ratio"] - 1.0) * w

    def value(self, Xq: np.ndarray, depth: np.ndarray, t: float) -> np.ndarray:
        """φ ``(n_el, n_q)`` at quadrature points ``Xq`` ``(n_el, n_q, 3)`` [m] of depth ``depth``."""
        return np.asarray(self._phi(self.params, Xq, depth, t), dtype=float)

    def complex_value(self, Xq: np.ndarray, depth: np.ndarray, t: float) -> np.ndarray:
        """φ ``(n_el, n_q)`` at complex ``Xq`` and ``depth`` (for a complex step in position or
        depth: φ is analytic in both)."""
        return np.asarray(self._phi(self.params, Xq, depth, t), dtype=complex)

    def derivative(self, key: str, Xq: np.ndarray, depth: np.ndarray, t: float) -> np.ndarray:
        """∂φ/∂``key`` ``(n_el, n_q)`` [1 per SI unit of the parameter] (complex step)."""
        if key not in self.params:
            raise ModelError(f"fields[{self.name}]", f"has no parameter {key!r}")
        p: dict[str, Any] = dict(self.params)
        p[key] = p[key] + 1j * _CS
        return np.imag(np.asarray(self._phi(p, Xq.astype(complex), depth.astype(complex), t))) / _CS


def read_fields(tables: Any, layer_names: list[str],
                quantity: Callable[[Any, str, str], float]) -> list[Field]:
    """``[[fields]]`` tables -> :class:`Field` list (errors name ``fields[i].<key>``)."""
    if tables is None:
        return []
    if not isinstance(tables, list):
        raise ModelError("fields", "must be an array of tables ([[fields]])")
    out = []
    names = set()
    for i, t in enumerate(tables):
        e = f"fields[{i}]"
        if not isinstance(t, Mapping):
            raise ModelError(e, "must be a table")
        name = str(t.get("name", ""))
        if not name or name in names:
            raise ModelError(f"{e}.name", f"needs a unique name, got {name!r}")
        names.add(name)
        kind = str(t.get("kind", ""))
        if kind not in KINDS:
            raise ModelError(f"{e}.kind", f"must be one of {sorted(KINDS)}, got {kind!r}")
        layers = t.get("layers", [])
        if isinstance(layers, str):
            layers = [layers]
        if not layers or any(n not in layer_names for n in layers):
            raise ModelError(f"{e}.layers", f"must name layers of the model {layer_names}, got {layers!r}")
        need, opt = KINDS[kind]
        unknown = sorted(set(t) - {"name", "kind", "layers"} - set(need) - set(opt))
        if unknown:
            raise ModelError(e, f"unknown key(s) {unknown} for a {kind!r} field; it takes {list(need + opt)}")
        params = {k: quantity(t[k], UNITS[k], f"{e}.{k}") for k in need + opt if k in t}
        try:
            out.append(Field(name, kind, list(layers), params))
        except ModelError as exc:
            raise ModelError(f"{e}", str(exc)) from None
    return out


__all__ = ["KINDS", "SHAPES", "SMOOTH_MIN_POWER", "Field", "ellipse_distance", "inclusion_shape",
           "read_fields", "smooth_min"]
