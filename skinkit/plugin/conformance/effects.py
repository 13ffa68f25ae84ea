"""The conformance kit for candidate effects (``skinkit.effects``): the stable API an effect
author (and skinkit's own tests) checks an effect with.

:func:`check_effect` ``(effect)`` -> :class:`~skinkit.plugin.conformance.report.Report`, checks:

- ``interface``: the members of :class:`skinkit.interfaces.Effect`, a name, and kinds among
  ``"fe"`` and ``"lumped"``;
- ``parameters``: at least one, unique local names without a dot, SI units, ``lower < upper``,
  the null and the typical magnitude (the declared value) inside the bounds, the names of
  ``null()`` those of ``parameters()``, and a typical magnitude that differs from the null; a
  declared ``region`` names three of them in metres and leaves at least one other (and a
  declared ``region_ellipse`` names a form of the effect with the centre and semi-axes in metres
  and the angle in rad);
- per model kind the effect supports, on a small model of that kind (:mod:`.testbeds`):
  ``<kind>: input unchanged`` (``apply`` at the null and at the typical magnitude leaves its
  input alone), ``<kind>: tables`` (only the top-level tables the effect declares in
  ``touches`` change), ``<kind>: applies once`` (a second application is an ``EffectError``
  naming ``effects.<name>``, unless the effect declares ``once = False``), ``<kind>: null``
  (at the null every prediction equals the model's without the effect to 1e-10 of its size),
  ``<kind>: sensitivity`` (at the typical magnitude the effect moves the prediction and at
  least one parameter has a non-zero derivative; the detail names those that have none);
- per model kind it does not support: ``<kind>: refused`` (``apply`` raises an
  ``EffectError`` naming ``effects.<name>``).

The lumped checks take well under a second per effect. The finite-element ones solve the
coarsest mesh (about a second per prediction) and run, by default, only for an effect that
applies to finite-element models alone (``fe=True`` runs them for any FE effect; ``fe=False``
never). ``lumped``/``fe_model`` and ``lumped_session``/``fe_session`` replace the built-in
model descriptions and sessions.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit import registry
from skinkit.errors import EffectError, SkinkitError
from skinkit.interfaces import Effect, missing_members
from skinkit.plugin.conformance import testbeds
from skinkit.plugin.conformance.report import Report
from skinkit.schemas import Observations
from skinkit.units import si_unit

KINDS = ("fe", "lumped")
#: the largest relative change of a prediction the null may cause (rounding of the solves)
NULL_RTOL = 1e-10
#: a parameter moves the prediction when its derivative times its typical step changes it by
#: more than this share of the prediction's size
VISIBLE_RTOL = 1e-6


def _plugin(effect: Any) -> Any:
    return registry.create("skinkit.effects", effect) if isinstance(effect, str) else effect


def check_effect(effect: Any, *, fe: bool | None = None, lumped_model: Mapping[str, Any] | None = None,
                 lumped_session: Observations | None = None, fe_model: Mapping[str, Any] | None = None,
                 fe_session: Observations | None = None) -> Report:
    """Check ``effect`` (a plugin object, or the name of an installed one); see the module."""
    plugin = _plugin(effect)
    name = str(getattr(plugin, "name", "") or "?")
    report = Report("effect", name)
    if not _interface(plugin, report) or not _parameters(plugin, report):
        return report
    kinds = tuple(plugin.kinds)
    run_fe = ("lumped" not in kinds) if fe is None else fe
    beds = {"lumped": (lumped_model, lumped_session, testbeds.lumped_model, testbeds.lumped_session),
            "fe": (fe_model, fe_session, testbeds.fe_model, testbeds.fe_session)}
    for kind in KINDS:
        given, obs, make, make_obs = beds[kind]
        spec = dict(given) if given is not None else make()
        if kind not in kinds:
            _refused(plugin, kind, spec, report)
            continue
        if not _edits(plugin, kind, spec, report):
            continue
        if kind == "lumped" or run_fe:
            _predictions(plugin, kind, spec, obs if obs is not None else make_obs(), report)
    return report


def _interface(plugin: Any, report: Report) -> bool:
    missing = missing_members(plugin, Effect)
    name = getattr(plugin, "name", None)
    kinds = tuple(getattr(plugin, "kinds", ()) or ())
    problems = [f"missing {', '.join(missing)}"] if missing else []
    if not isinstance(name, str) or not name:
        problems.append("no name")
    if not kinds or set(kinds) - set(KINDS):
        problems.append(f"kinds must be among {KINDS}, got {kinds}")
    return report.add("interface", not problems, "; ".join(problems))


def _parameters(plugin: Any, report: Report) -> bool:
    problems = []
    try:
        params = list(plugin.parameters())
        null = dict(plugin.null())
    except Exception as exc:  # a third-party declaration may raise anything
        return report.add("parameters", False, f"{type(exc).__name__}: {exc}")
    names = [p.name for p in params]
    if not params:
        problems.append("declares no parameter")
    if len(set(names)) != len(names):
        problems.append(f"repeated names {names}")
    if sorted(null) != sorted(names):
        problems.append(f"null() names {sorted(null)}, parameters() {sorted(names)}")
    for p in params:
        where = f"{p.name}"
        if "." in p.name or not p.name:
            problems.append(f"{where}: a local name is non-empty and has no dot")
        if p.unit != si_unit(p.unit):
            problems.append(f"{where}: unit {p.unit!r} is not SI")
        if not p.lower < p.upper:
            problems.append(f"{where}: bounds [{p.lower}, {p.upper}] are empty")
        v0 = null.get(p.name, math.nan)
        if not (math.isfinite(v0) and p.lower <= v0 <= p.upper):
            problems.append(f"{where}: null {v0} outside [{p.lower}, {p.upper}]")
        if not (math.isfinite(p.value) and p.lower <= p.value <= p.upper):
            problems.append(f"{where}: typical {p.value} outside [{p.lower}, {p.upper}]")
    if params and not problems and all(p.value == null[p.name] for p in params):
        problems.append("the typical magnitude equals the null: the effect could never be seen")
    problems += _region_problems(plugin, {p.name: p for p in params})
    return report.add("parameters", not problems, "; ".join(problems))


def _region_problems(plugin: Any, params: Mapping[str, Any]) -> list[str]:
    """What is wrong with a declared ``region``: three declared parameters in metres (centre x, y,
    size), and at least one other parameter for the region scan to test."""
    region = getattr(plugin, "region", None)
    if region is None:
        return []
    names = tuple(region) if isinstance(region, (tuple, list)) else ()
    if len(names) != 3 or not all(isinstance(n, str) for n in names):
        return [f"region must name three parameters (x, y, size), got {region!r}"]
    out = [f"region: {n!r} is not a declared parameter in m" for n in names
           if n not in params or params[n].unit != "m"]
    if not set(params) - set(names):
        out.append("region: no parameter besides the region's to test at each region")
    return out + _ellipse_problems(plugin)


def _ellipse_problems(plugin: Any) -> list[str]:
    """What is wrong with a declared ``region_ellipse``: a form the effect has, whose declared
    parameters hold the five names — centre x, y and semi-axes a, b in metres, the angle in rad."""
    decl = getattr(plugin, "region_ellipse", None)
    if decl is None:
        return []
    try:
        form, names = decl
        names = tuple(names)
    except (TypeError, ValueError):
        return [f"region_ellipse must be (form, (x, y, a, b, angle)), got {decl!r}"]
    if form not in tuple(getattr(plugin, "forms", ()) or ()) or len(names) != 5:
        return [f"region_ellipse: {form!r} must be one of the effect's forms and name five parameters, "
                f"got {decl!r}"]
    shaped = copy.copy(plugin)
    shaped.form = form
    params = {p.name: p for p in shaped.parameters()}
    units = ("m", "m", "m", "m", "rad")
    return [f"region_ellipse: {n!r} is not a declared parameter in {u} of form {form!r}"
            for n, u in zip(names, units, strict=True) if n not in params or params[n].unit != u]


def _typical(plugin: Any) -> dict[str, float]:
    return {p.name: float(p.value) for p in plugin.parameters()}


def _names_it(exc: EffectError, plugin: Any) -> bool:
    return getattr(exc, "entry", "") == f"effects.{plugin.name}"


def _refused(plugin: Any, kind: str, spec: Mapping[str, Any], report: Report) -> None:
    try:
        plugin.apply(spec, plugin.null())
    except EffectError as exc:
        ok = _names_it(exc, plugin)
        report.add(f"{kind}: refused", ok,
                   "" if ok else f"the error names {exc.entry!r}, not effects.{plugin.name}")
        return
    except Exception as exc:  # anything but EffectError is a bug of the effect
        report.add(f"{kind}: refused", False, f"raised {type(exc).__name__}: {exc} instead of EffectError")
        return
    report.add(f"{kind}: refused", False, f"applies to a {kind!r} model it does not declare in kinds")


def _edits(plugin: Any, kind: str, spec: Mapping[str, Any], report: Report) -> bool:
    """Input unchanged, declared tables only, refused twice; False when apply itself fails."""
    before = copy.deepcopy(dict(spec))
    outs = []
    for p in (plugin.null(), _typical(plugin)):
        try:
            outs.append(plugin.apply(spec, p))
        except Exception as exc:  # the testbed is one every effect of the kind must fit
            return report.add(f"{kind}: apply", False, f"{type(exc).__name__}: {exc}")
    same = spec == before
    report.add(f"{kind}: input unchanged", same, "" if same else "apply modified its input")
    declared = dict(getattr(plugin, "touches", {}) or {})
    if kind in declared:
        allowed = set(declared[kind])
        changed = sorted({k for out in outs for k in set(out) | set(before) if out.get(k) != before.get(k)})
        extra = sorted(set(changed) - allowed)
        report.add(f"{kind}: tables", not extra,
                   f"changes {extra}, declares {sorted(allowed)}" if extra else "")
    if getattr(plugin, "once", True):
        try:
            plugin.apply(outs[1], _typical(plugin))
        except EffectError as exc:
            report.add(f"{kind}: applies once", _names_it(exc, plugin),
                       "" if _names_it(exc, plugin) else f"the error names {exc.entry!r}")
        else:
            report.add(f"{kind}: applies once", False,
                       "a second application is accepted (declare once = False if it cannot be recognised)")
    return True


def _items(pred: Any) -> list[tuple[str, str, np.ndarray]]:
    return [(p, c, np.asarray(cp.values)) for p, c, cp in pred.items()]


def _size(pred: Any) -> float:
    return max((float(np.max(np.abs(v))) for _, _, v in _items(pred) if v.size), default=0.0)


def _change(a: Any, b: Any) -> float:
    """The largest absolute difference between two predictions of the same session."""
    pairs = zip(_items(a), _items(b), strict=True)
    return max((float(np.max(np.abs(x - y))) for (_, _, x), (_, _, y) in pairs if x.size), default=0.0)


def _predictions(plugin: Any, kind: str, spec: Mapping[str, Any], obs: Observations, report: Report) -> None:
    """The null leaves the predictions unchanged; the typical magnitude moves them."""
    from skinkit.forward import load

    base = copy.deepcopy(dict(spec))
    base.pop("effects", None)
    # the plugin object itself, installed or not
    mine = {plugin.name: plugin}
    try:
        with load(base, workers=1) as m:
            ref = m.predict(m.parameters(), obs)
        with load({**base, "effects": [{"name": plugin.name}]}, workers=1, plugins=mine) as m:
            null = m.predict(m.parameters(), obs)
        typical = _typical(plugin)
        with load({**base, "effects": [{"name": plugin.name, **typical}]}, workers=1, plugins=mine) as m:
            names = [f"{plugin.name}.{k}" for k in typical]
            typ = m.predict(m.parameters(), obs, sensitivities=names)
    except SkinkitError as exc:
        report.add(f"{kind}: predictions", False, f"{type(exc).__name__}: {exc}")
        return
    scale = _size(ref) or 1.0
    err = _change(null, ref) / scale
    report.add(f"{kind}: null", err <= NULL_RTOL, f"relative change {err:.1e} (tolerance {NULL_RTOL:.0e})")
    _sensitivity(plugin, kind, typ, ref, scale, report)


def _sensitivity(plugin: Any, kind: str, typ: Any, ref: Any, scale: float, report: Report) -> None:
    null = dict(plugin.null())
    flat = []
    for p in plugin.parameters():
        step = abs(p.value - null[p.name]) or abs(p.value) or (p.upper - p.lower)
        d = max((float(np.max(np.abs(cp.d.get(f"{plugin.name}.{p.name}", 0.0)))) for _, _, cp in typ.items()),
                default=0.0)
        if not (math.isfinite(d) and d * step > VISIBLE_RTOL * scale):
            flat.append(p.name)
    moved = _change(typ, ref) / scale
    ok = moved > VISIBLE_RTOL and len(flat) < len(null)
    detail = f"typical magnitude changes the prediction by {moved:.1e} of its size"
    if flat:
        detail += f"; no derivative on this model: {', '.join(flat)}"
    report.add(f"{kind}: sensitivity", ok, detail)


__all__ = ["KINDS", "NULL_RTOL", "VISIBLE_RTOL", "check_effect"]
