"""Effects that are smooth factors φ on a layer's elastic response (``[[fields]]``, see
``docs/guide/effects.md``): ``layer-slip``, ``fascia``, ``inclusion`` and ``preconditioning``.

Each writes one field named after the effect, so the field's parameters ``"<effect>.<key>"``
are the effect's own (no binding needed) and the forward model differentiates them
analytically. At ratio = 1 (softening = 0) φ = 1 exactly: the model without the effect.
"""

from __future__ import annotations

from typing import Any

from skinkit.plugin.effects import BaseEffect, Declared, declare


def _element_half(effect: BaseEffect, layer: dict[str, Any]) -> float:
    """Half the thickness of one element layer of ``layer`` [m] (``elements`` defaults to 2)."""
    n = int(layer.get("elements", 2))
    if n < 1:
        raise effect.fail(f"layer {layer['name']!r} has {n} elements")
    return effect.thickness(layer) / n / 2.0


class LayerSlip(BaseEffect):
    """A compliant interface between the skin and the tissue below: a ``band`` field of stiffness
    ``ratio`` [1] (null 1; < 1 is softer) on the second layer, one element row thick just below
    the interface: ``half_width`` = half that layer's element thickness, ``depth`` = skin thickness
    + half_width. Needs two layers."""

    name = "layer-slip"
    kinds = ("fe",)
    touches = {"fe": frozenset({"fields"})}

    def _declared(self) -> list[Declared]:
        return [declare("ratio", 0.2, 1.0, "1", 0.01, 1.0)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        skin, below = self.layers(model, at_least=2)[:2]
        hw = _element_half(self, below)
        self.add_field(model, {"kind": "band", "layers": [below["name"]], "depth": self.thickness(skin) + hw,
                               "half_width": hw, "ratio": v["ratio"]})


class Fascia(BaseEffect):
    """A thin stiff layer at depth: a ``band`` field of stiffness ``ratio`` [1] (null 1) centred
    ``depth`` [m] below the top surface, on the last layer, ``half_width`` = half that layer's
    element thickness. Needs two layers, and ``depth`` within the last layer (the typical 4 mm is
    80 % of the 5 mm in vivo models)."""

    name = "fascia"
    kinds = ("fe",)
    touches = {"fe": frozenset({"fields"})}

    def _declared(self) -> list[Declared]:
        return [declare("ratio", 10.0, 1.0, "1", 1.0, 1000.0),
                declare("depth", 4.0, 4.0, "mm", 0.1, 50.0)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        layers = self.layers(model, at_least=2)
        last = layers[-1]
        total = sum(self.thickness(L) for L in layers)
        top = total - self.thickness(last)
        if not top <= v["depth"] <= total:
            raise self.fail(f"depth {v['depth'] * 1e3:g} mm is not in the last layer {last['name']!r} "
                            f"({top * 1e3:g} to {total * 1e3:g} mm below the surface)")
        self.add_field(model, {"kind": "band", "layers": [last["name"]], "depth": v["depth"],
                               "half_width": _element_half(self, last), "ratio": v["ratio"]})


class Inclusion(BaseEffect):
    """A stiffer or softer region of the skin (a scar): an ``inclusion`` field on the skin layer,
    centre ``x``, ``y`` [m] in the skin plane, ``radius`` [m], stiffness ``ratio`` [1] (null 1),
    edge width the field's default (radius/4)."""

    name = "inclusion"
    kinds = ("fe",)
    touches = {"fe": frozenset({"fields"})}

    def _declared(self) -> list[Declared]:
        return [declare("ratio", 3.0, 1.0, "1", 0.05, 50.0),
                declare("x", 3.0, 0.0, "mm", -20.0, 20.0),
                declare("y", 3.0, 0.0, "mm", -20.0, 20.0),
                declare("radius", 2.0, 2.0, "mm", 0.2, 20.0)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        skin = self.layers(model)[0]
        self.add_field(model, {"kind": "inclusion", "layers": [skin["name"]], "x": v["x"], "y": v["y"],
                               "radius": v["radius"], "ratio": v["ratio"]})


class Preconditioning(BaseEffect):
    """Softening of the elastic response with the largest load seen so far: φ(t) = 1 − softening ·
    m(t)/m_ref (``docs/guide/effects.md``), ``softening`` [1] in [0, 0.9], null 0. Finite elements: a
    ``softening`` field on the skin layer. Lumped: ``[lumped.preconditioning] softening``, bound
    to ``lumped.softening``."""

    name = "preconditioning"
    kinds = ("fe", "lumped")
    touches = {"fe": frozenset({"fields"}), "lumped": frozenset({"bindings", "lumped"})}

    def _declared(self) -> list[Declared]:
        return [declare("softening", 0.2, 0.0, "1", 0.0, 0.9)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        skin = self.layers(model)[0]
        self.add_field(model, {"kind": "softening", "layers": [skin["name"]], "softening": v["softening"]})

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        lt = self.lumped(model)
        if lt.get("preconditioning"):
            raise self.fail("the lumped model already has a [lumped.preconditioning] table")
        lt["preconditioning"] = {"softening": v["softening"]}
        self.bind(model, "softening", "lumped.softening")


__all__ = ["Fascia", "Inclusion", "LayerSlip", "Preconditioning"]
