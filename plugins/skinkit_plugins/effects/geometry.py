"""Effects on the geometry and the support: ``thickness`` and ``support-compliance``.

Both are differentiated analytically by the FE forward model: ``thickness.delta`` only moves
the mesh's nodes (declared in ``geometry``: the shape derivative), ``support-compliance`` is
bound to the engine's ``boundary.compliance`` (``docs/guide/effects.md``).
"""

from __future__ import annotations

from typing import Any

from skinkit.plugin.effects import BaseEffect, Declared, declare


class Thickness(BaseEffect):
    """The skin is ``delta`` [m] thicker than the model's (null 0; negative: thinner), the tissue
    below as much thinner, so the total thickness is unchanged. Writes both layers' ``thickness``
    as numbers in metres; refused with fewer than two layers or when a layer would vanish.

    Fields written by earlier effects (a ``layer-slip`` band) keep their depth: apply
    ``thickness`` first."""

    name = "thickness"
    kinds = ("fe",)
    touches = {"fe": frozenset({"layers"})}
    once = False  # it only moves an interface: nothing to recognise it by
    # moving an interface moves nodes and nothing else: differentiated by the shape derivative
    geometry = frozenset({"delta"})

    def _declared(self) -> list[Declared]:
        return [declare("delta", 0.3, 0.0, "mm", -0.8, 1.5)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        skin, below = self.layers(model, at_least=2)[:2]
        t1 = self.thickness(skin) + v["delta"]
        t2 = self.thickness(below) - v["delta"]
        for L, t in ((skin, t1), (below, t2)):
            if not t > 0:
                raise self.fail(f"delta = {v['delta'] * 1e3:g} mm leaves layer {L['name']!r} "
                                f"{t * 1e3:g} mm thick")
        skin["thickness"] = t1
        below["thickness"] = t2


class SupportCompliance(BaseEffect):
    """The support ring is elastic, not fixed: the fixed rim sets (every set of
    ``[boundary] fixed`` but ``bottom``; for a disc without ``fixed``, ``outer``) are held by a
    distributed spring instead, ``[boundary] compliance = {sets = [...], value = compliance}``.

    ``compliance`` [m/Pa] is the rim's displacement per unit traction (traction = −u/compliance on
    every face of the sets; a nodal spring is its face area over the compliance), so it does not
    depend on the mesh; 0 is the fixed support exactly. The typical 1 mm/kPa is about the
    compliance R/E of soft tissue (E = 10–20 kPa) over the hole's radius R = 20 mm, i.e. a rim
    that moves as much as the tissue around it would. Refused when the model has no fixed rim or
    already has a ``compliance`` table. Binding ``support-compliance.compliance`` ->
    ``boundary.compliance`` (differentiated by the engine, also at its null)."""

    name = "support-compliance"
    kinds = ("fe",)
    touches = {"fe": frozenset({"boundary", "bindings"})}

    def _declared(self) -> list[Declared]:
        return [declare("compliance", 1.0, 0.0, "mm/kPa", 0.0, 20.0)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        self.layers(model)
        bd = dict(model.get("boundary", {}) or {})
        if bd.get("compliance"):
            raise self.fail("the model's boundary already has a compliance table")
        geometry = model.get("geometry", {}) or {}
        default = ["outer", "bottom"] if geometry.get("kind", "disc") == "disc" else ["bottom"]
        fixed = bd.get("fixed", default)
        fixed = [fixed] if isinstance(fixed, str) else list(fixed)
        rim = [str(s) for s in fixed if s != "bottom"]
        if not rim:
            raise self.fail(f"the model has no fixed rim to make elastic (boundary.fixed = {fixed})")
        bd["compliance"] = {"sets": rim, "value": v["compliance"]}
        model["boundary"] = bd
        self.bind(model, "compliance", "boundary.compliance")


__all__ = ["SupportCompliance", "Thickness"]
