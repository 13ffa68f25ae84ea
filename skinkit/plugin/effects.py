"""The stable API for authors of candidate effects (``skinkit.effects``).

Everything in ``__all__`` is public and kept stable. An effect declares parameters and edits a
**model description** (the mapping a model file parses to) with the vocabulary the forward
models already read and differentiate (``bindings``, ``[[layers]]`` edits, ``[[fields]]``,
``[[instrument]]`` entries, the ``[lumped]`` table; see ``docs/guide/effects.md``). It never adds code
to a forward model. Errors are :class:`skinkit.errors.EffectError` naming ``effects.<name>``.

- :class:`BaseEffect` what every effect shares: ``parameters()`` and ``null()`` from its
  declarations, the kind check, the deep copy (``apply`` never modifies its input), refusal of
  a second application, and accessors of the copied description (``layers``, ``thickness``,
  ``lumped``, ``bind``, ``add_field``, ``add_instrument``, ``fail``). A subclass sets ``name``
  and ``kinds``, returns its declarations from ``_declared()`` and implements ``_apply_fe``
  and/or ``_apply_lumped``, which edit the copy in place (values in SI, every parameter
  present: those not given take their null value);
- :func:`declare` one parameter: name, typical magnitude, null value, unit, admissible bounds
  (all in that unit; stored in SI) -> a :class:`Declared`;
- :func:`model_kind` ``"fe"`` (the default) or ``"lumped"`` from a description's ``[model]``;
- :func:`quantity` a scalar in SI from a model-file value, a number (already SI) or a
  ``"<number> <unit>"`` string (``quantity("1.5 mm", "m", "layers[0].thickness")`` ->
  ``0.0015``), refusing anything else with an :class:`~skinkit.errors.EffectError` naming the
  entry.

An effect is checked with :func:`skinkit.plugin.conformance.effects.check_effect`.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

from skinkit.errors import EffectError, SkinkitError
from skinkit.fem.model import quantity as _model_quantity
from skinkit.schemas import Parameter
from skinkit.units import to_si


@dataclass(frozen=True)
class Declared:
    """A declared parameter (typical magnitude as its value) and its null value [SI]."""

    parameter: Parameter
    null: float


def declare(name: str, typical: float, null: float, unit: str, lower: float, upper: float) -> Declared:
    """A parameter ``name`` given in ``unit`` (any known unit; stored in SI): typical magnitude,
    null value and admissible bounds ``[lower, upper]``, all in ``unit``."""
    p = Parameter(name, typical, unit, lower, upper)
    n = float(to_si(float(null), unit, p.unit, f"{name}.null"))
    if not p.lower <= n <= p.upper:  # a programming error in the effect, not a user error
        raise ValueError(f"null value of {name!r} is outside its bounds")
    return Declared(p, n)


def model_kind(model: Mapping[str, Any]) -> str:
    """``[model] kind`` of a description: ``"fe"`` (the default) or ``"lumped"``."""
    m = model.get("model", {})
    return str(m.get("kind", "fe")) if isinstance(m, Mapping) else "fe"


def quantity(value: Any, unit: str, entry: str) -> float:
    """A scalar in SI ``unit`` from a number (SI) or a ``"<number> <unit>"`` string;
    :class:`EffectError` naming ``entry`` otherwise."""
    try:
        return _model_quantity(value, unit, entry)
    except SkinkitError as exc:
        raise EffectError(entry, getattr(exc, "problem", str(exc))) from None


class BaseEffect:
    """Parameters, null, kind check and copy; subclasses edit the copy.

    Two optional declarations say what the conformance kit
    (:mod:`skinkit.plugin.conformance.effects`) may expect of the effect: ``touches``, model
    kind -> the top-level tables of a description ``apply`` may change (a kind left out is not
    checked), and ``once``, True when ``apply`` recognises the effect in a description it
    already edited and refuses a second application (an effect that only moves a value
    already in the description cannot).

    ``repeatable``, True when the effect may be added more than once ("more of the same", e.g.
    one more Prony term): a further ``[[effects]]`` table with an ``instance`` label applies a
    shallow copy of the plugin whose ``name`` is the label, so an effect that names everything
    after ``self.name`` (as the accessors below do) needs nothing else; its edits must then
    compose with those of the earlier instances (append, not overwrite).

    ``forms``, the forms an effect comes in when it has several (a constitutive choice with
    its own parameters), the first the default: an ``[[effects]]`` table may then choose one
    (``form = "..."``) and :func:`skinkit.forward.effects.resolve` applies a shallow copy of the
    plugin whose ``form`` is the chosen one; ``_declared`` and ``_apply_*`` read
    :meth:`chosen_form`.

    ``geometry``, the parameters that only move the model's geometry (a layer's thickness): for
    each of them ``apply`` changes where the mesh's nodes lie and nothing else — the same
    elements, regions, node sets, laws and values. The finite-element forward model then
    differentiates it analytically, by the shape derivative (:mod:`skinkit.fem.shape`), its
    design velocity dX/dp read off the meshes built at neighbouring values (geometry, no solve);
    a parameter not declared here is differentiated by central differences of whole solves
    unless the engine knows it otherwise (a binding).

    ``region``, the local names ``(x, y, size)`` of an effect confined to a region of the skin
    plane: its centre [m] in the skin frame and its size [m] (a radius). The gap diagnosis then
    scans candidate regions over the tracked points' extent for the effect's other parameters
    (:mod:`skinkit.gap.scan`) instead of testing it at the declared null position, and refuses a
    centre given outside that extent. Such an effect may be applied more than once under
    ``instance`` labels (several candidate regions in one model), so, as a repeatable effect,
    it names everything after ``self.name``.

    ``region_ellipse``, for a region effect that also comes in an elliptical form: that form's
    name and the local names of its centre, semi-axes and angle, ``(form, (x, y, a, b, angle))``
    ([m], [m], [rad] of the ``a`` axis from x). The diagnosis then scans elongated shapes at the
    best region it found and refits the effect in that form, so that it estimates the region's
    centre, semi-axes and direction with its strength.
    """

    name: str = ""
    kinds: tuple[str, ...] = ("fe",)
    touches: ClassVar[Mapping[str, frozenset[str]]] = MappingProxyType({})
    once: ClassVar[bool] = True
    repeatable: ClassVar[bool] = False
    forms: ClassVar[tuple[str, ...]] = ()
    form: str = ""
    geometry: ClassVar[frozenset[str]] = frozenset()
    region: ClassVar[tuple[str, str, str] | None] = None
    region_ellipse: ClassVar[tuple[str, tuple[str, str, str, str, str]] | None] = None

    def _declared(self) -> list[Declared]:
        raise NotImplementedError

    def chosen_form(self) -> str:
        """The form in use: ``form`` when set, else the first of ``forms`` (``""`` without forms)."""
        return self.form or (self.forms[0] if self.forms else "")

    @property
    def entry(self) -> str:
        """The name errors give: ``effects.<name>``."""
        return f"effects.{self.name}"

    def fail(self, problem: str) -> EffectError:
        """An :class:`EffectError` naming this effect (to raise)."""
        return EffectError(self.entry, problem)

    def parameters(self) -> list[Parameter]:
        """Declared parameters: local names, SI units, admissible bounds, typical magnitude as value."""
        return [d.parameter for d in self._declared()]

    def null(self) -> dict[str, float]:
        """Local name -> SI value at which the model with the effect is exactly the model without it."""
        return {d.parameter.name: d.null for d in self._declared()}

    def values(self, p: Mapping[str, Any]) -> dict[str, float]:
        """Every parameter [SI]: those of ``p`` (numbers in SI or quantity strings), the others null."""
        declared = {d.parameter.name: d for d in self._declared()}
        unknown = sorted(set(p) - set(declared))
        if unknown:
            raise self.fail(f"unknown parameter(s) {unknown}; it has {sorted(declared)}")
        return {k: (quantity(p[k], d.parameter.unit, f"{self.entry}.{k}") if k in p else d.null)
                for k, d in declared.items()}

    def apply(self, model: Mapping[str, Any], p: Mapping[str, Any]) -> dict[str, Any]:
        """A deep copy of ``model`` with the effect added, its parameters set from ``p``
        (local name -> SI value; missing ones take their null value). ``model`` is not modified."""
        kind = model_kind(model)
        if kind not in self.kinds:
            raise self.fail(f"applies to {', '.join(self.kinds)} models, not to a {kind!r} model")
        v = self.values(p)
        out = copy.deepcopy(dict(model))
        self.refuse_twice(out)
        if kind == "lumped":
            self._apply_lumped(out, v)
        else:
            self._apply_fe(out, v)
        return out

    def _apply_fe(self, model: dict[str, Any], v: dict[str, float]) -> None:
        raise self.fail("does not apply to finite-element models")

    def _apply_lumped(self, model: dict[str, Any], v: dict[str, float]) -> None:
        raise self.fail("does not apply to lumped models")

    def refuse_twice(self, model: Mapping[str, Any]) -> None:
        """:class:`EffectError` when the description already holds this effect's bindings,
        field or instrument entries (an effect applies once)."""
        prefix = f"{self.name}."
        bound = model.get("bindings", {}) or {}
        fields = model.get("fields", []) or []
        inst = model.get("instrument", []) or []
        if (any(str(k).startswith(prefix) for k in bound)
                or any(isinstance(f, Mapping) and f.get("name") == self.name for f in fields)
                or any(isinstance(e, Mapping) and str(e.get(k, "")).startswith(prefix)
                       for e in inst for k in ("parameter", "azimuth_parameter"))):
            raise self.fail("is already applied to this model")

    # -- accessors of the (copied) description -----------------------------------------------
    def layers(self, model: dict[str, Any], at_least: int = 1) -> list[dict[str, Any]]:
        """The ``[[layers]]`` tables (top down, made plain dicts in place); at least ``at_least``."""
        layers = model.get("layers")
        if not isinstance(layers, list) or not all(isinstance(L, Mapping) for L in layers):
            raise self.fail("needs a finite-element model with [[layers]] tables")
        if len(layers) < at_least:
            what = "a skin layer" if at_least == 1 else \
                f"at least {at_least} layers (skin and the tissue below)"
            raise self.fail(f"needs {what}; the model has {len(layers)}")
        model["layers"] = [dict(L) for L in layers]
        for i, L in enumerate(model["layers"]):
            if not str(L.get("name", "")):
                raise self.fail(f"layers[{i}] has no name")
        return model["layers"]

    def thickness(self, layer: Mapping[str, Any]) -> float:
        """A layer's thickness [m]."""
        return quantity(layer.get("thickness"), "m", f"{self.entry} (layer {layer.get('name')!r} thickness)")

    def bind(self, model: dict[str, Any], local: str, target: str) -> None:
        """``bindings["<effect>.<local>"] = target``: the effect parameter is model parameter ``target``."""
        b = dict(model.get("bindings", {}) or {})
        key = f"{self.name}.{local}"
        if key in b:
            raise self.fail(f"is already applied to this model (binding {key!r} exists)")
        b[key] = target
        model["bindings"] = b

    def add_field(self, model: dict[str, Any], table: dict[str, Any]) -> None:
        """Append a ``[[fields]]`` table named after the effect (its parameters are then
        ``"<effect>.<key>"``, the effect's own names)."""
        fields = list(model.get("fields", []) or [])
        if any(isinstance(f, Mapping) and f.get("name") == self.name for f in fields):
            raise self.fail(f"is already applied to this model (a field named {self.name!r} exists)")
        fields.append({"name": self.name, **table})
        model["fields"] = fields

    def add_instrument(self, model: dict[str, Any], entries: list[dict[str, Any]]) -> None:
        """Append ``[[instrument]]`` entries (their parameters are the effect's)."""
        inst = list(model.get("instrument", []) or [])
        prefix = f"{self.name}."
        for e in inst:
            if isinstance(e, Mapping) and any(str(e.get(k, "")).startswith(prefix)
                                              for k in ("parameter", "azimuth_parameter")):
                raise self.fail("is already applied to this model "
                                "(an [[instrument]] entry has its parameters)")
        model["instrument"] = inst + entries

    def lumped(self, model: dict[str, Any]) -> dict[str, Any]:
        """The ``[lumped]`` table of a lumped description (a plain dict, in place)."""
        lt = model.get("lumped")
        if not isinstance(lt, Mapping):
            raise self.fail("a lumped model needs a [lumped] table")
        model["lumped"] = dict(lt)
        return model["lumped"]


__all__ = ["BaseEffect", "Declared", "declare", "model_kind", "quantity"]
