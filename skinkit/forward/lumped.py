"""Lumped forward models: a session's recorded drive through a uniaxial element, predicting the other channel.

Families (``[lumped] family``; vocabulary in :mod:`skinkit.forward.lumped_spec`):

* ``quasi-static`` — extension, relaxation and indentation records. Displacement in, force
  out (``drive = "tip_position"``)::

      f(t) = g∞ φ Fe(u) + Σᵢ gᵢ hᵢ,   φ(t) = 1 − softening (1 − exp(−A(t)/cycles))

  with the elastic element Fe (``linear``, ``exponential``, ``polynomial``), the exact Prony
  recurrence of ``[[lumped.relaxation]]`` terms and the preconditioning factor φ, A(t) the
  loading strokes so far in units of the session's largest drive (or, in the largest-load
  form, φ = 1 − softening · m(t)/m_ref; :mod:`skinkit.forward.lumped_elements`); or force in,
  displacement out (``drive = "tip_force"``): the QLV filter and the element inverted sample
  by sample.
* ``kbi`` and ``wiener`` — the dynamic models of :mod:`skinkit.sysid` (force in, position out)
  on a uniformly sampled record (:mod:`skinkit.forward.lumped_dynamic`).

u and f are the tip position and force along ``axis`` (``-z``: into the skin). The drive
channel's invalid samples are interpolated; the prediction has the observed channel's shape
and times, with the components other than the axis 0 and marked not predicted.

``[[instrument]]`` entries (:mod:`skinkit.forward.instrument`) turn the recorded drive into
what the skin saw and the prediction into what was recorded. A series compliance on a
displacement drive (the motor's position recorded, the tip lagging by c f) is solved with the
element: u + c f(u) = recorded, Newton per sample. A(t) and m(t) are taken from the drive along
the axis after the bias and tilt entries (what the motor imposed).

Sensitivities: parameters of the element, relaxation, preconditioning and a drive-side series
compliance by the complex step (the simulation is complex-safe; exact to rounding); instrument
parameters acting on the measurement analytically; those acting on the drive by a complex step
along their analytic drive derivative. Effect parameters bound to a model parameter
(``bindings``) report that parameter's sensitivity under the effect's name.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from skinkit.errors import ForwardError, SchemaError
from skinkit.forward import drive as drive_mod
from skinkit.forward import instrument as inst_mod
from skinkit.forward import lumped_dynamic as dyn
from skinkit.forward import lumped_elements as el
from skinkit.forward.effects import AppliedEffect, apply_all
from skinkit.forward.lumped_spec import ELASTIC, LumpedSpec, check_values, parse_lumped
from skinkit.interfaces import ForwardModel
from skinkit.schemas import ChannelPrediction, Observations, Parameter, ParameterSet, Prediction

#: complex step [SI of the parameter]: far below rounding of any value, so exact to rounding
_H = 1e-30


def simulate(ls: LumpedSpec, v: Mapping[str, Any], drives: Sequence[tuple[np.ndarray, np.ndarray]]
             ) -> list[np.ndarray]:
    """The element's response to each protocol's drive (session order, complex-safe).

    ``v``: ``"lumped.<name>"`` -> value (and a drive-side series compliance under its entry's
    parameter name); ``drives``: per protocol ``(t (T,) [s], u (T,))``, u the drive along the
    axis [m or N]. Returns per protocol the predicted quantity along the axis ``(T,)``
    (force [N] for a displacement drive, position [m] for a force drive).
    """
    out = []
    if ls.family != "quasi-static":
        for t, u in drives:
            dt = np.diff(t)
            if dt.size == 0 or float(np.ptp(dt)) > 1e-6 * float(np.mean(dt)):
                raise ForwardError(f"lumped.family = {ls.family!r}", "needs a uniformly sampled record")
            step = float(np.mean(dt))
            if ls.family == "kbi":
                out.append(dyn.second_order(u, v["lumped.K"], v["lumped.B"], v["lumped.I"], step, ls.hold))
            else:
                out.append(dyn.wiener(u, v["lumped.Is"], v["lumped.Bs"], v["lumped.C1"], v["lumped.C2"], step,
                                      ls.hold))
        return out
    p = {n: v[f"lumped.{n}"] for n in ls.names}
    g = [v[f"lumped.g{i}"] for i in range(1, ls.n_terms + 1)]
    tau = [v[f"lumped.tau{i}"] for i in range(1, ls.n_terms + 1)]
    phis: list[Any] = [1.0] * len(drives)
    if ls.has_preconditioning:
        phis = el.softening_factors(ls.preconditioning_form, [u for _, u in drives], v["lumped.softening"],
                                    v.get("lumped.cycles", 1.0))
    series = [e for e in ls.entries if e.kind == "series" and e.channel == ls.drive]
    for (t, u), phi in zip(drives, phis, strict=True):
        if ls.drive == "tip_force":
            fe = el.qlv_inverse(t, u, g, tau) / phi
            out.append(el.elastic_inverse(ls.elastic, p, fe, "lumped.parameters"))
        elif series:
            c = sum(v.get(e.parameter, e.value) for e in series)
            where = f"instrument ({series[0].parameter})"
            out.append(el.series_solve(t, u, phi, ls.elastic, p, g, tau, c, where)[1])
        else:
            out.append(el.qlv(t, phi * el.elastic_force(ls.elastic, p, u), g, tau))
    return out


def _interp(t_to: np.ndarray, t_from: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Linear interpolation along axis 0 (complex-safe); the same array when the times agree."""
    if t_to.shape == t_from.shape and np.array_equal(t_to, t_from):
        return y
    flat = y.reshape(len(t_from), -1)
    cols = [np.interp(t_to, t_from, flat[:, j].real) + (1j * np.interp(t_to, t_from, flat[:, j].imag)
                                                         if np.iscomplexobj(flat) else 0.0)
            for j in range(flat.shape[1])]
    return np.stack(cols, axis=1).reshape((len(t_to),) + y.shape[1:])


class LumpedForwardModel(ForwardModel):
    """A lumped model description as a :class:`skinkit.interfaces.ForwardModel` (module docstring).

    It holds nothing between predictions: ``close()`` (inherited) does nothing, so a lumped
    model may be used after it and in any number of ``with`` blocks."""

    kind = "lumped"

    def __init__(self, spec: Mapping[str, Any], effects: Sequence[AppliedEffect] = ()) -> None:
        self.base = copy.deepcopy(dict(spec))
        self.base.pop("effects", None)
        self.base.pop("load", None)
        self.effects = list(effects)
        self.name = str(dict(self.base.get("model", {}) or {}).get("name", "lumped"))
        eff = apply_all(self.base, self.effects)
        self.spec = parse_lumped(eff)
        #: the tip axis letter (``skinkit predict`` reads a one-axis CSV along it)
        self.axis = self.spec.axis_name
        self.last_info: dict[str, Any] = {}
        self._pset = self._parameters(eff)

    @property
    def record_components(self) -> str:
        """The tip components of a record the model reads (``"x"``, ``"xyz"`` with a tilt entry,
        which turns the recorded drive): the noise of the others need not be estimable."""
        if any(e.kind == "tilt" for e in self.spec.entries):
            return "xyz"
        return self.axis

    @property
    def default_protocols(self) -> tuple[str, ...]:
        """Table 12 protocols a virtual-lab session of this model holds by default."""
        if self.spec.family != "quasi-static":
            return ("stochastic_full_scale",)
        return {"x": ("in_plane_000",), "y": ("in_plane_090",)}.get(self.axis, ("normal_indentation",))

    def _parameters(self, spec: Mapping[str, Any]) -> ParameterSet:
        bound = set(dict(spec.get("bindings", {}) or {}).values())
        effect_names = {f"{e.name}.{k}" for e in self.effects for k in e.declared}
        out: list[Parameter] = []
        for nm, v in self.spec.values.items():
            if nm not in bound:
                unit, lo, hi = self.spec.parameter_bounds(nm)
                out.append(Parameter(nm, v, unit, lo, hi))
        out += inst_mod.parameters(self.spec.entries, {p.name for p in out} | effect_names)
        for e in self.effects:
            out.extend(e.parameter_set())
        return ParameterSet(out)

    def parameters(self) -> ParameterSet:
        """Every parameter of the model, values from the description (effects at their values)."""
        return self._pset

    def values(self, params: ParameterSet | Mapping[str, float]) -> tuple[LumpedSpec, dict[str, float],
                                                                           dict[str, str]]:
        """``(spec, internal values, bindings)`` at ``params``: the description with the effects
        applied at their values; internal names are ``lumped.*`` and instrument parameters."""
        vals = params.values() if isinstance(params, ParameterSet) else dict(params)
        unknown = sorted(set(vals) - set(self._pset.names))
        if unknown:
            raise SchemaError("parameters", f"unknown parameter(s) {unknown} for model {self.name!r}")
        spec = apply_all(self.base, self.effects, vals)
        bind = {str(k): str(t) for k, t in dict(spec.get("bindings", {}) or {}).items()}
        ls = parse_lumped(spec)
        internal = dict(ls.values)
        for e in ls.entries:
            internal[e.parameter] = e.value
            if e.azimuth_parameter:
                internal[e.azimuth_parameter] = e.azimuth
        for nm, v in vals.items():
            internal[bind.get(nm, nm)] = float(v)
        check_values(ls, internal)
        ls.entries = [replace(e, value=internal.get(e.parameter, e.value),
                              azimuth=internal.get(e.azimuth_parameter, e.azimuth) if e.azimuth_parameter
                              else e.azimuth) for e in ls.entries]
        return ls, internal, bind

    # -- prediction ----------------------------------------------------------------------------
    def predict(self, params: ParameterSet, observations: Observations,
                sensitivities: bool | Sequence[str] = False) -> Prediction:
        """Predictions of the channel the model does not take as its drive, every protocol. A
        prediction or sensitivity that is not a finite number (the element overflowing at the
        record's drive) is refused naming the model's values, not returned as inf or nan."""
        # an overflow is reported once, below, naming the values, not as numpy warnings
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            pred = self._predict(params, observations, sensitivities)
        for proto, cname, cp in pred.items():
            ch = observations[proto].channels[cname]
            shown = cp.mask(ch)
            bad = [f"its prediction of {cname}"] if not np.isfinite(cp.values[shown]).all() else []
            bad += [f"the sensitivity of {cname} to {nm}" for nm, a in cp.d.items()
                    if not np.isfinite(a[shown]).all()]
            with np.errstate(over="ignore", invalid="ignore"):
                # the residual's sum of squares, bounded: a finite but huge prediction overflows it
                worst = np.max(np.abs(cp.values - ch.values)[shown] / np.min(ch.noise), initial=0.0)
                if not bad and not np.isfinite(worst * worst * max(int(shown.sum()), 1)):
                    bad = [f"the sum of squares of its residual of {cname} (up to {worst:.3g} noise levels)"]
            if bad:
                ls, v, _ = self.values(params)
                given = ", ".join(f"{nm} = {x:g}" for nm, x in v.items() if nm.startswith("lumped."))
                law = f"its {ls.elastic} element" if ls.elastic else f"its {ls.family} model"
                raise ForwardError(f"model {self.name!r}", f"{bad[0]} in protocol {proto!r} is not a finite "
                                   f"number at {given}: a value outside what {law} can evaluate over "
                                   "the record's drive")
        return pred

    def _predict(self, params: ParameterSet, observations: Observations,
                 sensitivities: bool | Sequence[str]) -> Prediction:
        if not isinstance(observations, Observations):
            raise SchemaError("observations", f"expected Observations, got {type(observations).__name__}")
        names = self._pset.names if sensitivities is True else \
            ([] if not sensitivities else list(sensitivities))
        unknown = sorted(set(names) - set(self._pset.names))
        if unknown:
            raise SchemaError("sensitivities", f"unknown parameter(s) {unknown} for model {self.name!r}")
        t0 = time.perf_counter()
        ls, v, bind = self.values(params)
        targets = {nm: bind.get(nm, nm) for nm in names}
        inst_names = inst_mod.parameter_names(ls.entries)
        series_drive = {e.parameter for e in ls.entries if e.kind == "series" and e.channel == ls.drive}
        drive_entries = [e for e in ls.entries if not (e.kind == "series" and e.channel == ls.drive)]
        want_inst = sorted({t for t in targets.values() if t in inst_names})
        # the drive each protocol's skin saw, along the axis, with its instrument derivatives
        recs = []
        for po in observations:
            if ls.drive not in po.channels:
                raise ForwardError(f"session protocol {po.name!r}",
                                   f"has no {ls.drive!r} channel to drive the lumped model ([lumped] drive); "
                                   f"it has {sorted(po.channels)}")
            if ls.predicted not in po.channels:
                raise ForwardError(f"session protocol {po.name!r}",
                                   f"has no {ls.predicted!r} channel for the lumped model to predict; "
                                   f"it has {sorted(po.channels)}")
            ch = po.channels[ls.drive]
            rec = drive_mod.fill_invalid(ch.values, ch.valid)
            true, dtrue = inst_mod.drive(drive_entries, ls.drive, ch.time_s, rec, want_inst)
            recs.append((ch.time_s, true, dtrue))
        base = [(t, ls.sense * true[:, ls.axis]) for t, true, _ in recs]
        y0 = simulate(ls, v, base)
        dy: dict[str, list[np.ndarray]] = {}
        methods: dict[str, str] = {}
        for key in sorted(set(targets.values())):
            if key in v and (key.startswith("lumped.") or key in series_drive):
                pert = dict(v)
                pert[key] = v[key] + 1j * _H
                dy[key] = [np.imag(y) / _H for y in simulate(ls, pert, base)]
                methods[key] = "complex-step"
            elif key in inst_names:
                if any(key in d for _, _, d in recs):
                    # a complex step along the drive's analytic derivative: the model's response to it
                    pdrv = [(t, u + 1j * _H * ls.sense * d[key][:, ls.axis] if key in d else u + 0j)
                            for (t, u), (_, _, d) in zip(base, recs, strict=True)]
                    dy[key] = [np.imag(y) / _H for y in simulate(ls, v, pdrv)]
                    methods[key] = "complex-step"
                else:
                    methods[key] = "analytic"
            else:
                methods[key] = "central-difference"
        out: dict[str, dict[str, ChannelPrediction]] = {}
        for k, po in enumerate(observations):
            t_d, true, dtrue = recs[k]
            ch = po.channels[ls.predicted]
            Y = np.zeros((len(t_d), 3))
            Y[:, ls.axis] = ls.sense * y0[k]
            d = {}
            for key, ys in dy.items():
                a = np.zeros_like(Y)
                a[:, ls.axis] = ls.sense * ys[k]
                d[key] = _interp(ch.time_s, t_d, a)
            Yp = _interp(ch.time_s, t_d, Y)
            channels = {ls.predicted: (Yp, d),
                        ls.drive: (_interp(ch.time_s, t_d, true),
                                   {n: _interp(ch.time_s, t_d, a) for n, a in dtrue.items()})}
            measured = [e for e in ls.entries if e.parameter not in series_drive]
            mv, md = inst_mod.measure(measured, ls.predicted, ch.time_s, Yp, d, channels, want_inst)
            mask = np.zeros(ch.values.shape, bool)
            mask[:, ls.axis] = True
            cd = {nm: md.get(targets[nm], np.zeros_like(mv)) for nm in names}
            out[po.name] = {ls.predicted: ChannelPrediction(mv, cd, mask)}
        pred = Prediction(out, {nm: methods[targets[nm]] for nm in names},
                          {po.name: ls.drive for po in observations}, {})
        fd = [nm for nm in names if methods[targets[nm]] == "central-difference"]
        if fd:
            self._central_differences(params, observations, pred, fd)
        pred.info = {"wall_s": time.perf_counter() - t0, "family": ls.family}
        self.last_info = pred.info
        return pred

    def _central_differences(self, params: ParameterSet, observations: Observations, pred: Prediction,
                             names: list[str]) -> None:
        """Parameters no route above covers (an effect that edits the description some other
        way): central differences of whole predictions, step 1e-6 of the parameter's scale."""
        for nm in names:
            p = params.param(nm)
            h = 1e-6 * max(abs(p.value), 1e-6)
            lo, hi = max(p.lower, p.value - h), min(p.upper, p.value + h)
            up = self.predict(params.with_values({nm: hi}), observations)
            dn = self.predict(params.with_values({nm: lo}), observations)
            for proto, chans in pred.protocols.items():
                for cname, cp in chans.items():
                    diff = up.protocols[proto][cname].values - dn.protocols[proto][cname].values
                    cp.d[nm] = diff / (hi - lo)


def build_lumped(spec: Mapping[str, Any], effects: Sequence[AppliedEffect] = ()) -> LumpedForwardModel:
    """The lumped forward model of a description (``[model] kind = "lumped"``) with its
    resolved ``[[effects]]`` (:func:`skinkit.forward.effects.resolve`); errors name the entry."""
    return LumpedForwardModel(spec, effects)


__all__ = ["ELASTIC", "LumpedForwardModel", "build_lumped", "simulate"]
