"""Check the model-file tables the forward models read but ``skinkit solve`` does not build
from: ``[session]``, ``[surface]``, ``[drive]``, ``[[instrument]]``, ``[[fields]]``,
``[[effects]]``, ``bindings`` and ``[calibration]``.

:func:`check_description` runs when a description is read (``read_description``, ``skinkit
solve``), before any work, so that a misspelt key, a value of the wrong type or outside its
range is one error naming the file's entry -- not a key silently ignored, nor an error at
the first prediction, minutes into a fit. The readers (``skinkit.forward.fe``,
``skinkit.forward.instrument``, ``skinkit.fem.fields``, ``skinkit.forward.effects``,
``skinkit.lab``) keep their own checks; this module adds what they leave out: unknown keys
with the nearest valid one, types, ranges, protocol and effect names against those known.
The accepted ranges are listed in ``docs/reference/model-files.md``.
"""

from __future__ import annotations

import copy
import difflib
import math
from collections.abc import Mapping
from typing import Any

from skinkit.errors import EffectError, ForwardError

#: ``[drive] max_step`` range [s]: positive, at most this (longer than any protocol)
MAX_DRIVE_STEP_S = 1e4
#: ``[[instrument]]`` keys
INSTRUMENT_KEYS = ("kind", "parameter", "value", "channel", "component", "basis", "tau", "tau_parameter",
                   "knot", "source", "mode", "azimuth", "azimuth_parameter")
#: ``[[fields]]`` keys besides each kind's parameters
FIELD_KEYS = ("name", "kind", "layers")


def _near(key: str, allowed: list[str]) -> str:
    near = difflib.get_close_matches(key, allowed, n=1, cutoff=0.6)
    return f" (did you mean {near[0]!r}?)" if near else ""


def _keys(d: Mapping[str, Any], allowed: list[str], entry: str, err: type[Exception]) -> None:
    """Refuse a key not in ``allowed``, naming the nearest valid one."""
    extra = sorted((k for k in d if k not in allowed), key=str)
    if extra:
        key = str(extra[0])
        raise err(f"{entry}.{key}",
                  f"unknown key{_near(key, sorted(allowed))}; allowed are {sorted(allowed)}")


def _table(value: Any, entry: str, err: type[Exception]) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise err(entry, f"expected a table, got {value!r}")
    return value


def _tables(value: Any, entry: str, err: type[Exception]) -> list[Mapping[str, Any]]:
    if not isinstance(value, list) or not all(isinstance(t, Mapping) for t in value):
        raise err(entry, f"must be an array of tables ([[{entry}]]), got {value!r}")
    return value


def _name(value: Any, entry: str, err: type[Exception]) -> str:
    if not isinstance(value, str) or not value.strip():
        raise err(entry, f"expected a non-empty name (a string), got {value!r}")
    return value


def _quantity(value: Any, unit: str, entry: str, err: type[Exception]) -> float:
    from skinkit.fem.errors import ModelError
    from skinkit.fem.model import quantity

    try:
        return quantity(value, unit, entry)
    except ModelError as exc:
        raise err(entry, exc.problem if hasattr(exc, "problem") else str(exc)) from None


def check_session(value: Any) -> None:
    """``[session]``: ``protocols`` (names of the protocol library, each once) and
    ``parameters`` (``<protocol> = { <parameter> = <number> }`` of those protocols)."""
    from skinkit.acquisition.library import catalogue

    s = _table(value, "session", ForwardError)
    _keys(s, ["protocols", "parameters"], "session", ForwardError)
    known = {p.name: p for p in catalogue()}
    if "protocols" in s:
        protos = s["protocols"]
        if not isinstance(protos, list) or not protos:
            raise ForwardError("session.protocols",
                               f"expected a non-empty list of protocol names, got {protos!r}")
        for i, p in enumerate(protos):
            _protocol(p, f"session.protocols[{i}]", known)
        dup = sorted({p for p in protos if protos.count(p) > 1})
        if dup:
            raise ForwardError("session.protocols", f"{dup[0]!r} is named twice")
    params = _table(s.get("parameters", {}), "session.parameters", ForwardError)
    for name, table in params.items():
        entry = f"session.parameters.{name}"
        proto = known[_protocol(name, entry, known)]
        table = _table(table, entry, ForwardError)
        _keys(table, sorted(proto.parameters), entry, ForwardError)
        for key, v in table.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                unit = {"1": "no unit"}.get(proto.units.get(key, "SI"), proto.units.get(key, "SI"))
                raise ForwardError(f"{entry}.{key}", f"expected a finite number in {unit} (the units "
                                   f"skinkit robot protocols lists), got {v!r}")
            if isinstance(proto.parameters[key], int) and not float(v).is_integer():
                raise ForwardError(f"{entry}.{key}", f"expected a whole number, got {v!r}")


def _protocol(name: Any, entry: str, known: Mapping[str, Any]) -> str:
    name = _name(name, entry, ForwardError)
    if name not in known:
        raise ForwardError(entry, f"unknown protocol {name!r}{_near(name, list(known))}; "
                           "see skinkit robot protocols")
    return name


def check_surface(value: Any) -> None:
    """``[surface]``: ``fit`` (true, false or "auto"), ``outside`` ("error" or "nearest")."""
    s = _table(value, "surface", ForwardError)
    _keys(s, ["fit", "outside"], "surface", ForwardError)
    fit = s.get("fit", "auto")
    if fit not in (True, False, "auto") or (not isinstance(fit, (bool, str))):
        raise ForwardError("surface.fit", f"must be true, false or \"auto\", got {fit!r}")
    outside = s.get("outside", "error")
    if outside not in ("error", "nearest") or not isinstance(outside, str):
        raise ForwardError("surface.outside", f"must be \"error\" or \"nearest\", got {outside!r}")


def check_drive(value: Any) -> None:
    """``[drive]``: ``max_step``, the largest solver step, a time in (0, 1e4] s."""
    d = _table(value, "drive", ForwardError)
    _keys(d, ["max_step"], "drive", ForwardError)
    if "max_step" in d:
        x = _quantity(d["max_step"], "s", "drive.max_step", ForwardError)
        if not 0 < x <= MAX_DRIVE_STEP_S:
            raise ForwardError("drive.max_step", f"must be in (0, {MAX_DRIVE_STEP_S:g}] s, got {x:g}")


def check_instrument(value: Any) -> None:
    """``[[instrument]]``: keys (nearest valid named), names as strings, ``component`` a whole
    number 0..2, and the angles and scales a transform can have: a tilt within ±90°, an in-plane
    rotation within ±180°, a scale ``1 + value`` above 0."""
    for i, e in enumerate(_tables(value, "instrument", ForwardError)):
        w = f"instrument[{i}]"
        _keys(e, list(INSTRUMENT_KEYS), w, ForwardError)
        kind = e.get("kind")
        for key in ("kind", "parameter", "channel", "basis", "source", "mode", "azimuth_parameter"):
            if key in e and not isinstance(e[key], str):
                raise ForwardError(f"{w}.{key}", f"expected a string, got {e[key]!r}")
        if "component" in e:
            c = e["component"]
            if isinstance(c, bool) or not isinstance(c, int) or c not in (0, 1, 2):
                raise ForwardError(f"{w}.component", f"must be 0, 1 or 2 (x, y, z), got {c!r}")
        if "value" not in e or kind not in ("tilt", "similarity"):
            continue
        v = e["value"]
        if kind == "tilt" or e.get("mode") == "rotation":
            x = _quantity(v, "rad", f"{w}.value", ForwardError)
            lim = math.pi / 2 if kind == "tilt" else math.pi
            if abs(x) > lim:
                raise ForwardError(f"{w}.value", f"{math.degrees(x):.4g} deg is outside "
                                   f"[-{math.degrees(lim):g}, {math.degrees(lim):g}] deg")
        else:
            x = _quantity(v, "1", f"{w}.value", ForwardError)
            if not x > -1:
                raise ForwardError(f"{w}.value", f"a scale 1 + value must be positive: value > -1, got {x:g}")


def check_fields(value: Any) -> None:
    """``[[fields]]``: ``name`` a string (each once), ``kind`` a known kind, ``layers`` names,
    and only the keys of that kind (nearest valid named)."""
    from skinkit.fem.errors import ModelError
    from skinkit.fem.fields import KINDS, UNITS, inclusion_shape

    for i, t in enumerate(_tables(value, "fields", ModelError)):
        e = f"fields[{i}]"
        _name(t.get("name"), f"{e}.name", ModelError)
        kind = t.get("kind")
        if not isinstance(kind, str) or kind not in KINDS:
            raise ModelError(f"{e}.kind", f"must be one of {sorted(KINDS)}, got {kind!r}")
        need, opt = KINDS[kind]
        _keys(t, [*FIELD_KEYS, *need, *opt], e, ModelError)
        layers = t.get("layers")
        if isinstance(layers, str):
            layers = [layers]
        if not isinstance(layers, list) or not layers or not all(isinstance(n, str) for n in layers):
            raise ModelError(f"{e}.layers",
                             f"expected the names of the layers it acts on, got {t.get('layers')!r}")
        missing = [k for k in need if k not in t]
        if missing:
            raise ModelError(f"{e}.{missing[0]}",
                             f"is required for a {kind!r} field (it takes {list(need + opt)})")
        if kind == "inclusion":   # a disc or an ellipse, not both
            try:
                inclusion_shape(t)
            except ModelError as exc:
                raise ModelError(e, exc.problem) from None
        for k in (*need, *opt):
            if k in t:
                _field_value(k, _quantity(t[k], UNITS[k], f"{e}.{k}", ModelError), f"{e}.{k}")


def _field_value(key: str, x: float, entry: str) -> None:
    """The ranges of ``[[fields]]`` parameters: a ratio, radius, semi-axes and widths above 0, a depth
    of at least 0, a softening in [0, 1)."""
    from skinkit.fem.errors import ModelError

    if key in ("ratio", "radius", "a", "b", "half_width", "width") and not x > 0:
        raise ModelError(entry, f"must be positive, got {x:g}")
    if key == "depth" and not x >= 0:
        raise ModelError(entry, f"must be at least 0 m (below the top surface), got {x:g}")
    if key == "softening" and not 0 <= x < 1:
        raise ModelError(entry, f"must be in [0, 1), got {x:g}")


def check_effects(value: Any) -> None:
    """``[[effects]]``: ``name`` an installed effect (the nearest and the installed ones named)
    and only that effect's parameters (nearest valid named)."""
    from skinkit import registry

    installed = registry.names("skinkit.effects")
    for i, t in enumerate(_tables(value, "effects", EffectError)):
        e = f"effects[{i}]"
        name = _name(t.get("name"), f"{e}.name", EffectError)
        if name not in installed:
            raise EffectError(f"{e}.name", f"unknown effect {name!r}{_near(name, installed)}; installed: "
                              f"{', '.join(sorted(installed)) or 'none'} (skinkit effects)")
        try:
            plugin = registry.create("skinkit.effects", name)
            forms = tuple(getattr(plugin, "forms", ()) or ())
            if "form" in t and t["form"] in forms:
                plugin = copy.copy(plugin)
                plugin.form = t["form"]
            declared = [p.name for p in plugin.parameters()]
        except Exception:  # a broken plugin is reported by the reader, with its own error
            continue
        # settings the reader checks itself: an instance label (repeatable or region effects), a form
        labelled = getattr(plugin, "repeatable", False) or getattr(plugin, "region", None)
        settings = ["instance"] if labelled else []
        settings += ["form"] if forms else []
        _keys(t, ["name", *settings, *declared], e, EffectError)


def check_bindings(value: Any) -> None:
    """``bindings``: a table of parameter name -> parameter name (written by effects)."""
    b = _table(value, "bindings", ForwardError)
    for k, v in b.items():
        if not isinstance(v, str) or not v:
            raise ForwardError(f"bindings.{k}", f"expected a parameter name (a string), got {v!r}")


def check_calibration(value: Any) -> None:
    """``[calibration]``: a table (a calibrated model's record of its fit, read by no model;
    :mod:`skinkit.inverse.calibrated`)."""
    _table(value, "calibration", ForwardError)


_CHECKS = {"session": check_session, "surface": check_surface, "drive": check_drive,
           "instrument": check_instrument, "fields": check_fields, "effects": check_effects,
           "bindings": check_bindings, "calibration": check_calibration}


def check_description(spec: Mapping[str, Any]) -> None:
    """Check every table of ``spec`` this module knows (see the module docstring); raises
    :class:`ForwardError`, :class:`EffectError` or :class:`skinkit.fem.errors.ModelError`
    naming the entry."""
    for key, check in _CHECKS.items():
        if key in spec and spec[key] is not None:
            check(spec[key])


__all__ = ["check_bindings", "check_calibration", "check_description", "check_drive", "check_effects",
           "check_fields", "check_instrument", "check_session", "check_surface"]
