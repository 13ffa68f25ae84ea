"""The ``[lumped]`` table of a lumped model description, parsed and checked.

Vocabulary (``docs/guide/effects.md``, "Lumped descriptions"; every quantity a number in SI or a
``"<number> <unit>"`` string):

* ``family``: ``"quasi-static"`` (default), ``"kbi"`` or ``"wiener"``.
* ``axis``: ``x``, ``y``, ``z`` or ``-x``, ``-y``, ``-z`` (default ``x``): the skin-frame tip
  component the model acts along; a leading minus makes the model's coordinate and force the
  opposite of that component (``-z``: into the skin, where indentation is positive).
* ``drive``: the recorded channel that drives the model: quasi-static ``"tip_position"``
  (default; force predicted) or ``"tip_force"`` (position predicted, the element inverted per
  sample); dynamic families ``"tip_force"`` only.
* ``elastic`` (quasi-static): ``linear`` (``k`` [N/m]), ``exponential`` (``a`` [N], ``b`` [1/m]),
  ``polynomial`` (``c1`` [N/m], ``c2`` [N/m²], ... ``cn``), values in ``[lumped.parameters]``.
* ``[lumped.parameters]`` of ``kbi``: ``K`` [N/m], ``B`` [N s/m], ``I`` [kg]; of ``wiener``:
  ``Is`` [s²], ``Bs`` [s], ``C1`` [m], ``C2`` [1/N]. ``hold``: ``"foh"`` (default) or ``"zoh"``.
* ``[[lumped.relaxation]]`` ``g``, ``tau`` and ``[lumped.preconditioning]``: quasi-static
  only. Preconditioning comes in two forms (``form``): ``"cycles"`` (``softening``, ``cycles``:
  softening that develops over the loading strokes) and ``"largest-load"`` (``softening``: with
  the largest load so far); without ``form`` a table with ``cycles`` is the cycles form, one
  with only ``softening`` the largest-load form.
* ``test``: a free label (``"extension"``, ``"relaxation"``, ``"indentation"``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from skinkit.errors import ForwardError
from skinkit.forward import instrument as inst_mod
from skinkit.forward.lumped_elements import poly_names

FAMILIES = ("quasi-static", "kbi", "wiener")
ELASTIC = ("linear", "exponential", "polynomial")
_AXES = {"x": 0, "y": 1, "z": 2}
_KEYS = {"family", "axis", "drive", "elastic", "parameters", "relaxation", "preconditioning", "test", "hold"}
#: parameter -> (unit for the parameter set, lower, upper). Units skinkit's table cannot name
#: (1/m, N/m², s², 1/N) are "1": the value is still SI.
_PARAMETERS: dict[str, tuple[str, float, float]] = {
    "k": ("N/m", 0.0, math.inf), "a": ("N", 0.0, math.inf), "b": ("1", 0.0, math.inf),
    "K": ("N/m", 0.0, math.inf), "B": ("N s/m", 0.0, math.inf), "I": ("kg", 0.0, math.inf),
    "Is": ("1", 0.0, math.inf), "Bs": ("s", 0.0, math.inf), "C1": ("m", -math.inf, math.inf),
    "C2": ("1", -math.inf, math.inf),
}
#: units used when reading a "<number> <unit>" string, by parameter
_READ_UNITS = {"k": "N/m", "a": "N", "b": "1", "K": "N/m", "B": "N s/m", "I": "kg", "Is": "1", "Bs": "s",
               "C1": "m", "C2": "1", "c1": "N/m"}
_DYNAMIC = {"kbi": ("K", "B", "I"), "wiener": ("Is", "Bs", "C1", "C2")}


@dataclass
class LumpedSpec:
    """A checked ``[lumped]`` table with its ``[[instrument]]`` entries (SI values)."""

    family: str
    axis: int
    sense: float
    drive: str
    elastic: str
    names: list[str]                        # element / dynamics parameters, local names
    values: dict[str, float]                # "lumped.<name>" -> SI value (relaxation, softening too)
    n_terms: int
    has_preconditioning: bool
    hold: str
    entries: list[inst_mod.Entry] = field(default_factory=list)
    #: ``"cycles"`` or ``"largest-load"`` (``""`` without preconditioning)
    preconditioning_form: str = ""

    @property
    def predicted(self) -> str:
        """The channel the model predicts (the tip channel that does not drive it)."""
        return "tip_force" if self.drive == "tip_position" else "tip_position"

    @property
    def axis_name(self) -> str:
        """The axis as ``"x"``, ``"y"`` or ``"z"``."""
        return "xyz"[self.axis]

    def parameter_bounds(self, name: str) -> tuple[str, float, float]:
        """``(unit, lower, upper)`` of ``"lumped.<name>"``."""
        local = name.split(".", 1)[1]
        if local in _PARAMETERS:
            return _PARAMETERS[local]
        if local.startswith("c"):
            return ("N/m" if local == "c1" else "1", -math.inf, math.inf)
        if local.startswith("g"):
            return ("1", 0.0, 0.99)
        if local.startswith("tau"):
            return ("s", 1e-4, 1e5)
        if local == "cycles":
            return ("1", 1e-3, 1e3)
        return ("1", 0.0, 0.99)   # softening


def _q(value: Any, unit: str, entry: str) -> float:
    from skinkit.fem.errors import ModelError
    from skinkit.fem.model import quantity

    try:
        return float(quantity(value, unit, entry))
    except ModelError as exc:
        raise ForwardError(entry, getattr(exc, "problem", str(exc))) from None
    except (TypeError, ValueError):
        raise ForwardError(entry, f"must be a number or a '<number> <unit>' string, got {value!r}") from None


def parse_lumped(spec: Mapping[str, Any]) -> LumpedSpec:
    """Check a lumped description's ``[lumped]`` table and ``[[instrument]]`` entries.

    Raises :class:`ForwardError` naming the entry (``lumped.parameters.k``, ``lumped.axis``,
    ``instrument[0].kind``) for anything unknown, missing or out of range."""
    lt = spec.get("lumped")
    if not isinstance(lt, Mapping):
        raise ForwardError("lumped", "a lumped model needs a [lumped] table")
    extra = sorted(set(lt) - _KEYS)
    if extra:
        raise ForwardError("lumped", f"unknown key(s) {extra}; allowed are {sorted(_KEYS)}")
    family = str(lt.get("family", "quasi-static"))
    if family not in FAMILIES:
        raise ForwardError("lumped.family", f"must be one of {list(FAMILIES)}, got {family!r}")
    ax = str(lt.get("axis", "x"))
    if ax.lstrip("-") not in _AXES or ax.count("-") > 1:
        raise ForwardError("lumped.axis", f"must be x, y or z (or -x, -y, -z), got {ax!r}")
    sense = -1.0 if ax.startswith("-") else 1.0
    dynamic = family != "quasi-static"
    drive = str(lt.get("drive", "tip_force" if dynamic else "tip_position"))
    allowed = ("tip_force",) if dynamic else ("tip_position", "tip_force")
    if drive not in allowed:
        raise ForwardError("lumped.drive",
                           f"a {family} model is driven by {' or '.join(allowed)}, got {drive!r}")
    hold = str(lt.get("hold", "foh"))
    if hold not in ("foh", "zoh"):
        raise ForwardError("lumped.hold", f"must be 'foh' or 'zoh', got {hold!r}")
    given = lt.get("parameters", {}) or {}
    if not isinstance(given, Mapping):
        raise ForwardError("lumped.parameters", "must be a table")
    elastic, names = _parameter_names(lt, family, given)
    missing = [n for n in names if n not in given]
    unknown = sorted(set(given) - set(names))
    if missing or unknown:
        what = (f"; missing {missing}" if missing else "") + (f"; unknown {unknown}" if unknown else "")
        raise ForwardError("lumped.parameters", f"the {elastic or family} model takes {names}{what}")
    values: dict[str, float] = {}
    for n in names:
        values[f"lumped.{n}"] = _q(given[n], _READ_UNITS.get(n, "1"), f"lumped.parameters.{n}")
    n_rel, pre = _relaxation_and_preconditioning(lt, values)
    out = LumpedSpec(family, _AXES[ax.lstrip("-")], sense, drive, elastic, names, values, n_rel,
                     bool(pre), hold, inst_mod.parse(spec.get("instrument")), pre)
    check_values(out, out.values)
    _check_instrument(out.entries, drive)
    return out


def _parameter_names(lt: Mapping[str, Any], family: str, given: Mapping[str, Any]) -> tuple[str, list[str]]:
    """The elastic law (``""`` for a dynamic family) and the parameter names it takes."""
    if family != "quasi-static":
        for key in ("elastic", "relaxation", "preconditioning"):
            if lt.get(key):
                raise ForwardError(f"lumped.{key}",
                                   f"applies to quasi-static models, not to a {family!r} one")
        return "", list(_DYNAMIC[family])
    elastic = str(lt.get("elastic", "linear"))
    if elastic not in ELASTIC:
        raise ForwardError("lumped.elastic", f"must be one of {list(ELASTIC)}, got {elastic!r}")
    names = poly_names(list(given)) if elastic == "polynomial" else \
        {"linear": ["k"], "exponential": ["a", "b"]}[elastic]
    return elastic, names


def _relaxation_and_preconditioning(lt: Mapping[str, Any], values: dict[str, float]) -> tuple[int, str]:
    """Read ``[[lumped.relaxation]]`` (g, tau [s]) and ``[lumped.preconditioning]`` into
    ``values``; returns the number of relaxation terms and the preconditioning form (``""``
    without it)."""
    rel = lt.get("relaxation", []) or []
    if not isinstance(rel, list) or not all(isinstance(r, Mapping) for r in rel):
        raise ForwardError("lumped.relaxation", "must be an array of tables ([[lumped.relaxation]])")
    for i, r in enumerate(rel, start=1):
        bad = sorted(set(r) - {"g", "tau"})
        if bad or "g" not in r or "tau" not in r:
            raise ForwardError(f"lumped.relaxation[{i - 1}]", f"needs exactly 'g' and 'tau', got {sorted(r)}")
        values[f"lumped.g{i}"] = _q(r["g"], "1", f"lumped.relaxation[{i - 1}].g")
        values[f"lumped.tau{i}"] = _q(r["tau"], "s", f"lumped.relaxation[{i - 1}].tau")
    pre = lt.get("preconditioning")
    return len(rel), ("" if pre is None else _preconditioning(pre, values))


#: preconditioning form -> the keys of its table besides ``form``
PRECONDITIONING_FORMS = {"cycles": ("softening", "cycles"), "largest-load": ("softening",)}


def _preconditioning(pre: Any, values: dict[str, float]) -> str:
    """Read a ``[lumped.preconditioning]`` table into ``values`` (``lumped.softening``,
    ``lumped.cycles``); returns its form. A table without ``form`` is the cycles form if it
    gives ``cycles``, else the largest-load form (older descriptions: ``softening`` only)."""
    e = "lumped.preconditioning"
    if not isinstance(pre, Mapping):
        raise ForwardError(e, "must be a table")
    form = str(pre.get("form", "cycles" if "cycles" in pre else "largest-load"))
    if form not in PRECONDITIONING_FORMS:
        raise ForwardError(f"{e}.form", f"must be one of {list(PRECONDITIONING_FORMS)}, got {form!r}")
    keys = PRECONDITIONING_FORMS[form]
    given = sorted(set(pre) - {"form"})
    if given != sorted(keys):
        raise ForwardError(e, f"the {form} form takes exactly {list(keys)}, got {given}")
    for k in keys:
        values[f"lumped.{k}"] = _q(pre[k], "1", f"{e}.{k}")
    if form == "cycles" and not values["lumped.cycles"] > 0:
        raise ForwardError(f"{e}.cycles", f"must be positive (strokes), got {values['lumped.cycles']:g}")
    return form


def _check_instrument(entries: Any, drive: str) -> None:
    """Instrument entries a lumped model can honour (no tracked points; the driving channel
    only as tip_position from tip_force)."""
    for i, e in enumerate(entries):
        if e.kind == "similarity":
            raise ForwardError(f"instrument[{i}].kind", "a 'similarity' entry acts on tracked points, "
                               "which a lumped model does not predict")
        if e.kind == "series" and e.channel == drive and \
                (e.channel, e.source) != ("tip_position", "tip_force"):
            raise ForwardError(f"instrument[{i}].channel", f"a series entry on the driving channel {drive!r} "
                               "is available only as tip_position from tip_force")


def entry_of(name: str) -> str:
    """The model-file entry of parameter ``name`` (``lumped.g1`` -> ``lumped.relaxation[0].g``)."""
    local = name.split(".", 1)[1] if name.startswith("lumped.") else name
    for key in ("tau", "g"):
        if local.startswith(key) and local[len(key):].isdigit():
            return f"lumped.relaxation[{int(local[len(key):]) - 1}].{key}"
    if local in ("softening", "cycles"):
        return f"lumped.preconditioning.{local}"
    return f"lumped.parameters.{local}" if name.startswith("lumped.") else name


def check_values(ls: LumpedSpec, values: Mapping[str, float]) -> None:
    """Refuse values the model cannot run with, naming the entry (``lumped.relaxation[0].g``)."""
    for nm, v in values.items():
        if not math.isfinite(v):
            raise ForwardError(entry_of(nm), f"must be finite, got {v}")
        if not nm.startswith("lumped."):
            continue
        _, lo, hi = ls.parameter_bounds(nm)
        if not lo <= v <= hi:
            raise ForwardError(entry_of(nm), f"{v:g} (parameter {nm}) is outside its admissible range "
                               f"[{lo:g}, {hi:g}]")
    local = {k.split(".", 1)[1]: v for k, v in values.items() if k.startswith("lumped.")}
    g = [local.get(f"g{i}", 0.0) for i in range(1, ls.n_terms + 1)]
    if sum(g) >= 1:
        raise ForwardError("lumped.relaxation", f"the moduli g sum to {sum(g):g}; they must sum below 1")
    for i in range(1, ls.n_terms + 1):
        if not local.get(f"tau{i}", 1.0) > 0:
            raise ForwardError(entry_of(f"lumped.tau{i}"), "must be positive")
    for n in ("K", "I", "Is", "Bs"):
        if n in ls.names and not local[n] > 0:
            raise ForwardError(f"lumped.parameters.{n}", f"must be positive, got {local[n]:g}")
    if ls.elastic == "linear" and ls.drive == "tip_force" and not local["k"] > 0:
        raise ForwardError("lumped.parameters.k", "must be positive for a force-driven model")


__all__ = ["ELASTIC", "FAMILIES", "LumpedSpec", "check_values", "entry_of", "parse_lumped"]
