"""Experimental design: which extra protocol would best pin down the current fit (D-optimality).

With noise-weighted residuals z (standard normals under the noise model) the Fisher
information of the free parameters is F = JᵀJ, J = ∂z/∂θ, and the Cramér–Rao covariance of the
estimate is F⁻¹ (thesis Eqs 7.15–7.16). Independent protocols add their information, so a
candidate protocol c with noise-weighted Jacobian J_c would bring

    gain(c) = log det(F + J_cᵀJ_c) − log det F        (D-optimality; thesis future work)

— minus twice the log of the factor by which the volume of the confidence ellipsoid shrinks —
and per parameter the standard error √[(F + J_cᵀJ_c)⁻¹]ᵢᵢ against √[F⁻¹]ᵢᵢ.

* F comes from the session's fitted protocols at ``params`` (a fit's optimum, or the model's
  values), J_c from the model's own sensitivities on a **noiseless skeleton** of the
  candidate: the library's programme (:func:`skinkit.lab.session.plan_protocol`), laid out
  like a virtual-lab session (:func:`skinkit.lab.session.skeleton`) but with *this* session's
  noise levels, sampling interval and tracked points, so the candidate's information is
  what it would add to this session.
* Coordinates: the scaled ones of the fit (:mod:`skinkit.inverse.scaling`). The gain is
  invariant to a diagonal rescaling (the log dets shift by the same constant); scaling
  matters only for the **ridge**: ε = :data:`RIDGE` times the identity is added to every
  information matrix, a Gaussian prior of standard deviation 1/√ε = 10⁵ scaled units
  (10⁵ times a parameter's bound range, or decades, or its value), far wider than anything
  the data allow, so it changes nothing when F is regular and keeps log det F finite when
  the current protocols leave a direction undetermined (then the gain of a candidate that
  determines it is large but finite: ≈ log(λ_c/ε)). An unbounded free parameter whose value
  is 0 is scaled by one SI unit (:mod:`skinkit.inverse.scaling`); give it a typical nonzero
  value when its SI unit is far from its magnitude.
* A candidate drives the model with its programme's channel. A model driven by the other
  channel (a force-driven FE model on a trajectory protocol) is driven by what the
  programme would produce: a twin of the model driven by the programme predicts that
  channel first (as the session would record it), then the model predicts the rest.
  A candidate the model cannot be driven by (a dynamic lumped model on a trajectory) is
  listed as not applicable, with the reason.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError
from skinkit.inverse.fit import free_set
from skinkit.inverse.objective import Objective
from skinkit.inverse.scaling import Scaling
from skinkit.schemas import Channel, Observations, ParameterSet, ProtocolObservations

#: ridge added to every information matrix in scaled coordinates (module docstring)
RIDGE = 1e-10
#: a scaled standard error above this is "not determined" by the current protocols: the
#: ridge (prior) then carries more than 1 % of the information along that parameter
UNDETERMINED_SCALED_SE = 0.1 / math.sqrt(RIDGE)

Candidate = str | tuple[str, Mapping[str, Any]]


class DesignError(SkinkitError):
    """A design request that cannot run: unknown candidates, no free parameter, no applicable protocol."""


# -- candidates --------------------------------------------------------------------------------
def default_candidates(model: Any) -> list[str]:
    """Library protocols a model of this kind is driven by: the Table 12 trajectories for a
    finite-element or quasi-static lumped model, the force programmes for a dynamic lumped one."""
    from skinkit.acquisition.library import catalogue

    spec = getattr(model, "spec", None)
    family = getattr(spec, "family", "quasi-static")
    dynamic = getattr(model, "kind", "fe") == "lumped" and family != "quasi-static"
    want = "force" if dynamic else "trajectory"
    return [p.name for p in catalogue() if p.kind == want and p.name != "preconditioning"]


def _normalise(candidates: Sequence[Candidate] | None, model: Any) -> list[tuple[str, dict[str, Any]]]:
    from skinkit.acquisition.library import names as known

    items = default_candidates(model) if candidates is None else list(candidates)
    out = []
    for c in items:
        name, pars = (c, {}) if isinstance(c, str) else (str(c[0]), dict(c[1]))
        if name not in known():
            raise DesignError(f"--candidates: unknown protocol {name!r}; the library has "
                              f"{', '.join(known())}")
        out.append((name, pars))
    if not out:
        raise DesignError("--candidates: no candidate protocol named")
    return out


def parse_candidates(text: str | None) -> list[str] | None:
    """``"a,b"`` as ``["a", "b"]`` (None: the default candidates)."""
    if text is None:
        return None
    items = [s.strip() for s in text.split(",") if s.strip()]
    if not items:
        raise DesignError(f"--candidates {text!r}: no protocol named")
    return items


def _protocol_parameters(model: Any, name: str, given: Mapping[str, Any]) -> dict[str, Any]:
    """Parameters a candidate runs with, as the virtual lab would: an FE model's affordable
    force programme, the model file's ``[session.parameters.<name>]``, then ``given``."""
    from skinkit.acquisition.library import make_protocol
    from skinkit.lab.session import FE_FORCE_PARAMETERS

    out: dict[str, Any] = {}
    if getattr(model, "kind", "fe") == "fe" and make_protocol(name).kind == "force":
        out.update(FE_FORCE_PARAMETERS)
    base = dict(getattr(model, "base", {}) or {})
    table = dict(dict(base.get("session", {}) or {}).get("parameters", {}) or {})
    out.update(dict(table.get(name, {}) or {}))
    out.update(given)
    return out


# -- the session's layout ----------------------------------------------------------------------
def _layout(obs: Observations) -> dict[str, Any]:
    """Noise per channel (median over protocols, per component), the tip channels' sampling
    interval [s], and the tracked points' reference layout of ``obs``."""
    noise: dict[str, list[np.ndarray]] = {}
    dts: list[float] = []
    points = None
    for po in obs:
        for c in po.channels.values():
            noise.setdefault(c.name, []).append(c.noise)
            if not c.is_points and c.time_s.size > 1:
                dts.append(float(np.median(np.diff(c.time_s))))
            if c.is_points and points is None and c.reference is not None:
                points = c
    return {"noise": {k: np.median(np.stack(v), axis=0) for k, v in noise.items()},
            "dt": float(np.median(dts)) if dts else None, "points": points}


def candidate_observations(model: Any, observations: Observations, name: str,
                           parameters: Mapping[str, Any] | None = None) -> tuple[Observations, str]:
    """A noiseless skeleton of library protocol ``name`` laid out like ``observations``
    (module docstring) and the channel its programme drives (``"tip_position"`` or
    ``"tip_force"``). The drive channel holds the programme (skin frame); the others are
    placeholders to be predicted."""
    from skinkit.lab.sensors import LOG_RATE_HZ, SensorModel
    from skinkit.lab.session import plan_protocol, skeleton

    lay = _layout(observations)
    planned = plan_protocol(name, _protocol_parameters(model, name, parameters or {}))
    if lay["dt"] is not None:   # the session's sampling: information grows with the number of samples
        step = max(1, int(round(lay["dt"] * LOG_RATE_HZ)))
        planned.time_s = planned.time_s[::step]
        planned.drive_robot = planned.drive_robot[::step]
    pts: Channel | None = lay["points"]
    reference = pts.reference if pts is not None else None
    sk = skeleton([planned], SensorModel(), reference, observations.profile)
    po = sk[name]
    chans: dict[str, Channel] = {}
    for cname, ch in po.channels.items():
        if cname == "points" and pts is not None and pts.name == "points_2d":
            cname = "points_2d"
        if cname not in lay["noise"]:
            continue   # the session does not measure it: neither would the candidate
        vals = ch.values[..., :2] if cname == "points_2d" else ch.values
        frame = pts.reference_frame if (ch.is_points and pts is not None) else None
        chans[cname] = Channel(cname, ch.time_s, vals, noise=lay["noise"][cname],
                               noise_source="session", reference=ch.reference, reference_frame=frame,
                               window_m=pts.window_m if (ch.is_points and pts is not None) else None)
    for need in ("tip_position", "tip_force"):
        if need not in chans and need in po.channels:   # the drive and the prediction need both
            chans[need] = po.channels[need]
    return Observations({name: ProtocolObservations(po.protocol, chans)}, observations.profile,
                        f"design candidate {name}"), planned.drive


def _model_drive(model: Any) -> str | None:
    """The channel that drives ``model`` (None when it does not say)."""
    if getattr(model, "kind", None) == "lumped":
        return str(model.spec.drive)
    base = getattr(model, "base", None)
    if getattr(model, "kind", None) == "fe" and isinstance(base, Mapping):
        mode = str(dict(base.get("indenter", {}) or {}).get("mode", "force"))
        return "tip_force" if mode == "force" else "tip_position"
    return None


def _twin(model: Any, drive: str) -> Any | None:
    """A copy of ``model`` driven by ``drive`` (None: the model cannot be)."""
    spec = copy.deepcopy(dict(getattr(model, "base", {}) or {}))
    if getattr(model, "kind", None) == "fe":
        spec.setdefault("indenter", {})["mode"] = "displacement" if drive == "tip_position" else "force"
        return type(model)(spec, model.effects, workers=getattr(model, "workers", None))
    if getattr(model, "kind", None) == "lumped" and model.spec.family == "quasi-static":
        spec.setdefault("lumped", {})["drive"] = drive
        return type(model)(spec, model.effects)
    return None


def _drive_with(model: Any, params: ParameterSet, obs: Observations, drive: str) -> Observations:
    """``obs`` with the channel that drives ``model`` filled with what the programme's
    ``drive`` would produce (predicted by a twin driven by ``drive``)."""
    own = _model_drive(model)
    if own is None or own == drive:
        return obs
    twin = _twin(model, drive)
    if twin is None:
        raise DesignError(f"the model is driven by {own} and cannot be driven by this programme's {drive}")
    try:
        pred = twin.predict(params, obs)
    finally:
        if twin is not model:
            twin.close()
    po = next(iter(obs))
    chans = dict(po.channels)
    cp = pred.protocols[po.name].get(own)
    if cp is None:
        raise DesignError(f"the model's twin driven by {drive} does not predict {own}")
    ch = chans[own]
    vals = np.where(np.isfinite(cp.values), cp.values, 0.0)
    chans[own] = Channel(own, ch.time_s, vals, noise=ch.noise, noise_source=ch.noise_source)
    return Observations({po.name: ProtocolObservations(po.protocol, chans)}, obs.profile, obs.source)


# -- information -------------------------------------------------------------------------------
def _logdet(A: np.ndarray) -> float:
    sign, val = np.linalg.slogdet(A)
    return float(val) if sign > 0 else -math.inf


def information(model: Any, observations: Observations, params: ParameterSet, free: Sequence[str],
                scaling: Scaling) -> tuple[np.ndarray, int]:
    """``(F, m)``: the noise-weighted Fisher information ``(n, n)`` of ``free`` in ``scaling``'s
    coordinates from one prediction with sensitivities on ``observations``, and the number
    of residual samples ``m``."""
    obj = Objective(model, observations, list(free), "noise")
    res, _ = obj.evaluate(params, jacobian=True)
    D = scaling.dvalue_dscaled(scaling.to_scaled(np.array([params[n] for n in free])))
    J = res.J * D[None, :]
    return J.T @ J, int(res.z.size)


def rank_protocols(model: Any, observations: Observations,
                   params: ParameterSet | Mapping[str, float] | None = None,
                   free: Sequence[str] | None = None, candidates: Sequence[Candidate] | None = None, *,
                   progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Rank candidate protocols by the D-optimal gain they would bring (module docstring).

    ``observations``: the session (its fitted protocols give F); ``params``: where to
    linearise (a ParameterSet, or values overriding the model's; default the model's);
    ``free``: the parameters to pin down (default those free in ``params``); ``candidates``:
    library names, or ``(name, parameters)`` pairs (default :func:`default_candidates`).

    Returns a JSON-ready dict: ``free``, ``current`` (per parameter ``value``, ``se`` [SI],
    ``determined``; ``logdet``, ``singular``), ``ranking`` (best first; per candidate
    ``protocol``, ``label`` (with the parameters given), ``parameters`` (as run), ``drive``,
    ``gain``, ``samples``, ``se_after``, ``se_reduction`` (fraction),
    ``pins_down``, ``message``), ``not_applicable`` (``protocol``, ``reason``), ``ridge``.
    """
    base = model.parameters()
    if params is None:
        pset = base
    elif isinstance(params, ParameterSet):
        pset = params
    else:
        unknown = sorted(set(params) - set(base.names))
        if unknown:
            raise DesignError(f"--at: the model has no parameter(s) {unknown}")
        pset = base.with_values(dict(params))
    pset = free_set(pset, list(free) if free is not None else None)
    names = pset.free_names
    if not names:
        raise DesignError(f"model {getattr(model, 'name', '?')!r} has no free parameter to design for; "
                          "name some with --free")
    cands = _normalise(candidates, model)
    fitted = observations.fitted()
    if not len(fitted):
        raise DesignError("session: every protocol is held out; the current information needs fitted "
                          "protocols")
    sc = Scaling.for_parameters(pset, names)
    say = progress or (lambda _m: None)
    say(f"information of the session's {len(fitted)} fitted protocol(s)")
    F, m0 = information(model, fitted, pset, names, sc)
    n = len(names)
    R = RIDGE * np.eye(n)
    C0 = np.linalg.inv(F + R)
    D = sc.dvalue_dscaled(sc.to_scaled(pset.free_vector()))
    se0_scaled = np.sqrt(np.diag(C0))
    se0 = se0_scaled * D
    ld0 = _logdet(F + R)
    current = {nm: {"value": pset[nm], "unit": pset.param(nm).unit, "se": float(se0[i]),
                    "determined": bool(se0_scaled[i] < UNDETERMINED_SCALED_SE)} for i, nm in enumerate(names)}
    rows, skipped = [], []
    for k, (cname, cpars) in enumerate(cands, 1):
        say(f"candidate {k}/{len(cands)}: {cname}")
        try:
            obs_c, drive = candidate_observations(model, observations, cname, cpars)
            obs_c = _drive_with(model, pset, obs_c, drive)
            G, mc = information(model, obs_c, pset, names, sc)
        except SkinkitError as exc:
            skipped.append({"protocol": cname, "reason": str(exc)})
            continue
        C1 = np.linalg.inv(F + G + R)
        se1 = np.sqrt(np.diag(C1)) * D
        red = 1.0 - se1 / se0
        gain = _logdet(F + G + R) - ld0
        label = cname + (f"({', '.join(f'{k}={v:g}' for k, v in cpars.items())})" if cpars else "")
        rows.append({"protocol": cname, "label": label,
                     "parameters": _protocol_parameters(model, cname, cpars), "drive": drive,
                     "gain": float(gain), "samples": mc,
                     "se_after": {nm: float(se1[i]) for i, nm in enumerate(names)},
                     "se_reduction": {nm: float(red[i]) for i, nm in enumerate(names)}})
    if not rows:
        reasons = "; ".join(f"{s['protocol']}: {s['reason']}" for s in skipped)
        raise DesignError(f"no candidate protocol of the library applies to model "
                          f"{getattr(model, 'name', '?')!r} ({reasons})")
    rows.sort(key=lambda r: -r["gain"])
    for rank, r in enumerate(rows, 1):
        r["rank"] = rank
        r["pins_down"], r["message"] = _words(r, current)
    weak = max(names, key=lambda nm: current[nm]["se"] / max(abs(current[nm]["value"]), 1e-300)
               if current[nm]["value"] != 0 else math.inf)
    return {"model": getattr(model, "name", "model"), "free": names, "ridge": RIDGE,
            "current": {"parameters": current, "logdet": ld0, "samples": m0,
                        "singular": bool(np.linalg.matrix_rank(F, tol=RIDGE) < n), "weakest": weak},
            "ranking": rows, "not_applicable": skipped}


def _words(row: dict[str, Any], current: dict[str, Any]) -> tuple[str | None, str]:
    """Which parameter a candidate pins down, in words."""
    red = row["se_reduction"]
    best = max(red, key=lambda nm: red[nm])
    if row["gain"] < 1e-6 or red[best] < 1e-3:
        return None, (f"{row['label']}: adds (almost) nothing (log det gain {row['gain']:.3g}); it does "
                      "not move the free parameters")
    c = current[best]
    unit = "" if c["unit"] in ("1", "") else f" {c['unit']}"
    if not c["determined"]:
        what = f"determines {best}, which the current protocols leave undetermined " \
               f"(standard error {row['se_after'][best]:.3g}{unit})"
    else:
        what = (f"pins down {best}: standard error {c['se']:.3g} -> {row['se_after'][best]:.3g}{unit} "
                f"({100 * red[best]:.0f} % smaller)")
    others = [f"{nm} {100 * r:.0f} %" for nm, r in sorted(red.items(), key=lambda kv: -kv[1])
              if nm != best and r >= 0.01]
    tail = f"; also {', '.join(others)}" if others else ""
    return best, f"{row['label']}: log det gain {row['gain']:.3g}; {what}{tail}"


def format_ranking(result: dict[str, Any], top: int | None = None) -> list[str]:
    """:func:`rank_protocols`'s result as text lines (the CLI's output)."""
    cur = result["current"]
    lines = [f"current fit ({len(result['free'])} free, {cur['samples']} samples): weakest {cur['weakest']}"]
    for nm, c in cur["parameters"].items():
        state = "" if c["determined"] else "  (not determined)"
        lines.append(f"  {nm:28s} {c['value']:.6g} ± {c['se']:.2g} {c['unit']}{state}")
    names = result["free"]
    w = max([24] + [len(r["label"]) for r in result["ranking"]])
    head = f"{'rank':>4}  {'protocol':{w}s} {'gain':>9}  " + "  ".join(f"{('-SE ' + n)[:14]:>14s}"
                                                                       for n in names)
    lines += ["", head]
    rows = result["ranking"][:top] if top else result["ranking"]
    for r in rows:
        lines.append(f"{r['rank']:>4}  {r['label']:{w}s} {r['gain']:>9.4g}  "
                     + "  ".join(f"{100 * r['se_reduction'][n]:>13.1f}%" for n in names))
    lines.append("")
    lines += [r["message"] for r in result["ranking"][:3]]
    for s in result["not_applicable"]:
        lines.append(f"not applicable: {s['protocol']}: {s['reason']}")
    return lines


__all__ = ["RIDGE", "DesignError", "candidate_observations", "default_candidates", "format_ranking",
           "information", "parse_candidates", "rank_protocols"]
