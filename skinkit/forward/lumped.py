"""Lumped forward models: a uniaxial elastic element, with relaxation and preconditioning.

For extension, relaxation and indentation records along one ``axis``: the recorded tip
position drives the model (``drive = "tip_position"``, the default) and the force along the
axis is predicted::

    F(t) = φ(t) [g∞ Fe(x(t)) + Σ gᵢ hᵢ(t)],  hᵢ' = −hᵢ/τᵢ + dFe/dt   (QLV, thesis Eq 7.6-7.7)

with the elastic element Fe (``elastic``): ``linear`` F = k x; ``exponential`` (Fung)
F = a (exp(b x) − 1); ``polynomial`` F = c1 x + c2 x² + c3 x³; x the displacement along the
axis [m] (sign as recorded). The Prony recurrence is exact for Fe piecewise linear in time
(as in :mod:`skinkit.fem.viscoelastic`). φ(t) = 1 − softening · m(t)/m_ref is the
preconditioning factor: m the largest |x| seen so far over the session, m_ref the largest
of the session. The other force components are not predicted. ``[[instrument]]`` entries
(force offset and drift, series compliance) apply as for every model.

Sensitivities of every parameter by the complex step (the simulation is complex-safe): exact
to rounding. Model file::

    [model]
    kind = "lumped"
    [lumped]
    axis = "x"
    elastic = "exponential"
    [lumped.parameters]
    a = "0.05 N"
    b = 300.0          # [1/m]: numbers are SI
    [[lumped.relaxation]]
    g = 0.3
    tau = "10 s"
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from skinkit.errors import ForwardError, SchemaError
from skinkit.forward import drive as drive_mod
from skinkit.forward import instrument as inst_mod
from skinkit.forward.effects import AppliedEffect, apply_all
from skinkit.schemas import ChannelPrediction, Observations, Parameter, ParameterSet, Prediction

#: elastic element -> (parameter, SI unit, lower, upper)
ELASTIC: dict[str, list[tuple[str, str, float, float]]] = {
    "linear": [("k", "N/m", 0.0, math.inf)],
    "exponential": [("a", "N", 0.0, math.inf), ("b", "1", 0.0, math.inf)],
    "polynomial": [("c1", "N/m", -math.inf, math.inf), ("c2", "1", -math.inf, math.inf),
                   ("c3", "1", -math.inf, math.inf)],
}
_AXES = {"x": 0, "y": 1, "z": 2}
_KEYS = {"axis", "drive", "elastic", "parameters", "relaxation", "preconditioning", "test"}
_H = 1e-30


def _elastic(kind: str, p: Mapping[str, Any], x: np.ndarray) -> np.ndarray:
    if kind == "linear":
        return p["k"] * x
    if kind == "exponential":
        return p["a"] * np.expm1(p["b"] * x) if np.isrealobj(p["a"]) and np.isrealobj(p["b"]) \
            else p["a"] * (np.exp(p["b"] * x) - 1)
    return p["c1"] * x + p["c2"] * x ** 2 + p["c3"] * x ** 3


def simulate(kind: str, p: Mapping[str, Any], t: np.ndarray, x: np.ndarray, g: Sequence[Any],
             tau: Sequence[Any], phi: np.ndarray | Any) -> np.ndarray:
    """Force ``(T,)`` of the element at times ``t`` [s] under displacement ``x`` [m] (complex-safe)."""
    fe = _elastic(kind, p, x)
    out = (1 - sum(g)) * fe if len(g) else fe * 1.0
    if len(g):
        dt = np.diff(t)
        dfe = np.diff(fe)
        for gi, ti in zip(g, tau, strict=True):
            e = np.exp(-dt / ti)
            beta = ti / dt * (1 - e)
            h = np.zeros(len(t), dtype=np.result_type(fe, gi, ti))
            for n in range(1, len(t)):   # the exact recurrence for piecewise-linear Fe
                h[n] = e[n - 1] * h[n - 1] + beta[n - 1] * dfe[n - 1]
            out = out + gi * h
    return phi * out


class LumpedForwardModel:
    """A uniaxial lumped model as a :class:`skinkit.protocols.ForwardModel`."""

    kind = "lumped"

    def __init__(self, spec: Mapping[str, Any], effects: list[AppliedEffect] = ()) -> None:
        self.base = copy.deepcopy(dict(spec))
        self.base.pop("effects", None)
        self.effects = list(effects)
        self.name = str(dict(self.base.get("model", {}) or {}).get("name", "lumped"))
        eff = apply_all(self.base, self.effects)
        self._read(eff)
        self.axis = self._axis_name
        self._pset = self._parameters(eff)

    def _read(self, spec: Mapping[str, Any]) -> None:
        from skinkit.fem.errors import ModelError
        from skinkit.fem.model import quantity
        lt = spec.get("lumped")
        if not isinstance(lt, Mapping):
            raise ForwardError("lumped", "a lumped model needs a [lumped] table")
        extra = sorted(set(lt) - _KEYS)
        if extra:
            raise ForwardError("lumped", f"unknown key(s) {extra}; allowed are {sorted(_KEYS)}")
        self._axis_name = str(lt.get("axis", "x"))
        if self._axis_name not in _AXES:
            raise ForwardError("lumped.axis", f"must be x, y or z, got {self._axis_name!r}")
        self.drive_channel = str(lt.get("drive", "tip_position"))
        if self.drive_channel != "tip_position":
            raise ForwardError("lumped.drive",
                               "only 'tip_position' (displacement in, force out) is available")
        self.elastic = str(lt.get("elastic", "linear"))
        if self.elastic not in ELASTIC:
            raise ForwardError("lumped.elastic", f"must be one of {sorted(ELASTIC)}, got {self.elastic!r}")
        given = dict(lt.get("parameters", {}) or {})
        names = [n for n, *_ in ELASTIC[self.elastic]]
        missing = sorted(set(names) - set(given))
        unknown = sorted(set(given) - set(names))
        if missing or unknown:
            what = (f"; missing {missing}" if missing else "") + (f"; unknown {unknown}" if unknown else "")
            raise ForwardError("lumped.parameters", f"the {self.elastic!r} element takes {names}{what}")
        try:
            self.params = {n: quantity(given[n], u, f"lumped.parameters.{n}")
                           for n, u, *_ in ELASTIC[self.elastic]}
            rel = lt.get("relaxation", []) or []
            self.g = [quantity(r.get("g"), "1", f"lumped.relaxation[{i}].g") for i, r in enumerate(rel)]
            self.tau = [quantity(r.get("tau"), "s", f"lumped.relaxation[{i}].tau") for i, r in enumerate(rel)]
            pre = dict(lt.get("preconditioning", {}) or {})
            self.softening = quantity(pre.get("softening", 0.0), "1", "lumped.preconditioning.softening")
        except ModelError as exc:
            raise ForwardError(exc.args[0].split(":")[0], str(exc)) from None
        for n, _, lo, hi in ELASTIC[self.elastic]:
            if not lo <= self.params[n] <= hi:
                raise ForwardError(f"lumped.parameters.{n}",
                                   f"{self.params[n]:g} is outside [{lo:g}, {hi:g}]")
        if any(t <= 0 for t in self.tau) or any(not 0 <= g < 1 for g in self.g) or sum(self.g) >= 1:
            raise ForwardError("lumped.relaxation", "needs 0 <= g, sum(g) < 1 and tau > 0")
        if not 0 <= self.softening < 1:
            raise ForwardError("lumped.preconditioning.softening",
                               f"must be in [0, 1), got {self.softening}")
        self.entries = inst_mod.parse(spec.get("instrument"))

    def _parameters(self, spec: Mapping[str, Any]) -> ParameterSet:
        bound = set(dict(spec.get("bindings", {}) or {}).values())
        out = []
        for n, u, lo, hi in ELASTIC[self.elastic]:
            out.append(Parameter(f"lumped.{n}", self.params[n], u, lo, hi))
        for i, (g, t) in enumerate(zip(self.g, self.tau, strict=True), start=1):
            out.append(Parameter(f"lumped.g{i}", g, "1", 0.0, 0.99))
            out.append(Parameter(f"lumped.tau{i}", t, "s", 1e-3, 1e4))
        if "preconditioning" in dict(spec["lumped"]):
            out.append(Parameter("lumped.softening", self.softening, "1", 0.0, 0.99))
        out = [p for p in out if p.name not in bound]
        effect_names = {f"{e.name}.{k}" for e in self.effects for k in e.declared}
        for e in self.entries:
            for nm in (e.parameter, e.azimuth_parameter):
                if nm and nm not in effect_names and nm not in {p.name for p in out}:
                    out.append(Parameter(nm, e.value, "1"))
        for e in self.effects:
            out.extend(e.parameter_set())
        return ParameterSet(out)

    def parameters(self) -> ParameterSet:
        return self._pset

    def _values(self, params: ParameterSet) -> tuple[dict[str, Any], Mapping[str, Any]]:
        """Internal values (``lumped.*`` and instrument names) at ``params``."""
        vals = params.values()
        unknown = sorted(set(vals) - set(self._pset.names))
        if unknown:
            raise SchemaError("parameters", f"unknown parameter(s) {unknown} for model {self.name!r}")
        spec = apply_all(self.base, self.effects, vals)
        bind = dict(spec.get("bindings", {}) or {})
        internal: dict[str, Any] = {f"lumped.{n}": v for n, v in self.params.items()}
        lt = spec["lumped"]
        for i, r in enumerate(lt.get("relaxation", []) or [], start=1):
            internal[f"lumped.g{i}"] = float(r["g"])
            internal[f"lumped.tau{i}"] = _si(r["tau"], "s")
        pre = dict(lt.get("preconditioning", {}) or {})
        internal["lumped.softening"] = _si(pre.get("softening", 0.0), "1")
        for e in inst_mod.parse(spec.get("instrument")):
            internal[e.parameter] = e.value
            if e.azimuth_parameter:
                internal[e.azimuth_parameter] = e.azimuth
        for nm, v in vals.items():
            internal[bind.get(nm, nm)] = v
        return internal, bind

    def predict(self, params: ParameterSet, observations: Observations,
                sensitivities: bool | Sequence[str] = False) -> Prediction:
        """Predicted force (and, with a series compliance, position) of every protocol."""
        names = self._pset.names if sensitivities is True else \
            ([] if not sensitivities else list(sensitivities))
        unknown = sorted(set(names) - set(self._pset.names))
        if unknown:
            raise SchemaError("sensitivities", f"unknown parameter(s) {unknown} for model {self.name!r}")
        internal, bind = self._values(params)
        base = self._run(internal, observations)
        pred = Prediction({p: {c: ChannelPrediction(v, {}, m) for c, (v, m) in chans.items()}
                           for p, chans in base.items()}, {},
                          {p.name: self.drive_channel for p in observations})
        for nm in names:
            key = bind.get(nm, nm)
            pert = dict(internal)
            pert[key] = internal[key] + 1j * _H
            out = self._run(pert, observations)
            for p, chans in out.items():
                for c, (v, _) in chans.items():
                    pred.protocols[p][c].d[nm] = np.imag(v) / _H
            pred.methods[nm] = "complex-step"
        return pred

    def _run(self, v: Mapping[str, Any], observations: Observations) -> dict[str, dict[str, tuple[Any, Any]]]:
        ax = _AXES[self._axis_name]
        p = {n: v[f"lumped.{n}"] for n, *_ in ELASTIC[self.elastic]}
        g = [v[f"lumped.g{i}"] for i in range(1, len(self.g) + 1)]
        tau = [v[f"lumped.tau{i}"] for i in range(1, len(self.tau) + 1)]
        entries = [_with(e, v) for e in self.entries]
        drives = {}
        for po in observations:
            if self.drive_channel not in po.channels:
                raise ForwardError(f"session protocol {po.name!r}", f"has no {self.drive_channel!r} channel "
                                   f"to drive the lumped model; it has {sorted(po.channels)}")
            if "tip_force" not in po.channels:
                raise ForwardError(f"session protocol {po.name!r}", "has no 'tip_force' channel to predict")
            ch = po.channels[self.drive_channel]
            x = drive_mod.fill_invalid(ch.values, ch.valid)
            drives[po.name] = (ch.time_s, x[:, ax])
        m_ref = max((float(np.max(np.abs(x))) for _, x in drives.values()), default=0.0)
        running = 0.0
        out: dict[str, dict[str, tuple[Any, Any]]] = {}
        for po in observations:
            t, x = drives[po.name]
            level = np.maximum.accumulate(np.maximum(np.abs(x), running)) / m_ref if m_ref > 0 else 0 * x
            running = max(running, float(np.max(np.abs(x))))
            phi = 1 - v["lumped.softening"] * level
            f = simulate(self.elastic, p, t, x, g, tau, phi)
            fch = po.channels["tip_force"]
            F = np.zeros(fch.values.shape, dtype=np.result_type(f, float))
            F[:, ax] = np.interp(fch.time_s, t, f.real)
            if np.iscomplexobj(f):
                F[:, ax] = F[:, ax] + 1j * np.interp(fch.time_s, t, f.imag)
            mask = np.zeros(fch.values.shape, bool)
            mask[:, ax] = True
            Fm = _measure(entries, "tip_force", fch.time_s, F)
            out[po.name] = {"tip_force": (Fm, mask)}
        return out


def _si(value: Any, unit: str) -> float:
    from skinkit.fem.model import quantity
    return quantity(value, unit, "lumped")


def _with(e: inst_mod.Entry, v: Mapping[str, Any]):
    from dataclasses import replace
    return replace(e, value=v.get(e.parameter, e.value),
                   azimuth=v.get(e.azimuth_parameter, e.azimuth) if e.azimuth_parameter else e.azimuth)


def _measure(entries, channel: str, t: np.ndarray, F):
    """Bias entries on the predicted force (complex-safe)."""
    out = F.astype(np.result_type(F, *[e.value for e in entries]))
    for e in entries:
        if e.kind == "bias" and e.channel == channel:
            out[:, e.component] = out[:, e.component] + e.value * (1.0 if e.basis == "constant" else t)
        elif e.kind in ("series", "tilt", "similarity") and e.channel in (channel, "", "tip_position"):
            if e.kind != "similarity":
                raise ForwardError(f"instrument ({e.parameter})",
                                   f"{e.kind!r} entries are not available in a lumped model "
                                   "driven by position")
    return out


def build_lumped(spec: Mapping[str, Any], effects: list[AppliedEffect] = ()) -> LumpedForwardModel:
    """The lumped forward model of a description (``[model] kind = "lumped"``)."""
    return LumpedForwardModel(spec, list(effects))


__all__ = ["ELASTIC", "LumpedForwardModel", "build_lumped", "simulate"]
