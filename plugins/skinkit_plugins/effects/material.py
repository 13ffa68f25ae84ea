"""Effects that edit the skin's constitutive description: ``viscoelastic`` (a Prony term),
``prestress`` (in-plane natural tension) and ``fibres`` (a GOH fibre family).

The skin is the first (top) ``[[layers]]`` table, whatever its name. Every parameter of these
effects is bound to a model parameter the forward model differentiates analytically
(``bindings``, ``docs/guide/effects.md``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from skinkit.plugin.effects import BaseEffect, Declared, declare, quantity


def _sum_g(terms: list[Any], entry: str) -> float:
    """Sum of existing Prony moduli [1]."""
    return sum(quantity(g, "1", entry) for g in terms)


class Viscoelastic(BaseEffect):
    """One more Prony term around the skin's elastic response: relative modulus ``g1`` [1] and
    relaxation time ``tau1`` [s]; null g1 = 0.

    Phenomenon: under a held stretch the force of skin falls over seconds to minutes and recovers
    after unloading (the collagen network and the interstitial fluid rearranging). Form: Fung's
    quasi-linear viscoelasticity, the elastic response convolved with a reduced relaxation
    function G(t) = g∞ + Σ gᵢ e^(−t/τᵢ) (Fung, Biomechanics, 1993, ch. 7; Puso & Weiss 1998 for
    its finite-strain Prony form). A spectrum of times is approached by repeating the effect (one
    term per instance, the diagnosis offering the next as "more of the same"). Not covered: a
    relaxing fraction that grows with stretch (non-separable, e.g. Schapery's or Pipkin-Rogers
    forms), a power-law (fractional) kernel other than through several terms, poroelastic flow
    whose time scales with the loaded size, and creep under force beyond what the same G gives.

    Finite elements: a skin whose law is ``qlv`` gets its next term (``terms`` + 1, parameters
    ``g<n>``, ``tau<n>``); any other law is wrapped, ``law = "qlv"``, ``options = {elastic =
    <law>, terms = 1, elastic_options = <its options>}``. Bindings: ``viscoelastic.g1`` ->
    ``<skin>.g<n>``, ``viscoelastic.tau1`` -> ``<skin>.tau<n>``. Lumped: a ``[[lumped.relaxation]]``
    term ``{g, tau}``, bound to ``lumped.g<n>``, ``lumped.tau<n>``. The moduli of all terms
    must sum below 1 (refused otherwise).

    Repeatable: each further instance (``instance = "viscoelastic-2"``) appends the next term
    the same way, its parameters ``viscoelastic-2.g1``, ``viscoelastic-2.tau1``; the sum check
    counts the terms of the earlier instances, which are in the description by then.
    """

    name = "viscoelastic"
    kinds = ("fe", "lumped")
    repeatable = True
    touches = {"fe": frozenset({"bindings", "layers"}), "lumped": frozenset({"bindings", "lumped"})}

    def _declared(self) -> list[Declared]:
        return [declare("g1", 0.3, 0.0, "1", 0.0, 0.9),
                declare("tau1", 2.0, 2.0, "s", 0.05, 200.0)]

    def _check_sum(self, existing: float, g: float) -> None:
        if existing + g >= 1.0:
            raise self.fail(f"the Prony moduli would sum to {existing + g:g} (existing {existing:g} "
                            f"+ g1 = {g:g}); they must sum below 1")

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        skin = self.layers(model)[0]
        law = skin.get("law")
        if not isinstance(law, str) or not law:
            raise self.fail(f"the skin layer {skin['name']!r} has no law")
        params = dict(skin.get("parameters", {}) or {})
        if law == "qlv":
            opts = dict(skin.get("options", {}) or {})
            n = int(opts.get("terms", 1)) + 1
            existing = _sum_g([params[f"g{i}"] for i in range(1, n) if f"g{i}" in params], self.entry)
            opts["terms"] = n
        else:
            n, existing = 1, 0.0
            opts = {"elastic": law, "terms": 1, "elastic_options": dict(skin.get("options", {}) or {})}
            skin["law"] = "qlv"
        self._check_sum(existing, v["g1"])
        params[f"g{n}"] = v["g1"]
        params[f"tau{n}"] = v["tau1"]
        skin["options"] = opts
        skin["parameters"] = params
        self.bind(model, "g1", f"{skin['name']}.g{n}")
        self.bind(model, "tau1", f"{skin['name']}.tau{n}")

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        lt = self.lumped(model)
        terms = [dict(t) for t in (lt.get("relaxation", []) or [])]
        self._check_sum(_sum_g([t.get("g", 0.0) for t in terms], self.entry), v["g1"])
        terms.append({"g": v["g1"], "tau": v["tau1"]})
        lt["relaxation"] = terms
        n = len(terms)
        self.bind(model, "g1", f"lumped.g{n}")
        self.bind(model, "tau1", f"lumped.tau{n}")


class Prestress(BaseEffect):
    """In-plane natural tension of the skin: stretches ``l1`` (along ``angle`` from x) and ``l2``
    [1] of the natural state, ``angle`` [rad]; null l1 = l2 = 1. Writes the skin's ``prestress =
    {stretch = [l1, l2], angle}``; bindings ``prestress.l1|l2|angle`` ->
    ``<skin>.prestretch.l1|l2|angle``. Refused when the skin already has a pre-stress."""

    name = "prestress"
    kinds = ("fe",)
    touches = {"fe": frozenset({"bindings", "layers"})}

    def _declared(self) -> list[Declared]:
        return [declare("l1", 1.10, 1.0, "1", 0.8, 1.4),
                declare("l2", 1.03, 1.0, "1", 0.8, 1.4),
                declare("angle", 20.0, 0.0, "deg", -90.0, 90.0)]

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        skin = self.layers(model)[0]
        if skin.get("prestress"):
            raise self.fail(f"the skin layer {skin['name']!r} already has a pre-stress")
        skin["prestress"] = {"stretch": [v["l1"], v["l2"]], "angle": v["angle"]}
        for local in ("l1", "l2", "angle"):
            self.bind(model, local, f"{skin['name']}.prestretch.{local}")


class Fibres(BaseEffect):
    """A GOH fibre family in an isotropic neo-Hookean skin: ``k1`` [Pa] (null 0), ``k2`` [1],
    direction ``gamma`` [rad] from x, dispersion ``kappa`` [1] in [0, 1/3].

    The skin's ``neo-hookean-ni`` law (plain or the ``elastic`` law of a ``qlv``) becomes ``goh``
    with ``c = mu``, ``k = K`` and options ``{families = 1, switch = "macaulay", volumetric = <the
    neo-Hookean's, default "quadratic">}``: GOH's ground matrix and volumetric energy are then the
    neo-Hookean's, and its fibre energy k1/(2 k2) [exp(k2 <E>²) − 1] vanishes at k1 = 0, so the
    null is the original model exactly. Bindings ``fibres.<p>`` -> ``<skin>.<p>``. Refused for
    any other skin law. Note that the model's ``<skin>.mu``, ``<skin>.K`` are then named
    ``<skin>.c``, ``<skin>.k``.
    """

    name = "fibres"
    kinds = ("fe",)
    touches = {"fe": frozenset({"bindings", "layers"})}

    def _declared(self) -> list[Declared]:
        return [declare("k1", 20.0, 0.0, "kPa", 0.0, 1000.0),
                declare("k2", 5.0, 5.0, "1", 0.01, 100.0),
                declare("gamma", 30.0, 30.0, "deg", -90.0, 90.0),
                declare("kappa", 0.2, 0.2, "1", 0.0, 1.0 / 3.0)]

    def _goh_options(self, opts: Mapping[str, Any] | None) -> dict[str, Any]:
        vol = (opts or {}).get("volumetric", "quadratic")
        return {"families": 1, "switch": "macaulay", "volumetric": vol}

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        skin = self.layers(model)[0]
        law = skin.get("law")
        opts = dict(skin.get("options", {}) or {})
        if law == "neo-hookean-ni":
            skin["law"] = "goh"
            skin["options"] = self._goh_options(opts)
        elif law == "qlv" and opts.get("elastic", "neo-hookean-ni") == "neo-hookean-ni":  # qlv's default
            opts["elastic"] = "goh"
            opts["elastic_options"] = self._goh_options(opts.get("elastic_options"))
            skin["options"] = opts
        else:
            inner = f" (elastic {opts.get('elastic')!r})" if law == "qlv" else ""
            raise self.fail(f"needs an isotropic skin law 'neo-hookean-ni' (plain or inside 'qlv'); "
                            f"the skin layer {skin['name']!r} has {law!r}{inner}")
        params = dict(skin.get("parameters", {}) or {})
        missing = [k for k in ("mu", "K") if k not in params]
        if missing:
            raise self.fail(f"the skin layer {skin['name']!r} lacks parameter(s) {missing}")
        params["c"] = params.pop("mu")
        params["k"] = params.pop("K")
        for local in ("k1", "k2", "kappa", "gamma"):
            params[local] = v[local]
            self.bind(model, local, f"{skin['name']}.{local}")
        skin["parameters"] = params


__all__ = ["Fibres", "Prestress", "Viscoelastic"]
