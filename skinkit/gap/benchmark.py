"""The withheld-effect benchmark of the gap diagnosis (issue 11, step 6).

For every effect plugin that applies to the benchmark model, at two magnitudes (near the
detection limit and moderate) and several seeds, for a few pairs of effects and for null
sessions (no effect), a virtual-lab session is made whose truth has the effect
(:class:`skinkit.inverse.coverage.LabSessions`: the truth solved once, Gaussian noise at the
lab's declared levels per seed, the drive exact), and the model *without* the effect is
diagnosed (:func:`skinkit.gap.diagnose`). The diagnoses are scored against the truth.

**Magnitudes are derived, not hand-picked.** An effect's parameters move linearly from its
null towards its typical value, p(s) = null + s (typical − null). Its *signature* is the
noiseless truth with the effect minus the truth without it, in noise units (z = Δ/σ per
sample). The part the calibration can absorb is projected out: J, the model's noise-normalised
sensitivities to its free parameters at the truth, and S(s) = |(I − J J⁺) z(s)|² is the
χ² excess the effect leaves after the fit (linearised). The detection threshold is the global
χ² test's critical excess at α = 0.05, E = χ²₁₋α(ν) − ν (ν samples less free parameters); a
magnitude is the scale s at which S(s) = k · E, with k = 2 ("near the detection limit") and
k = 30 ("moderate"), found from S(1) (s = √(kE/S(1)), since S grows as s²) and refined by
up to :data:`CALIBRATION_STEPS` steps on the real (non-linear) truth, each with the growth
exponent of S measured from the last two truths. s is capped where a parameter meets its
admissible bound; an effect whose S stays below E there is *not visible* on these protocols
(or is absorbed by the model's own parameters, e.g. a force offset when the model fits one)
and is left out, with the reason, under ``skipped``.

**Where the effect really is.** The same projected signature, grouped by the cells of
:func:`skinkit.gap.where.locate` (noiseless truth as observations, so each cell's χ² is the
signature's), gives per partition (protocol; loading/unloading/hold; first/later cycles; radial
bands; angular sectors) the cells that carry it: the fewest cells holding ≥ 75 % of the
partition's signature. A diagnosis localises correctly when its top-ranked significant cell on
the protocol, phase or region axes is one of them.

**Oracle.** The model *with* the true effect structure (all its parameters and the effect's
free), fitted from the truth, gives the shrinkage a perfect attribution would report, and the
standard errors that pick the effect's main parameter (the scaled one the oracle determines
best, largest |true − null| / se) for the magnitude error.

Scores (:func:`score`): the confusion matrix ``{true: {named or "none": count}}`` (the first
named effect; pairs under ``"a+b"`` with the named set); top-1 attribution over separable
single-effect cases at moderate magnitude; for cases the diagnosis reports not separable,
whether the truth is in the reported set of at most two; the false-alarm rate on null
sessions; localisation; the median relative magnitude error and shrinkage error against the
oracle; time per case. Rates come with Clopper–Pearson 95 % intervals.

``docs/gap-benchmark.md`` has the rules' justification and the measured figures.
"""

from __future__ import annotations

import copy
import json
import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import click
import numpy as np

from skinkit.errors import EffectError, ForwardError, SkinkitError

_DOCS = Path(__file__).resolve().parents[2] / "docs" / "models"
#: detection threshold multiples of the two magnitudes
MAGNITUDES = {"near": 2.0, "moderate": 30.0}
#: level of the global χ² test whose critical excess is the detection threshold
ALPHA = 0.05
#: truths solved at most per magnitude to bring its signature within 20 % of the target
CALIBRATION_STEPS = 6
#: share of a partition's signature that its occupied cells hold
OCCUPIED_SHARE = 0.75
#: axes on which localisation is judged
LOCAL_AXES = ("protocol", "phase", "region")
#: effects of the quick run (those of them that apply and are visible), at moderate magnitude
QUICK_EFFECTS = ("prestress", "preconditioning", "indenter-tilt", "force-drift")
QUICK_NULLS = 2
FULL_NULLS = 20
FULL_PAIRS = 3
#: version of the benchmark's definitions a journal's cases were made under (2: signatures with
#: the sessions' measured reference frame, whitened along frames; 3: points predicted as the
#: measured reference plus the model's displacement in every component, so χ² of exact-model
#: sessions is at its degrees of freedom)
DEFINITIONS = 3
#: seeds of null sessions start here (apart from the effect cases' seeds)
NULL_SEED0 = 1000


class BenchmarkError(SkinkitError):
    """A benchmark that cannot run: an unknown model preset or effect, no visible effect."""


# -- the benchmark models -----------------------------------------------------------------------
def quick_spec() -> tuple[dict[str, Any], list[str]]:
    """``docs/models/invivo_quick.toml`` coarsened as the coverage benchmark's in vivo case
    (``n_inner = 1``, one period of the four default Table 12 protocols, displacement-driven,
    flat top) and its free parameters (c, k1, κ, g1)."""
    from skinkit.bench.coverage import invivo_spec

    return invivo_spec()


def lumped_spec() -> tuple[dict[str, Any], list[str]]:
    """``docs/models/extension_relaxation_lumped.toml`` (exponential element and a force zero,
    no relaxation, no preconditioning) pulled along x by the in-plane 0° programme at 6 mm
    peak to peak (three 10 s cycles); all its parameters free (a, b, the force zero)."""
    from skinkit.fem.model import read_model

    spec = read_model(_DOCS / "extension_relaxation_lumped.toml")
    spec["session"] = {"protocols": ["in_plane_000"], "parameters": {"in_plane_000": {"peak_to_peak": 0.006}}}
    return spec, ["lumped.a", "lumped.b", "offset.x"]


PRESETS: dict[str, Callable[[], tuple[dict[str, Any], list[str]]]] = {"quick": quick_spec,
                                                                      "lumped": lumped_spec}


def model_spec(model: str | Mapping[str, Any] | None) -> tuple[dict[str, Any], list[str] | None]:
    """The benchmark model's description (no ``[[effects]]``) and its free parameters (None:
    every parameter the model declares). ``model``: a preset (``"quick"``, ``"lumped"``), a
    model file, or a parsed description; a file's truth gets a flat top (``[surface] fit = false``)."""
    if model is None:
        model = "quick"
    if isinstance(model, str) and model in PRESETS:
        spec, free = PRESETS[model]()
        return _plain(spec), free
    if isinstance(model, Mapping):
        spec = copy.deepcopy(dict(model))
    else:
        from skinkit.forward import read_description

        path = Path(model)
        if not path.is_file():
            raise BenchmarkError(f"--model: {model!r} is neither a preset ({', '.join(PRESETS)}) "
                                 "nor a model file")
        spec = read_description(path)
    spec.pop("load", None)
    if "lumped" not in spec:
        spec.setdefault("surface", {})["fit"] = False
    return _plain(spec), None


def _plain(spec: dict[str, Any]) -> dict[str, Any]:
    spec = copy.deepcopy(spec)
    spec.pop("effects", None)
    return spec


def _with_effects(spec: Mapping[str, Any], effects: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    out = copy.deepcopy(dict(spec))
    if effects:
        out["effects"] = [dict(e) for e in effects]
    return out


# -- per-process caches (a worker keeps its truths and its base model's sensitivities) -----------
_LABS: dict[str, Any] = {}
_BASES: dict[str, Any] = {}


def _key(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, default=str)


def _lab(spec: Mapping[str, Any]) -> Any:
    """:class:`~skinkit.inverse.coverage.LabSessions` of ``spec``, solved once per process."""
    from skinkit.inverse.coverage import LabSessions

    k = _key(spec)
    if k not in _LABS:
        if len(_LABS) > 16:          # keep a worker's memory bounded on long runs
            _LABS.clear()
        _LABS[k] = LabSessions(spec)
    return _LABS[k]


def _noiseless(lab: Any) -> Any:
    """The lab's noiseless truth as observations at the declared noise levels, the points'
    reference as the sessions have it: with a measured reference (the lab's default) the
    noiseless frame 0 is the reference frame, so that the signature is the one a session shows
    (whitened along frames, a distortion of the tracker seen in the reference too)."""
    from skinkit.lab.session import top_surface
    from skinkit.schemas import Channel, Observations, ProtocolObservations

    sensors = lab.truth.sensors
    surface = top_surface(lab.spec, lab.kind)
    ref = surface.track_reference() if (lab.kind == "fe" and surface.has_mesh) else None
    measured = getattr(lab, "reference", "exact") == "measured"
    out = {}
    for p in lab.truth.planned:
        true = lab.truth.noiseless[p.protocol.name]
        chans = {c: Channel(c, p.time_s, np.asarray(true[c], float), noise=sensors.sigma(c),
                            noise_source="virtual lab (declared)") for c in ("tip_position", "tip_force")}
        if "points" in true and ref is not None:
            v = np.asarray(true["points"], float)
            r0, f0 = (v[:, 0].copy(), 0) if measured else (ref.copy(), None)
            chans["points"] = Channel("points", p.frames, v, noise=sensors.sigma("points"),
                                      noise_source="tracker", reference=r0, reference_frame=f0)
        out[p.protocol.name] = ProtocolObservations(p.protocol, chans)
    return Observations(out, None, "virtual lab, noiseless")


def _references(obs: Any) -> list[np.ndarray]:
    return [c.reference for po in obs for c in po.channels.values() if c.is_points]


class _Base:
    """The model without effects at the truth: its noiseless prediction and noise-normalised
    sensitivities to the free parameters (one sensitivity pass), and their projector."""

    def __init__(self, spec: Mapping[str, Any], free: Sequence[str] | None,
                 workers: int | None = None) -> None:
        from skinkit.forward import load

        self.lab = _lab(spec)
        self.model = load(self.lab.model_spec, workers=workers)
        params = self.model.parameters()
        self.free = list(free) if free is not None else list(params.free_names)
        self.obs = _noiseless(self.lab)
        self.pred = self.model.predict(params, self.obs, sensitivities=self.free)
        res = self._objective(self.obs).residual(self.pred, jacobian=True)
        self.n = int(res.z.size)
        J = res.J
        scale = np.linalg.norm(J, axis=0)
        J = J[:, scale > 0] / scale[scale > 0]
        u, sv, _ = np.linalg.svd(J, full_matrices=False)
        self.Q = u[:, sv > 1e-9 * (sv[0] if sv.size else 1.0)]
        self.dof = self.n - len(self.free)
        from scipy.stats import chi2

        self.critical_excess = float(chi2.ppf(1 - ALPHA, self.dof) - self.dof)

    def _objective(self, obs: Any) -> Any:
        from skinkit.inverse.objective import Objective

        return Objective(self.model, obs, self.free)

    def signature(self, lab: Any) -> dict[str, Any]:
        """The truth ``lab``'s signature against this model: raw and projected χ² (noise units),
        and the cells each partition's projected signature occupies."""
        from skinkit.gap.where import locate
        from skinkit.schemas import ChannelPrediction, Prediction

        obs = _noiseless(lab)
        pred = self.pred
        same = zip(_references(obs), _references(self.obs), strict=True)
        if not all(np.array_equal(a, b) for a, b in same):
            # the truth's reference differs (a tracker's distortion seen in frame 0): the model
            # tracks the material points the session's reference names
            pred = self.model.predict(self.model.parameters(), obs)
        res = self._objective(obs).residual(pred, jacobian=False)
        z = res.z
        zp = z - self.Q @ (self.Q.T @ z)
        protos: dict[str, dict[str, Any]] = {}
        for (p, c, sl) in res.blocks:
            ch = obs[p].channels[c]
            cp = pred.protocols[p][c]
            m = cp.mask(ch)
            v = np.array(ch.values, float)
            sig = np.broadcast_to(ch.noise, v.shape)
            a = np.zeros(v.shape)
            a[m] = zp[sl]
            # pred' − Y = σ W⁻¹ z': the residual that whitens to the projected signature
            v[m] = v[m] + (sig * ch.unwhiten(a, m))[m]
            protos.setdefault(p, {})[c] = ChannelPrediction(v, predicted=cp.predicted)
        loc = locate(obs, Prediction(protos, inputs=dict(pred.inputs)))
        return {"raw": float(z @ z), "projected": float(zp @ zp), "cells": _occupied(loc.cells)}


_IN_POOL = [False]


def _mark_worker() -> None:
    _IN_POOL[0] = True


def _task_done(payload: Mapping[str, Any]) -> None:
    """In a pool worker, a cached FE model with its own worker processes is closed after each
    task: a nested pool left open keeps the worker from exiting when the benchmark's pool shuts
    down (measured: the run hung after its last case)."""
    if _IN_POOL[0] and payload.get("workers") != 1:
        release()


def release() -> None:
    """Close the cached base models (an FE model with worker processes keeps a pool: a worker
    of the benchmark's own pool that still holds one does not exit at shutdown) and clear the caches."""
    for b in _BASES.values():
        if hasattr(b.model, "close"):
            b.model.close()
    _BASES.clear()
    _LABS.clear()


def _base(spec: Mapping[str, Any], free: Sequence[str] | None, workers: int | None = None) -> _Base:
    k = _key([spec, free])
    if k not in _BASES:
        _BASES[k] = _Base(spec, free, workers)
    return _BASES[k]


def _occupied(cells: Sequence[Any]) -> dict[str, list[str]]:
    """Per ``axis/partition`` on the localisation axes: the fewest cells holding
    :data:`OCCUPIED_SHARE` of the partition's signature χ²."""
    parts: dict[str, list[Any]] = {}
    for c in cells:
        if c.axis in LOCAL_AXES:
            parts.setdefault(f"{c.axis}/{c.partition or c.axis}", []).append(c)
    out: dict[str, list[str]] = {}
    for key, cs in parts.items():
        total = sum(max(c.chi2, 0.0) for c in cs)
        if not total > 0:
            continue
        got, acc = [], 0.0
        for c in sorted(cs, key=lambda c: -c.chi2):
            got.append(c.label)
            acc += c.chi2
            if acc >= OCCUPIED_SHARE * total:
                break
        out[key] = got
    return out


# -- magnitudes ---------------------------------------------------------------------------------
def _plugin_values(name: str) -> tuple[dict[str, float], dict[str, float], dict[str, tuple[float, float]]]:
    from skinkit.forward.effects import effect_plugin

    plugin = effect_plugin(name, "--effects")
    params = plugin.parameters()
    typical = {p.name: float(p.value) for p in params}
    null = {k: float(v) for k, v in plugin.null().items()}
    bounds = {p.name: (float(p.lower), float(p.upper)) for p in params}
    return typical, null, bounds


def effect_at(name: str, s: float) -> dict[str, Any]:
    """The ``[[effects]]`` table of effect ``name`` at scale ``s``: null + s (typical − null)."""
    typical, null, _ = _plugin_values(name)
    return {"name": name, **{k: null.get(k, v) + s * (v - null.get(k, v)) for k, v in typical.items()}}


def _max_scale(name: str, limit: float = 20.0) -> float:
    """The largest scale keeping every scaled parameter inside its admissible bounds (≤ ``limit``)."""
    typical, null, bounds = _plugin_values(name)
    s = limit
    for k, v in typical.items():
        d = v - null.get(k, v)
        lo, hi = bounds[k]
        if d > 0 and math.isfinite(hi):
            s = min(s, 0.999 * (hi - null[k]) / d)
        elif d < 0 and math.isfinite(lo):
            s = min(s, 0.999 * (lo - null[k]) / d)
    return s


def calibrate(payload: Mapping[str, Any]) -> dict[str, Any]:
    """One effect's magnitudes (a task: ``payload`` has ``spec``, ``free``, ``effect``,
    ``magnitudes`` {label: multiple of the detection threshold}, ``workers``). Returns per
    magnitude the scale, the ``[[effects]]`` table, the projected signature and its cells, or
    why the effect is left out (``skipped``)."""
    try:
        return _calibrate(payload)
    finally:
        _task_done(payload)


def _calibrate(payload: Mapping[str, Any]) -> dict[str, Any]:
    name = payload["effect"]
    t0 = time.perf_counter()
    base = _base(payload["spec"], payload["free"], payload.get("workers"))
    crit = base.critical_excess
    out: dict[str, Any] = {"effect": name, "critical_excess": crit, "dof": base.dof, "magnitudes": {}}

    def sig(s: float) -> dict[str, Any]:
        lab = _lab(_with_effects(payload["spec"], [effect_at(name, s)]))
        return base.signature(lab)

    try:
        s_max = _max_scale(name)
        first = sig(1.0 if s_max >= 1.0 else s_max)
        s1 = 1.0 if s_max >= 1.0 else s_max
    except (EffectError, ForwardError) as exc:
        out["skipped"] = f"not applicable: {exc}"
        return out
    except SkinkitError as exc:
        out["skipped"] = f"the truth with it cannot be solved: {exc}"
        return out
    out["typical"] = {"scale": s1, "raw": first["raw"], "projected": first["projected"]}
    for label, k in payload["magnitudes"].items():
        target = k * crit
        s, got = s1, first
        prev: tuple[float, float] | None = None
        for _ in range(CALIBRATION_STEPS):
            if got["projected"] <= 0:
                break
            if abs(got["projected"] / target - 1) < 0.2:
                break
            # S ∝ s^p: p = 2 to first order, then the slope in log-log of the last two truths
            # (an effect whose signature saturates, e.g. a support going from fixed to soft,
            # has p well below 2 and the s² rule alone would not reach its target)
            p = 2.0
            if prev is not None and prev[1] > 0 and prev[0] != s:
                slope = math.log(got["projected"] / prev[1]) / math.log(s / prev[0])
                p = min(max(slope, 0.25), 4.0)
            s_new = min(s * (target / got["projected"]) ** (1 / p), s_max)
            if s_new == s:
                break
            prev = (s, got["projected"])
            s = s_new
            try:
                got = sig(s)
            except SkinkitError as exc:
                out["skipped"] = f"the truth at scale {s:.3g} cannot be solved: {exc}"
                return out
        if got["projected"] < crit:
            out["skipped"] = (f"not visible: its signature left after the fit, {got['projected']:.3g} "
                              f"(noise units²), stays below the detection threshold {crit:.3g} "
                              f"up to scale {s:.3g}")
            return out
        # the projection is a linearised fit: an effect the model's own parameters express
        # exactly but non-linearly (a second Prony term at the skin's own τ) still leaves its
        # curvature there, so a real fit to the noiseless truth has the last word
        fitted = _fitted_excess(base, payload, effect_at(name, s))
        if fitted < crit:
            out["skipped"] = (f"absorbed: a fit of the model to the noiseless truth at scale {s:.3g} leaves "
                              f"{fitted:.3g} (noise units²), below the detection threshold {crit:.3g} "
                              f"(the linearised signature, {got['projected']:.3g}, is curvature the model's "
                              "own parameters take up)")
            return out
        out["magnitudes"][label] = {"scale": s, "effect": effect_at(name, s), "target": target,
                                    "raw": got["raw"], "projected": got["projected"], "fitted": fitted,
                                    "multiple": got["projected"] / crit, "capped": s >= s_max,
                                    "cells": got["cells"]}
    out["wall_s"] = time.perf_counter() - t0
    return out


def _fitted_excess(base: _Base, payload: Mapping[str, Any], effect: Mapping[str, Any]) -> float:
    """χ² (noise units²) the model without the effect (``base``: its lab and free parameters)
    leaves when fitted, from the truth's values, to the noiseless truth with ``effect``: the
    excess a session would show at most, beyond noise."""
    obs = _noiseless(_lab(_with_effects(payload["spec"], [effect])))
    return _oracle(base.lab, obs, base.free, [], payload.get("workers"))["chi2"]


# -- one case -----------------------------------------------------------------------------------
def _diagnose(spec: Mapping[str, Any], obs: Any, free: Sequence[str] | None,
              workers: int | None, options: Mapping[str, Any]) -> dict[str, Any]:
    from skinkit.gap.diagnose import diagnose

    # truth and model share one mesh by construction: the discretisation check would find
    # nothing and cost a refined solve per case (it has its own test, test_discretisation_gap)
    opts = {"error_estimate": False, **dict(options)}
    return diagnose(spec, obs, free=None if free is None else list(free), workers=workers, **opts).to_dict()


def _oracle(lab: Any, obs: Any, free: Sequence[str], effects: Sequence[Mapping[str, Any]],
            workers: int | None) -> dict[str, Any]:
    """The model with the truth's structure fitted from the truth: χ², dof, estimates and se."""
    from skinkit.forward import load
    from skinkit.inverse.fit import fit

    model = load(lab.model_spec, workers=workers)
    try:
        names = list(free) + [f"{e['name']}.{k}" for e in effects for k in e if k != "name"]
        r = fit(model, obs, names)
        n = sum(int(cp.mask(obs[p].channels[c]).sum())
                for p, c, cp in model.predict(r.parameters, obs).items())
        return {"chi2": float(r.chi2_per_dof) * (n - len(names)), "dof": n - len(names),
                "estimates": {k: float(r.parameters[k]) for k in names},
                "se": {k: float(r.se.get(k, math.nan)) for k in names}, "converged": bool(r.converged),
                "n_forward": int(r.n_forward)}
    finally:
        if hasattr(model, "close"):
            model.close()


def _shrinkage(before_chi2: float, before_dof: float, after_chi2: float, after_dof: float, *,
               clip: bool = True) -> float:
    """Fraction of the excess residual removed, as the diagnosis reports it:
    ((χ²_b − ν_b) − (χ²_a − ν_a)) / (χ²_b − ν_b), at most 1 unless ``clip`` is false (NaN without
    an excess). Unclipped, a refit that ends below ν by noise reads a little above 1."""
    excess = before_chi2 - before_dof
    if not excess > 0:
        return math.nan
    frac = (excess - (after_chi2 - after_dof)) / excess
    return float(min(frac, 1.0) if clip else frac)


def run_case(payload: Mapping[str, Any]) -> dict[str, Any]:
    """One benchmark case (a task): ``payload`` has ``id``, ``kind`` (``effect``, ``pair``,
    ``null``), ``magnitude``, ``effects`` (``[[effects]]`` tables of the truth), ``seed``,
    ``spec``, ``free``, ``workers``. Returns the JSON-ready record :func:`score` reads."""
    t0 = time.perf_counter()
    effects = list(payload["effects"])
    rec: dict[str, Any] = {k: payload[k] for k in ("id", "kind", "magnitude", "seed")}
    rec["truth"] = [e["name"] for e in effects]
    rec["truth_parameters"] = {f"{e['name']}.{k}": v for e in effects for k, v in e.items() if k != "name"}
    try:
        base = _base(payload["spec"], payload["free"], payload.get("workers"))
        lab = _lab(_with_effects(payload["spec"], effects))
        obs = lab(int(payload["seed"]))
        if effects:
            s = base.signature(lab)
            rec["signature"] = {"raw": s["raw"], "projected": s["projected"],
                                "multiple": s["projected"] / base.critical_excess}
            rec["true_cells"] = s["cells"]
        td = time.perf_counter()
        rep = _diagnose(base.lab.model_spec, obs, base.free, payload.get("workers"),
                        payload.get("diagnose", {}))
        rec["diagnose_s"] = time.perf_counter() - td
        rec["report"] = _slim(rep)
        if effects:
            rec["oracle"] = _oracle(lab, obs, base.free, effects, payload.get("workers"))
            rec["n_samples"] = base.n
    except SkinkitError as exc:
        rec["error"] = str(exc)
    rec["wall_s"] = time.perf_counter() - t0
    _task_done(payload)
    return rec


def _slim(rep: Mapping[str, Any]) -> dict[str, Any]:
    """The parts of a diagnosis the scores read (the full report is large)."""
    gap = rep.get("gap", {}) or {}
    cells = list(gap.get("cells", []) or [])
    size: dict[tuple[str, str], int] = {}
    for c in cells:
        k = (c.get("axis"), c.get("partition") or c.get("axis"))
        size[k] = size.get(k, 0) + 1
    keep = [dict(c, partition_size=size[(c.get("axis"), c.get("partition") or c.get("axis"))])
            for c in cells if c.get("significant")]
    return {"named": list(rep.get("named", []) or []), "fit": rep.get("fit", {}),
            "gap": {"significant": gap.get("significant"), "chi2_per_dof": gap.get("chi2_per_dof"),
                    "cells": keep, "gate": gap.get("gate")},
            "candidates": rep.get("candidates", []), "chi2": rep.get("chi2", {}),
            "shrinkage": {k: v for k, v in (rep.get("shrinkage") or {}).items() if k != "cells"},
            "rounds": [{"named": r.get("named"), "candidates": r.get("candidates", [])}
                       for r in rep.get("rounds", []) or [] if isinstance(r, Mapping)]}


# -- scores -------------------------------------------------------------------------------------
def clopper_pearson(k: int, n: int, mass: float = 0.95) -> list[float] | None:
    """Exact central ``mass`` interval of a binomial proportion k/n (None when n = 0)."""
    from scipy.stats import beta

    if n <= 0:
        return None
    a = (1 - mass) / 2
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a, k + 1, n - k))
    return [lo, hi]


def _rate(k: int, n: int) -> dict[str, Any]:
    return {"k": k, "n": n, "rate": (k / n) if n else None, "interval_95": clopper_pearson(k, n)}


def _candidate(rep: Mapping[str, Any], name: str) -> dict[str, Any] | None:
    for c in rep.get("candidates", []):
        if c.get("effect") == name:
            return c
    for r in rep.get("rounds", []) or []:
        for c in (r.get("candidates", []) if isinstance(r, dict) else []):
            if c.get("effect") == name:
                return c
    return None


def _top_cell(rep: Mapping[str, Any]) -> dict[str, Any] | None:
    """The diagnosis's top-ranked significant cell on :data:`LOCAL_AXES` (largest share), in a
    partition of more than one cell (a one-cell partition, e.g. the only protocol, says nothing)."""
    cells = [c for c in rep["gap"]["cells"] if c.get("significant") and c.get("axis") in LOCAL_AXES
             and c.get("partition_size", 2) > 1]
    if not cells:
        return None
    return max(cells, key=lambda c: (c.get("share") or 0.0, c.get("chi2_per_dof") or 0.0))


def _label_numbers(label: str) -> list[float]:
    import re

    return [float(x) for x in re.findall(r"-?\d+(?:\.\d+)?", label)]


def _in_cells(cell: Mapping[str, Any], true_cells: Mapping[str, list[str]]) -> bool:
    """Is the diagnosis's ``cell`` one of the truth's occupied cells? Region labels are matched
    by their numbers when the edges differ by rounding (measured against exact references)."""
    axis, label = cell["axis"], cell["label"]
    keys = [k for k in true_cells if k.split("/")[0] == axis]
    if any(label in true_cells[k] for k in keys):
        return True
    if axis != "region":
        return False
    nums = _label_numbers(label)
    word = label.split(" ")[0]
    for k in keys:
        for t in true_cells[k]:
            tn = _label_numbers(t)
            if t.split(" ")[0] == word and len(tn) == len(nums) and np.allclose(tn, nums, atol=0.15):
                return True
    return False


def _main_parameter(rec: Mapping[str, Any], effect: str) -> str | None:
    """The scaled parameter of ``effect`` the oracle determines best (largest |true − null|/se)."""
    _, null, _ = _plugin_values(effect)
    se = rec.get("oracle", {}).get("se", {})
    best, score_ = None, -1.0
    for k, v in rec["truth_parameters"].items():
        eff, _, local = k.partition(".")
        if eff != effect or abs(v - null.get(local, v)) == 0:
            continue
        s = se.get(k, math.nan)
        sc = abs(v - null[local]) / s if (s and math.isfinite(s) and s > 0) else 0.0
        if sc > score_:
            best, score_ = k, sc
    return best


def _estimate(cand: Mapping[str, Any] | None, full: str) -> float | None:
    pars = (cand or {}).get("parameters") or {}
    local = full.partition(".")[2]
    for key in (full, local):
        if key in pars:
            v = pars[key]
            v = v.get("value") if isinstance(v, Mapping) else v
            return None if v is None else float(v)
    return None


def assess(rec: Mapping[str, Any]) -> dict[str, Any]:
    """One case's verdicts: attribution, reported set, false alarm, localisation, magnitude and
    shrinkage errors (JSON-ready; missing when not applicable)."""
    out: dict[str, Any] = {}
    if "error" in rec:
        return {"failed": True}
    rep = rec["report"]
    named = list(rep["named"])
    truth = list(rec["truth"])
    out["named"] = named
    if not truth:
        out["false_alarm"] = bool(named)
        out["gap_significant"] = bool((rep.get("gap") or {}).get("significant"))
        return out
    first = named[0] if named else None
    reported = [first, *((_candidate(rep, first) or {}).get("not_separable_from") or [])] if first else []
    true_cand = _candidate(rep, truth[0]) or {}
    separable = (len(reported) <= 1) if first else not (true_cand.get("not_separable_from") or [])
    out["separable"] = separable
    out["reported_set"] = reported
    orc, c2 = rec.get("oracle"), rep.get("chi2") or {}
    if orc and c2.get("before") is not None:
        # what the true structure gains over the fitted model on this session: when not even
        # the oracle's refit improves χ² beyond noise, the session does not show the effect (the
        # model's own parameters express it), and no diagnosis could attribute it
        from scipy.stats import chi2 as chi2_dist

        k = int(round(float(c2["dof_before"]) - float(orc["dof"])))
        gain = float(c2["before"]) - float(orc["chi2"])
        out["oracle_gain"] = {"chi2": gain, "dof": k}
        out["visible"] = not (k > 0 and gain <= float(chi2_dist.ppf(1 - ALPHA, k)))
    if rec["kind"] == "effect":
        out["top1"] = first == truth[0]
        out["in_set"] = truth[0] in reported and len(reported) <= 2
    else:
        out["all_named"] = set(truth) <= set(named)
        out["any_named"] = bool(set(truth) & set(named))
    top = _top_cell(rep)
    if top is not None:
        out["top_cell"] = f"{top['axis']}: {top['label']}"
        out["localised"] = _in_cells(top, rec.get("true_cells", {}))
        part = f"{top['axis']}/{top.get('partition') or top['axis']}"
        occupied = rec.get("true_cells", {}).get(part)
        if occupied is not None and top.get("partition_size"):
            # the hit rate of a cell drawn at random from the partition: the metric's chance level
            out["localisation_chance"] = len(occupied) / top["partition_size"]
    if rec["kind"] == "effect" and first == truth[0]:
        main = _main_parameter(rec, truth[0])
        if main is not None:
            _, null, _ = _plugin_values(truth[0])
            true = rec["truth_parameters"][main]
            est = _estimate(true_cand, main)
            if est is not None:
                d = true - null[main.partition(".")[2]]
                out["magnitude"] = {"parameter": main, "truth": true, "estimate": est,
                                    "relative_error": (est - true) / d}
    shr = (rep.get("shrinkage") or {}).get("overall")
    orc = rec.get("oracle")
    c2 = rep.get("chi2") or {}
    if named and shr is not None and orc and c2.get("before") is not None:
        oracle = _shrinkage(float(c2["before"]), float(c2["dof_before"]), orc["chi2"], orc["dof"])
        if math.isfinite(oracle) and oracle > 0:
            out["shrinkage"] = {"reported": float(shr), "oracle": oracle,
                                "relative_error": (float(shr) - oracle) / oracle}
            if c2.get("after") is not None:
                # both clip to 1 once refit and oracle reach the noise, which hides how close the
                # refit came to the oracle; the unclipped pair still tells them apart
                args = (float(c2["before"]), float(c2["dof_before"]))
                rep_u = _shrinkage(*args, float(c2["after"]), float(c2["dof_after"]), clip=False)
                orc_u = _shrinkage(*args, orc["chi2"], orc["dof"], clip=False)
                out["shrinkage"].update(reported_unclipped=rep_u, oracle_unclipped=orc_u,
                                        unclipped_error=(rep_u - orc_u) / orc_u)
    return out


def score(records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The benchmark's figures from the case records of :func:`run_case` (JSON-ready)."""
    verdicts = [assess(r) for r in records]
    confusion: dict[str, dict[str, int]] = {}
    for r, v in zip(records, verdicts, strict=True):
        if v.get("failed"):
            continue
        key = "+".join(sorted(r["truth"])) or "none"
        if r["kind"] == "pair":
            got = "+".join(sorted(v["named"])) or "none"
        else:
            got = v["named"][0] if v["named"] else "none"
        row = confusion.setdefault(key, {})
        row[got] = row.get(got, 0) + 1

    def pick(kind: str, magnitude: str | None = None) -> list[tuple[Mapping[str, Any], dict[str, Any]]]:
        # cases whose session did not show the effect (``visible`` false) are counted apart
        return [(r, v) for r, v in zip(records, verdicts, strict=True)
                if r["kind"] == kind and not v.get("failed") and v.get("visible", True)
                and (magnitude is None or r["magnitude"] == magnitude)]

    out: dict[str, Any] = {}
    by_mag: dict[str, Any] = {}
    for mag in MAGNITUDES:
        sel = pick("effect", mag)
        sep = [v for _, v in sel if v["separable"]]
        non = [v for _, v in sel if not v["separable"]]
        by_mag[mag] = {"cases": len(sel),
                       "top1": _rate(sum(v["top1"] for v in sep), len(sep)),
                       "in_reported_set": _rate(sum(v["in_set"] for v in non), len(non)),
                       "named_any": _rate(sum(bool(v["named"]) for _, v in sel), len(sel))}
    mod = by_mag["moderate"]
    out["top1_accuracy"] = mod["top1"]["rate"]
    out["top1"] = mod["top1"]
    out["not_separable_in_set_rate"] = mod["in_reported_set"]["rate"]
    out["by_magnitude"] = by_mag
    nulls = pick("null")
    fa = _rate(sum(v["false_alarm"] for _, v in nulls), len(nulls))
    out["null_false_alarm_rate"] = fa["rate"]
    out["null_false_alarm"] = fa
    # the report's "significant gap" on sessions the model describes: its gate's level, ALPHA
    out["null_gap_significant"] = _rate(sum(v["gap_significant"] for _, v in nulls), len(nulls))
    pairs = pick("pair")
    out["pairs"] = {"both_named": _rate(sum(v["all_named"] for _, v in pairs), len(pairs)),
                    "one_named": _rate(sum(v["any_named"] for _, v in pairs), len(pairs))}
    loc = [v for kind in ("effect", "pair") for _, v in pick(kind) if "localised" in v]
    out["localisation"] = _rate(sum(v["localised"] for v in loc), len(loc))
    out["localisation_accuracy"] = out["localisation"]["rate"]
    chance = [v["localisation_chance"] for v in loc if "localisation_chance" in v]
    out["localisation"]["chance_mean"] = float(np.mean(chance)) if chance else None
    out["localisation"]["no_significant_cell"] = sum(
        1 for kind in ("effect", "pair") for _, v in pick(kind) if "localised" not in v)
    mags = [abs(v["magnitude"]["relative_error"]) for _, v in pick("effect", "moderate") if "magnitude" in v]
    out["magnitude_error_median"] = float(np.median(mags)) if mags else None
    out["magnitude_errors"] = {"n": len(mags), "within_15_percent": sum(m <= 0.15 for m in mags)}
    shr = [abs(v["shrinkage"]["relative_error"]) for _, v in pick("effect", "moderate") if "shrinkage" in v]
    out["shrinkage_error_median"] = float(np.median(shr)) if shr else None
    out["shrinkage_errors"] = {"n": len(shr), "within_15_percent": sum(s <= 0.15 for s in shr)}
    shr_u = [abs(v["shrinkage"]["unclipped_error"]) for _, v in pick("effect", "moderate")
             if "unclipped_error" in v.get("shrinkage", {})]
    out["shrinkage_errors"].update(unclipped_median=float(np.median(shr_u)) if shr_u else None,
                                   unclipped_max=float(np.max(shr_u)) if shr_u else None)
    out["confusion"] = confusion
    out["not_visible"] = [{"id": r["id"], "named": v["named"], "oracle_gain": v["oracle_gain"]}
                          for r, v in zip(records, verdicts, strict=True)
                          if not v.get("failed") and v.get("visible") is False]
    walls = [r["wall_s"] for r in records]
    out["case_wall_s"] = {"median": float(np.median(walls)) if walls else None,
                          "max": float(np.max(walls)) if walls else None}
    out["failed"] = [{"id": r["id"], "error": r["error"]} for r in records if "error" in r]
    out["verdicts"] = {r["id"]: v for r, v in zip(records, verdicts, strict=True)}
    return out


# -- planning and running -----------------------------------------------------------------------
def plan(calibrations: Sequence[Mapping[str, Any]], *, magnitudes: Sequence[str], seeds: int, nulls: int,
         pairs: int) -> list[dict[str, Any]]:
    """The cases: every calibrated effect × magnitude × seed, ``pairs`` pairs of effects at
    moderate magnitude (neighbours in the list of effects, one seed), ``nulls`` null sessions."""
    cases: list[dict[str, Any]] = []
    ok = [c for c in calibrations if "skipped" not in c]
    for c in ok:
        for mag in magnitudes:
            m = c["magnitudes"].get(mag)
            if m is None:
                continue
            for seed in range(seeds):
                cases.append({"id": f"{c['effect']}/{mag}/{seed}", "kind": "effect", "magnitude": mag,
                              "effects": [m["effect"]], "seed": seed})
    usable = [c for c in ok if "moderate" in c["magnitudes"]]
    for i in range(min(pairs, len(usable) // 2)):
        a, b = usable[2 * i], usable[2 * i + 1]
        cases.append({"id": f"{a['effect']}+{b['effect']}/moderate/0", "kind": "pair",
                      "magnitude": "moderate", "seed": 0,
                      "effects": [x["magnitudes"]["moderate"]["effect"] for x in (a, b)]})
    for i in range(nulls):
        cases.append({"id": f"null/{NULL_SEED0 + i}", "kind": "null", "magnitude": None, "effects": [],
                      "seed": NULL_SEED0 + i})
    return cases


def execution_order(cases: Sequence[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """``cases`` in the order they run: seed by seed (a run stopped part-way has whole seeds),
    within a seed pairs, then moderate, then near (the longest first: the pool's tail is short),
    the null sessions after the first seed."""
    def key(c: Mapping[str, Any]) -> tuple[int, int]:
        if c["kind"] == "null":
            return (0, 3)
        rank = {"pair": 0, "moderate": 1}.get(c["kind"] if c["kind"] == "pair" else c["magnitude"], 2)
        return (int(c["seed"]) if int(c["seed"]) == 0 else int(c["seed"]) + 1, rank)

    return sorted(cases, key=key)


class _Pool:
    """Tasks run in this process (``parallel <= 1``), in a pool of processes, or on a Dask cluster."""

    def __init__(self, parallel: int, scheduler: str | None) -> None:
        self.client = self.executor = None
        if scheduler:
            from dask.distributed import Client

            self.client = Client(scheduler)
        elif parallel > 1:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            self.executor = ProcessPoolExecutor(parallel, mp_context=multiprocessing.get_context("spawn"),
                                                initializer=_mark_worker)

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any], done: Callable[[Any], None]) -> list[Any]:
        """``fn`` over ``items`` (results in the items' order); ``done(result)`` as each finishes."""
        if self.client is not None:
            from dask.distributed import as_completed

            futs = [self.client.submit(fn, it, pure=False) for it in items]
            index = {f.key: i for i, f in enumerate(futs)}
            out: list[Any] = [None] * len(items)
            for f in as_completed(futs):
                out[index[f.key]] = r = f.result()
                done(r)
            return out
        if self.executor is not None:
            from concurrent.futures import as_completed as done_order

            futs = {self.executor.submit(fn, it): i for i, it in enumerate(items)}
            out = [None] * len(items)
            for f in done_order(futs):
                out[futs[f]] = r = f.result()
                done(r)
            return out
        res = []
        for it in items:
            res.append(fn(it))
            done(res[-1])
        return res

    def close(self) -> None:
        if self.executor is not None:
            self.executor.shutdown()
        if self.client is not None:
            self.client.close()


def _open_journal(journal: str | os.PathLike[str] | None, settings: Mapping[str, Any],
                  say: Callable[[str], None]) -> Any:
    if journal is None:
        return None
    from skinkit.gap.journal import Journal

    jr = Journal(journal, settings)
    if jr.cases or jr.calibrations:
        say(f"journal {journal}: {len(jr.calibrations)} calibrations and {len(jr.cases)} cases recorded")
    return jr


def _calibrations(pool: _Pool, tasks: Sequence[Mapping[str, Any]], jr: Any,
                  say: Callable[[str], None], recorded_only: bool = False) -> list[dict[str, Any]]:
    """The calibrations of ``tasks`` (one per effect, in order): from the journal ``jr`` when it
    holds them, else run on ``pool`` (and recorded) — or left out (``recorded_only``)."""
    def cal_line(c: Mapping[str, Any]) -> None:
        if "skipped" in c:
            say(f"calibrate {c['effect']}: skipped ({c['skipped']})")
        else:
            scales = ", ".join(f"{m} x{v['scale']:.3g} ({v['multiple']:.1f} thresholds)"
                               for m, v in c["magnitudes"].items())
            say(f"calibrate {c['effect']}: {scales}, {c.get('wall_s', 0):.1f} s")
        if jr is not None:
            jr.add_calibration(c)

    known = {} if jr is None else jr.calibrations
    todo = [] if recorded_only else [t for t in tasks if t["effect"] not in known]
    new = {c["effect"]: c for c in pool.map(calibrate, todo, cal_line)}
    return [new[t["effect"]] if t["effect"] in new else known[t["effect"]] for t in tasks
            if t["effect"] in new or t["effect"] in known]


def _run_cases(pool: _Pool, payloads: Sequence[Mapping[str, Any]], jr: Any,
               say: Callable[[str], None], recorded_only: bool = False) -> tuple[list[dict[str, Any]], int]:
    """The records of ``payloads`` in their order, and how many came from the journal ``jr``;
    the others run on ``pool`` in :func:`execution_order`, each recorded as it finishes (or,
    ``recorded_only``, are left out)."""
    known = {} if jr is None else jr.cases
    before = {p["id"]: known[p["id"]] for p in payloads if p["id"] in known}
    if recorded_only:
        return [before[p["id"]] for p in payloads if p["id"] in before], len(before)
    todo = execution_order([p for p in payloads if p["id"] not in before])
    n_done = [len(before)]

    def case_line(r: Mapping[str, Any]) -> None:
        n_done[0] += 1
        named = "error" not in r and ", ".join(r["report"]["named"])
        what = f"error: {r['error']}" if "error" in r else f"named {named or 'none'}"
        say(f"case {n_done[0]}/{len(payloads)} {r['id']}: {what}, {r['wall_s']:.1f} s")
        if jr is not None:
            jr.add_case(r)

    if before:
        say(f"{len(before)} of {len(payloads)} cases from the journal, {len(todo)} to run")
    fresh = {r["id"]: r for r in pool.map(run_case, todo, case_line)}
    return [before[p["id"]] if p["id"] in before else fresh[p["id"]] for p in payloads], len(before)


def run(quick: bool, scheduler: str | None = None, workers: int | None = None, seeds: int | None = None,
        progress: Callable[[str], None] | None = None, *, model: str | Mapping[str, Any] | None = None,
        effects: Sequence[str] | None = None, nulls: int | None = None, pairs: int | None = None,
        magnitudes: Sequence[str] | None = None, parallel: int | None = None,
        max_effects: int | None = None, candidates: int | None = None,
        journal: str | os.PathLike[str] | None = None, recorded_only: bool = False) -> dict[str, Any]:
    """Run the benchmark and score it (JSON-ready).

    ``quick``: the quick run (:data:`QUICK_EFFECTS` that apply and are visible, moderate
    magnitude only, one seed, :data:`QUICK_NULLS` null sessions, no pairs); otherwise every
    applicable effect at both magnitudes, ``seeds`` seeds (default 3), :data:`FULL_PAIRS` pairs
    and :data:`FULL_NULLS` null sessions. ``model``: a preset (``"quick"``: the coarse in vivo
    model, the default; ``"lumped"``), a model file or a description. ``effects``: restrict the
    truths to these. ``scheduler``: a Dask scheduler address (one task per case);
    ``parallel``: worker processes otherwise (default 2; 1 runs in this process); ``workers``:
    worker processes of each FE prediction (default 1 when cases run in parallel, else
    one per protocol up to the CPU count). ``progress(line)``: one line per calibrated effect
    and per case. ``max_effects`` (default 1 quick, 2 full) and ``candidates`` (refits per round,
    default 2 quick, 3 full) go to each :func:`~skinkit.gap.diagnose.diagnose`. ``journal``: a
    file (:mod:`skinkit.gap.journal`) that records each calibration and case as it finishes; the
    ones it already holds are not run again (resuming a stopped run, or adding seeds or null
    sessions to a finished one); ``recorded_only``: run nothing, score the planned cases the
    journal holds (``planned_cases`` says how many were planned). Cases run seed by seed (a
    stopped run has whole seeds), longest first within a seed, null sessions after the first
    seed. Keys:
    ``top1_accuracy``, ``null_false_alarm_rate``, ``localisation_accuracy``,
    ``magnitude_error_median``, ``shrinkage_error_median``, ``confusion``, ``cases`` (the
    records), ``wall_s``, and the details of :func:`score`, ``calibration``, ``skipped``.
    """
    from skinkit.forward import model_kind
    from skinkit.forward.visibility import applicable_effects

    t0 = time.perf_counter()
    say = progress or (lambda line: None)
    spec, free = model_spec(model)
    kind = model_kind(spec)
    names = applicable_effects(kind)
    if effects is not None:
        unknown = sorted(set(effects) - set(names))
        if unknown:
            raise BenchmarkError(f"--effects: {', '.join(unknown)} not installed or not applicable to a "
                                 f"{kind} model (applicable: {', '.join(names)})")
        names = [n for n in names if n in set(effects)]
    elif quick:
        names = [n for n in QUICK_EFFECTS if n in names] or names[:4]
    mags = list(magnitudes) if magnitudes is not None else (["moderate"] if quick else list(MAGNITUDES))
    bad = sorted(set(mags) - set(MAGNITUDES))
    if bad:
        raise BenchmarkError(f"magnitudes: unknown {bad}; choose from {list(MAGNITUDES)}")
    seeds = (1 if quick else 3) if seeds is None else int(seeds)
    nulls = (QUICK_NULLS if quick else FULL_NULLS) if nulls is None else int(nulls)
    pairs = (0 if quick else FULL_PAIRS) if pairs is None else int(pairs)
    parallel = 2 if parallel is None else int(parallel)
    if workers is None and (parallel > 1 or scheduler):
        workers = 1          # the cases are the parallel unit: one process per FE prediction
    opts = {"max_effects": (1 if quick else 2) if max_effects is None else int(max_effects),
            "candidates": (2 if quick else 3) if candidates is None else int(candidates)}
    if recorded_only and journal is None:
        raise BenchmarkError("--recorded-only scores a journal's cases: give --journal FILE")
    if recorded_only and not Path(journal).is_file():
        raise BenchmarkError(f"--recorded-only: journal {journal} does not exist")
    jr = _open_journal(journal, {"model": spec, "free": free, "magnitudes": {m: MAGNITUDES[m] for m in mags},
                                 "diagnose": opts, "alpha": ALPHA, "definitions": DEFINITIONS}, say)
    pool = _Pool(1, None) if recorded_only else _Pool(parallel, scheduler)
    try:
        cals = _calibrations(pool, [{"spec": spec, "free": free, "effect": n, "workers": workers,
                                     "magnitudes": {m: MAGNITUDES[m] for m in mags}} for n in names], jr, say,
                             recorded_only)
        cases = plan(cals, magnitudes=mags, seeds=seeds, nulls=nulls, pairs=pairs)
        if not any(c["kind"] != "null" for c in cases) and names:
            say("no effect is visible on these protocols: only null sessions run")
        payloads = [dict(c, spec=spec, free=free, workers=workers, diagnose=opts) for c in cases]
        records, n_resumed = _run_cases(pool, payloads, jr, say, recorded_only)
    finally:
        pool.close()
        release()
    out = score(records)
    out.update({"model": spec.get("model", {}).get("name"), "kind": kind, "quick": bool(quick),
                "free": free, "effects": names, "magnitudes": {m: MAGNITUDES[m] for m in mags},
                "occupied_share": OCCUPIED_SHARE, "alpha": ALPHA, "diagnose_options": opts,
                "calibration": {c["effect"]: c for c in cals},
                "skipped": {c["effect"]: c["skipped"] for c in cals if "skipped" in c},
                "cases": records, "wall_s": time.perf_counter() - t0,
                "resumed_cases": n_resumed, "planned_cases": len(payloads)})
    return out


# -- command ------------------------------------------------------------------------------------
def _summary_lines(res: Mapping[str, Any]) -> list[str]:
    def pct(r: Mapping[str, Any]) -> str:
        if not r["n"]:
            return "-"
        lo, hi = r["interval_95"]
        return f"{100 * r['rate']:.0f} % ({r['k']}/{r['n']}; 95 % CI {100 * lo:.0f}-{100 * hi:.0f} %)"

    def num(x: Any) -> str:
        return "-" if x is None else f"{100 * x:.1f} %"

    lines = [f"model {res['model']} ({res['kind']}), {len(res['cases'])} of {res['planned_cases']} planned "
             f"cases, {res['wall_s'] / 60:.1f} min",
             f"top-1 attribution (separable, moderate): {pct(res['top1'])}",
             f"truth in the reported set (not separable, moderate): "
             f"{pct(res['by_magnitude']['moderate']['in_reported_set'])}",
             f"false alarms on null sessions: {pct(res['null_false_alarm'])}",
             f"'significant gap' on null sessions (level {100 * res['alpha']:.0f} %): "
             f"{pct(res['null_gap_significant'])}",
             f"localisation: {pct(res['localisation'])}",
             f"magnitude error (median |relative|, moderate): {num(res['magnitude_error_median'])}",
             f"shrinkage error vs oracle (median |relative|, moderate): {num(res['shrinkage_error_median'])}"
             f" (unclipped: median {num(res['shrinkage_errors'].get('unclipped_median'))}, "
             f"max {num(res['shrinkage_errors'].get('unclipped_max'))})",
             f"time per case: median {res['case_wall_s']['median'] or 0:.1f} s, "
             f"max {res['case_wall_s']['max'] or 0:.1f} s"]
    if res["by_magnitude"].get("near", {}).get("cases"):
        lines.append("near the detection limit: named something in "
                     f"{pct(res['by_magnitude']['near']['named_any'])}")
    for e, why in res["skipped"].items():
        lines.append(f"skipped {e}: {why}")
    for c in res.get("not_visible", []):
        g = c["oracle_gain"]
        lines.append(f"not counted {c['id']}: the session does not show it (the true structure's refit gains "
                     f"χ² {g['chi2']:.3g} on {g['dof']} parameters, within noise); named "
                     f"{', '.join(c['named']) or 'none'}")
    lines.append("confusion (true -> named):")
    for t, row in sorted(res["confusion"].items()):
        ranked = sorted(row.items(), key=lambda kv: -kv[1])
        lines.append(f"  {t}: " + ", ".join(f"{k} {v}" for k, v in ranked))
    return lines


def _names(text: str | None) -> list[str] | None:
    if text is None:
        return None
    out = [s.strip() for s in text.split(",") if s.strip()]
    if not out:
        raise BenchmarkError("--effects: no effect named")
    return out


@click.command("benchmark")
@click.option("--quick", is_flag=True, help="the quick run (a handful of effects at moderate magnitude, "
              "two null sessions; measured time in docs/gap-benchmark.md)")
@click.option("--scheduler", default=None, metavar="ADDRESS", help="run the cases on this Dask scheduler")
@click.option("--json", "as_json", is_flag=True, help="print JSON (progress lines go to stderr)")
@click.option("--seeds", type=click.IntRange(1), default=None, help="seeds per effect and magnitude "
              "(default 1 quick, 3 full)")
@click.option("--effects", default=None, metavar="NAME,...", help="only these effects in the truths")
@click.option("--model", default="quick", show_default=True,
              help="preset (quick: coarse in vivo; lumped: extension-relaxation) or a model file")
@click.option("--nulls", type=click.IntRange(0), default=None,
              help="null sessions (default 2 quick, 20 full)")
@click.option("--parallel", type=click.IntRange(1), default=2, show_default=True,
              help="cases run at once (worker processes; without --scheduler)")
@click.option("--journal", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="record each finished case in FILE (JSON lines) and skip the cases it already "
              "holds: resume a stopped run, or add seeds or null sessions to a finished one")
@click.option("--recorded-only", is_flag=True, help="run nothing: score the cases the --journal holds "
              "(a run under way or stopped)")
def benchmark(quick: bool, scheduler: str | None, as_json: bool, seeds: int | None, effects: str | None,
              model: str, nulls: int | None, parallel: int, journal: str | None, recorded_only: bool) -> None:
    """Withheld-effect benchmark: diagnose virtual sessions whose truth has an effect the model lacks."""
    res = run(quick, scheduler=scheduler, seeds=seeds, progress=lambda s: click.echo(s, err=True),
              model=model, effects=_names(effects), nulls=nulls, parallel=parallel, journal=journal,
              recorded_only=recorded_only)
    if as_json:
        click.echo(json.dumps(res, indent=1, default=float))
        return
    for line in _summary_lines(res):
        click.echo(line)


__all__ = ["ALPHA", "MAGNITUDES", "BenchmarkError", "assess", "benchmark", "calibrate", "clopper_pearson",
           "effect_at", "execution_order", "lumped_spec", "model_spec", "plan", "quick_spec", "release",
           "run", "run_case", "score"]
