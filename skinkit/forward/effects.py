"""``[[effects]]`` tables of a model file: resolve the plugins, check the values, apply them.

An ``[[effects]]`` table names an effect plugin (``name``) and gives any subset of its
parameters (numbers in SI or ``"<number> <unit>"`` strings); the others take the effect's
null value, so ``[[effects]] name = "prestress"`` alone leaves the model unchanged.
Effect parameters are named ``"<effect>.<parameter>"`` in the model's parameter set.

An effect that declares ``repeatable = True`` may be given again with an ``instance`` label
(``{name = "viscoelastic", instance = "viscoelastic-2"}``): the plugin is applied once more under
that label, which names its parameters (``"viscoelastic-2.g1"``), bindings, fields and
instrument entries in place of the effect's name. Labels are unique and no other installed
effect's name.

An effect that declares a ``region`` (its centre and size parameters) takes ``instance`` labels
too: several regions of one effect in one model (two scars; the gap diagnosis's region scan).

An effect that declares ``forms`` (its first the default) may be given in another form
(``{name = "preconditioning", form = "largest-load"}``): the plugin is applied as a copy whose
``form`` is the chosen one, with that form's parameters.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from skinkit import registry
from skinkit.errors import EffectError, PluginError
from skinkit.schemas import Parameter, ParameterSet


@dataclass
class AppliedEffect:
    """One effect of a model: the plugin, its declared parameters and the values in use [SI].

    ``name`` is the label its parameters are named after (the effect's name, or the table's
    ``instance``); ``effect`` the plugin's name (the same unless an instance)."""

    name: str
    plugin: Any
    declared: dict[str, Parameter]
    values: dict[str, float]
    effect: str = ""

    def __post_init__(self) -> None:
        self.effect = self.effect or self.name

    def parameter_set(self) -> list[Parameter]:
        """The effect's parameters under their model names (``"<effect>.<local>"``), values in use."""
        out = []
        for local, d in self.declared.items():
            out.append(Parameter(f"{self.name}.{local}", self.values[local], d.unit, d.lower, d.upper,
                                 free=True))
        return out


def effect_plugin(name: str, entry: str = "effects") -> Any:
    """The effect plugin ``name``; :class:`EffectError` naming ``entry`` if it is not installed."""
    try:
        return registry.create("skinkit.effects", name)
    except PluginError as exc:
        raise EffectError(entry, f"unknown effect {name!r}: {exc}") from None


def _label(t: Mapping[str, Any], name: str, plugin: Any, entry: str, seen: set[str]) -> str:
    """The table's label: its ``instance`` (checked) or the effect's name; not one of ``seen``."""
    if "instance" not in t:
        if name in seen:
            more = (f"; a further instance needs a label (instance = \"{name}-2\")"
                    if getattr(plugin, "repeatable", False) else "")
            raise EffectError(f"{entry}.name", f"effect {name!r} is given twice{more}")
        return name
    label = t["instance"]
    e = f"{entry}.instance"
    if not (getattr(plugin, "repeatable", False) or getattr(plugin, "region", None)):
        raise EffectError(e, f"effect {name!r} is not repeatable and declares no region: it takes no "
                          "instance label")
    if not isinstance(label, str) or not label or "." in label or label != label.strip():
        # the label heads parameter names "<label>.<local>"
        raise EffectError(e, f"must be a non-empty name without '.' or surrounding spaces, got {label!r}")
    if label in seen:
        raise EffectError(e, f"label {label!r} is given twice")
    if label != name and label in registry.names("skinkit.effects"):
        raise EffectError(e, f"label {label!r} is the name of another installed effect")
    return label


def _instance(plugin: Any, label: str) -> Any:
    """The plugin under ``label``: a shallow copy whose ``name`` is the label (the plugin itself
    when the label is its name), so everything it names after itself takes the label."""
    if label == getattr(plugin, "name", label):
        return plugin
    inst = copy.copy(plugin)
    inst.name = label
    return inst


def _in_form(t: Mapping[str, Any], name: str, plugin: Any, entry: str) -> Any:
    """The plugin in the table's ``form`` (a shallow copy whose ``form`` is set), or the
    plugin itself when the table chooses none."""
    if "form" not in t:
        return plugin
    forms = tuple(getattr(plugin, "forms", ()) or ())
    if not forms:
        raise EffectError(f"{entry}.form", f"effect {name!r} has only one form: it takes no 'form'")
    if t["form"] not in forms:
        raise EffectError(f"{entry}.form", f"effect {name!r} has the forms {list(forms)}, "
                          f"not {t['form']!r}")
    inst = copy.copy(plugin)
    inst.form = t["form"]
    return inst


def _quantity(value: Any, unit: str, entry: str) -> float:
    from skinkit.fem.errors import ModelError
    from skinkit.fem.model import quantity

    try:
        return quantity(value, unit, entry)
    except ModelError as exc:
        raise EffectError(entry, exc.problem if hasattr(exc, "problem") else str(exc)) from None


def check_value(effect: str, p: Parameter, value: float, entry: str) -> float:
    """``value`` [SI] if it lies in ``p``'s admissible range, else an :class:`EffectError`."""
    if not math.isfinite(value):
        raise EffectError(entry, f"must be finite, got {value}")
    if not p.lower <= value <= p.upper:
        raise EffectError(entry, f"{value:g} {p.unit} is outside the admissible range "
                          f"[{p.lower:g}, {p.upper:g}] {p.unit} of effect {effect!r}")
    return value


def resolve(tables: Any, kind: str, plugins: Mapping[str, Any] | None = None) -> list[AppliedEffect]:
    """Validate ``[[effects]]`` tables for a model of ``kind`` (``"fe"`` or ``"lumped"``).

    ``plugins``: effect name -> plugin object, used instead of the installed plugin of that name
    (an effect not installed yet, as the conformance kit checks one)."""
    if tables is None:
        return []
    if not isinstance(tables, list):
        raise EffectError("effects", "must be an array of tables ([[effects]])")
    out: list[AppliedEffect] = []
    seen: set[str] = set()
    for i, t in enumerate(tables):
        entry = f"effects[{i}]"
        if not isinstance(t, Mapping) or "name" not in t:
            raise EffectError(entry, "needs a 'name' (an effect of the skinkit.effects group)")
        name = str(t["name"])
        plugin = plugins[name] if plugins and name in plugins else effect_plugin(name, f"{entry}.name")
        label = _label(t, name, plugin, entry, seen)
        seen.add(label)
        kinds = tuple(getattr(plugin, "kinds", ()))
        if kind not in kinds:
            raise EffectError(f"{entry}.name", f"effect {name!r} applies to {', '.join(kinds) or 'no'} "
                              f"models, not to a {kind!r} model")
        plugin = _in_form(t, name, plugin, entry)
        declared = {p.name: p for p in plugin.parameters()}
        null = dict(plugin.null())
        unknown = sorted(set(t) - set(declared) - {"name", "instance", "form"})
        if unknown:
            raise EffectError(entry, f"unknown parameter(s) {unknown} for effect {name!r}; "
                              f"it has {sorted(declared)}")
        values = {}
        for local, d in declared.items():
            e = f"{entry}.{local}"
            v = _quantity(t[local], d.unit, e) if local in t else float(null.get(local, d.value))
            values[local] = check_value(label, d, v, e)
        out.append(AppliedEffect(label, _instance(plugin, label), declared, values, name))
    return out


def apply_all(spec: Mapping[str, Any], effects: list[AppliedEffect],
              values: Mapping[str, float] | None = None) -> dict[str, Any]:
    """The description with every effect applied in order (values: ``"<effect>.<local>"`` ->
    SI value overriding those in use). The input is not modified."""
    out = copy.deepcopy(dict(spec))
    out.pop("effects", None)
    for eff in effects:
        p = dict(eff.values)
        if values:
            for local in p:
                key = f"{eff.name}.{local}"
                if key in values:
                    p[local] = check_value(eff.name, eff.declared[local], float(values[key]), key)
        # an effect refuses a model with EffectError (docs/guide/writing-plugins.md); anything else it
        # raises is a bug in the effect and propagates with its traceback
        out = dict(eff.plugin.apply(out, p))
    return out


def effect_parameters(effects: list[AppliedEffect]) -> ParameterSet:
    """Every effect parameter under its model name."""
    return ParameterSet([p for e in effects for p in e.parameter_set()])


__all__ = ["AppliedEffect", "apply_all", "check_value", "effect_parameters", "effect_plugin", "resolve"]
