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
    stiffness ``ratio`` [1] (null 1), centre ``x``, ``y`` [m] in the skin plane, a disc (form
    ``disc``, the default) or an ellipse (form ``ellipse``); ``docs/guide/effects.md``.

    The edge width is the field's default. The form is chosen in the ``[[effects]]`` table
    (``form = "ellipse"``):

    * ``"disc"`` (the default): ``radius`` [m]; edge width radius/4;
    * ``"ellipse"``: semi-axes ``a``, ``b`` [m], the ``a`` axis at ``angle`` [rad] from x (in
      [-90, 90] deg: an ellipse turned by 180 deg is itself); edge width a quarter of a smooth
      minimum of a and b (:func:`skinkit.fem.fields.smooth_min`). A scar is usually elongated
      (a healed incision): the ellipse's two extra parameters carry its length and direction.
    """

    name = "inclusion"
    kinds = ("fe",)
    touches = {"fe": frozenset({"fields"})}
    forms = ("disc", "ellipse")
    # the diagnosis scans centres and radii over the tracked area (with the disc, the default form)
    region = ("x", "y", "radius")
    # ... and refits the best region found as an ellipse (a scar is rarely round)
    region_ellipse = ("ellipse", ("x", "y", "a", "b", "angle"))

    def _declared(self) -> list[Declared]:
        out = [declare("ratio", 3.0, 1.0, "1", 0.05, 50.0),
               declare("x", 3.0, 0.0, "mm", -20.0, 20.0),
               declare("y", 3.0, 0.0, "mm", -20.0, 20.0)]
        if self.chosen_form() == "disc":
            return out + [declare("radius", 2.0, 2.0, "mm", 0.2, 20.0)]
        return out + [declare("a", 4.0, 2.0, "mm", 0.2, 20.0),
                      declare("b", 2.0, 2.0, "mm", 0.2, 20.0),
                      declare("angle", 30.0, 0.0, "deg", -90.0, 90.0)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        skin = self.layers(model)[0]
        shape = ("radius",) if self.chosen_form() == "disc" else ("a", "b", "angle")
        self.add_field(model, {"kind": "inclusion", "layers": [skin["name"]], "x": v["x"], "y": v["y"],
                               **{k: v[k] for k in shape}, "ratio": v["ratio"]})


class Preconditioning(BaseEffect):
    """Softening of the elastic response that develops cycle after cycle and levels off (form
    ``cycles``, the default: φ(t) = 1 − softening (1 − exp(−A(t)/cycles)), A the loading strokes
    so far) or follows the largest load so far (form ``largest-load``: φ(t) = 1 − softening ·
    m(t)/m_ref); ``docs/guide/effects.md``.

    Soft tissue loaded repeatedly to the same stretch carries less force on each cycle, the fall
    slowing until the response repeats (Fung's "preconditioning"; in mouse skin Muñoz et al.
    2008, "An experimental study of the mouse skin behaviour: damage and inelastic aspects",
    J. Biomech. 41; cyclic softening of soft tissue, Peña 2011, "Prediction of the softening and
    damage effects with permanent set in fibrous biological materials", J. Mech. Phys. Solids
    59). The form is chosen in the ``[[effects]]`` table (``form = "largest-load"``):

    * ``"cycles"`` (the default): φ(t) = 1 − softening · (1 − exp(−A(t)/cycles)), A(t) the
      loading strokes so far: the sum of the increases of |drive| up to t over the session's
      largest |drive| (protocols in session order; one ramp to full amplitude adds 1). The peak
      of cycle k to the same amplitude is softened by 1 − softening (1 − e^(−k/cycles)): it
      falls and levels off at 1 − softening. ``softening`` [1] in [0, 0.9] (null 0),
      ``cycles`` [1] in [0.1, 50] (null and typical 1): the strokes over which the softening
      develops (63 % of it after ``cycles`` strokes). At softening = 0, φ = 1 whatever ``cycles``.
    * ``"largest-load"`` (Mullins-type; Mullins 1969, Ogden & Roxburgh 1999, "A pseudo-elastic
      model for the Mullins effect in filled rubber", Proc. R. Soc. A 455): φ(t) = 1 − softening
      · m(t)/m_ref, m the largest |drive| so far, m_ref the session's largest; ``softening``
      only. Every cycle reaching the same stretch then has the same peak.

    Neither form covers recovery during rest (the softening is permanent over the session),
    direction-dependent softening (φ is isotropic: stretch along one axis softens all) nor the
    residual strain that accompanies preconditioning (the unloaded length is unchanged).

    Finite elements: a ``softening`` field on the skin layer (with ``cycles`` in the cycles
    form). Lumped: a ``[lumped.preconditioning]`` table (``form``, ``softening``, ``cycles``),
    the parameters bound to ``lumped.softening`` and ``lumped.cycles``.
    """

    name = "preconditioning"
    kinds = ("fe", "lumped")
    touches = {"fe": frozenset({"fields"}), "lumped": frozenset({"bindings", "lumped"})}
    forms = ("cycles", "largest-load")

    def _declared(self) -> list[Declared]:
        out = [declare("softening", 0.2, 0.0, "1", 0.0, 0.9)]
        if self.chosen_form() == "cycles":
            out.append(declare("cycles", 1.0, 1.0, "1", 0.1, 50.0))
        return out

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        skin = self.layers(model)[0]
        self.add_field(model, {"kind": "softening", "layers": [skin["name"]], **v})

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        lt = self.lumped(model)
        if lt.get("preconditioning"):
            raise self.fail("the lumped model already has a [lumped.preconditioning] table")
        lt["preconditioning"] = {"form": self.chosen_form(), **v}
        for local in v:
            self.bind(model, local, f"lumped.{local}")


__all__ = ["Fascia", "Inclusion", "LayerSlip", "Preconditioning"]
