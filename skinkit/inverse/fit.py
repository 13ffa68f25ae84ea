"""Fitting a forward model's free parameters to a session: weighted least squares with the
model's analytic Jacobian, in scaled coordinates, with honest uncertainty.

Each iteration asks the forward model for its predictions *and* their sensitivities to the
free parameters in one pass (direct differentiation: one back-substitution per parameter
and step, not one solve per parameter as finite differences need); the optimiser plugin
(default ``scipy-lsq``, trust-region reflective) gets residual and Jacobian together.
Stopping rules of the thesis (7.6): the relative change of the objective below ``ftol``
(1e-6) or the scaled step below ``xtol`` (1e-3). A forward solve that fails during a fit
(a step into a region where the model cannot be solved) is answered with a residual the
optimiser rejects, so that it shrinks its step — never a traceback.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from skinkit import jsonio, registry
from skinkit.errors import PluginError, SkinkitError
from skinkit.inverse.identifiability import analyse
from skinkit.inverse.objective import Objective, Residual, held_out_rms
from skinkit.inverse.scaling import Scaling
from skinkit.schemas import FitResult, Observations, ParameterSet
from skinkit.schemas.parameters import bound_entries
from skinkit.schemas.results import SE_NOT_A_NUMBER, SE_UNDETERMINED
from skinkit.units import format_quantity, unit_suffix


class FitError(SkinkitError):
    """A fit that cannot start: a free parameter the model lacks, bounds, a start outside them."""


def free_set(params: ParameterSet, free: Sequence[str] | None) -> ParameterSet:
    """``params`` with exactly ``free`` free (None: as the model declares them)."""
    if free is None:
        return params
    unknown = sorted(set(free) - set(params.names))
    if unknown:
        raise FitError(f"--free: the model has no parameter(s) {unknown}; it has {params.names}")
    if not free:
        raise FitError("--free: no free parameter; name at least one")
    from dataclasses import replace
    return ParameterSet(replace(p, free=p.name in set(free)) for p in params)


def with_bounds(params: ParameterSet, bounds: dict[str, tuple[float, float]]) -> ParameterSet:
    """``params`` with the fit's own bounds (name -> (lower, upper) [SI]) inside the admissible ones."""
    from dataclasses import replace
    out = {}
    for name, (lo, hi) in bounds.items():
        if name not in params:
            raise FitError(f"--bounds: the model has no parameter {name!r}; it has {params.names}")
        p = params.param(name)
        if not lo < hi:
            raise FitError(f"--bounds {name}: inverted or empty, lower {lo:g} >= upper "
                           f"{format_quantity(hi, p.unit)}")
        if lo < p.lower or hi > p.upper:
            raise FitError(f"--bounds {name}: [{lo:g}, {hi:g}]{unit_suffix(p.unit)} leaves the admissible "
                           f"range [{p.lower:g}, {p.upper:g}]")
        value = min(max(p.value, lo), hi)
        out[name] = replace(p, lower=lo, upper=hi, value=value)
    return ParameterSet(out.get(p.name, p) for p in params)


def aic(chi2: float, n: int, k: int) -> tuple[float, float]:
    """AIC and AICc of a fit with Σz² = ``chi2`` over ``n`` observations and ``k`` free
    parameters: Eq 7.14, AIC = n ln(SSE/n) + 2(k + 1), and the small-sample correction."""
    a = n * np.log(max(chi2, 1e-300) / n) + 2 * (k + 1)
    c = a + 2 * (k + 1) * (k + 2) / max(n - k - 2, 1)
    return float(a), float(c)


#: scaled points this close (every coordinate; the scaled parameters are of order one) are one
#: evaluation: far below what a forward solve's convergence tolerance resolves
SAME_POINT = 1e-9


class _Evaluations:
    """Every evaluation of a fit, kept by its scaled point; optionally on disk.

    With a ``directory``, each completed evaluation is written there atomically (one ``.npz``
    each), so a fit killed at any moment and run again with the same directory replays the
    evaluations already made — the deterministic optimiser retraces its path at no solve cost
    and continues where it was stopped, to the same optimum.
    """

    def __init__(self, directory: Path | None) -> None:
        self.directory = directory
        self.table: dict[bytes, dict[str, Any]] = {}
        if directory is None:
            return
        directory.mkdir(parents=True, exist_ok=True)
        for f in sorted(directory.glob("eval-*.npz")):
            try:
                with np.load(f) as d:
                    rec = {k: d[k] for k in d.files}
            except (OSError, ValueError, EOFError):
                continue   # a file cut by the kill: that evaluation is simply redone
            self.table[rec["x"].tobytes()] = {"z": rec["z"], "J": rec["J"] if rec["J"].size else None,
                                              "ok": bool(rec["ok"]), "error": str(rec["error"]),
                                              "blocks": json.loads(str(rec["blocks"])), "from_disk": True}

    def get(self, x: np.ndarray) -> dict[str, Any] | None:
        x = np.asarray(x, float)
        rec = self.table.get(x.tobytes())
        if rec is not None:
            return rec
        # an optimiser that moves a start lying on a bound strictly inside it (by ~1e-10 of the
        # scale: scipy's trust-region reflective) asks again for the point just evaluated
        for key, r in self.table.items():
            xs = np.frombuffer(key)
            if xs.shape == x.shape and float(np.max(np.abs(xs - x), initial=0.0)) <= SAME_POINT:
                return r
        return None

    def put(self, x: np.ndarray, rec: dict[str, Any]) -> None:
        x = np.asarray(x, float)
        self.table[x.tobytes()] = rec
        if self.directory is None:
            return
        k = len(list(self.directory.glob("eval-*.npz")))
        path = self.directory / f"eval-{k:05d}.npz"
        tmp = self.directory / f".eval-{k:05d}.part.npz"
        J = rec["J"] if rec["J"] is not None else np.zeros(0)
        np.savez(tmp, x=x, z=rec["z"], J=J, ok=rec["ok"], error=rec.get("error", ""),
                 blocks=jsonio.dumps(rec.get("blocks", [])))
        os.replace(tmp, path)


class _FitRun:
    """The evaluations of one fit: each scaled point's residual and Jacobian, asked of the
    checkpoint first, and the history the fit reports.

    ``z`` and ``J`` are the weighted residual ``(m,)`` and its derivative in scaled
    coordinates ``(m, n_free)``; a point the model cannot solve has a NaN residual."""

    def __init__(self, params: ParameterSet, obj: Objective, sc: Scaling, evals: _Evaluations,
                 use_jac: bool, progress: Callable[[int, float, dict[str, float]], None] | None) -> None:
        self.params, self.obj, self.sc, self.evals = params, obj, sc, evals
        self.names = params.free_names
        self.use_jac = use_jac
        self.progress = progress
        self.history: list[dict[str, Any]] = []
        self.n_replayed = 0
        self.m: int | None = None   # residual size, known after the first solved evaluation

    def at(self, x: np.ndarray, need_jac: bool | None = None) -> dict[str, Any]:
        """The evaluation at scaled point ``x``: replayed from the checkpoint, or solved."""
        need_jac = self.use_jac if need_jac is None else need_jac
        rec = self.evals.get(x)
        if rec is not None and (rec["J"] is not None or not need_jac or not rec["ok"]):
            if rec.pop("from_disk", False):   # an evaluation made before the fit was stopped
                self.n_replayed += 1
                self._record(x, rec, replayed=True)
            return rec
        rec = self._solve(x, need_jac)
        self.evals.put(x, rec)
        self._record(x, rec, replayed=False)
        return rec

    def _solve(self, x: np.ndarray, need_jac: bool) -> dict[str, Any]:
        pset = self.params.with_free_vector(self.sc.to_values(x))
        try:
            res, _ = self.obj.evaluate(pset, jacobian=need_jac)
            J = res.J * self.sc.dvalue_dscaled(x)[None, :] if need_jac else None
            rec = {"z": res.z, "J": J, "ok": True, "error": "",
                   "blocks": [(p, c, sl.start, sl.stop) for p, c, sl in res.blocks]}
            self.m = res.z.size
            return rec
        except (SkinkitError, ArithmeticError) as exc:
            if self.m is None:
                raise FitError(f"the model cannot be solved at the start of the fit "
                               f"({_describe(pset, self.names)}): {exc}"
                               f"{_component_hint(self.obj.model, self.obj.observations)}") from None
            # not a penalty: a non-finite residual makes the optimiser reject the step and shrink it
            return {"z": np.full(self.m, np.nan), "J": np.zeros((self.m, len(self.names))), "ok": False,
                    "error": str(exc), "blocks": []}

    def _record(self, x: np.ndarray, rec: dict[str, Any], replayed: bool) -> None:
        phi = 0.5 * float(rec["z"] @ rec["z"]) if rec["ok"] else float("nan")
        values = self.sc.to_values(x)
        self.history.append({"x": values.tolist(), "x_scaled": np.asarray(x, float).tolist(),
                             "objective": phi, "solved": rec["ok"], "replayed": replayed,
                             **({"error": rec["error"]} if not rec["ok"] else {})})
        if self.m is None:
            self.m = rec["z"].size
        if self.progress is not None:
            self.progress(len(self.history), phi, dict(zip(self.names, values.tolist(), strict=True)))


def _optimiser(optimiser: str, use_jac: bool) -> Any:
    """The optimiser plugin ``optimiser``, refused when it needs a Jacobian the fit does not give."""
    try:
        opt = registry.create("skinkit.optimisers", optimiser)
    except PluginError as exc:
        raise FitError(f"--optimiser {optimiser!r}: {exc}") from None
    if getattr(opt, "needs_gradient", False) and not use_jac:
        raise FitError(f"--optimiser {optimiser!r} is gradient-based: it needs the analytic Jacobian")
    return opt


def _minimise(run: _FitRun, opt: Any, optimiser: str, options: dict[str, Any]) -> Any:
    """Run the optimiser from the fit's start (which must be solvable) within the scaled bounds."""
    x0 = run.sc.to_scaled(run.params.free_vector())
    lo, hi = run.sc.bounds()
    run.at(x0)   # the start must be solvable
    try:
        return opt.minimise(lambda x: run.at(x)["z"], x0, lo, hi,
                            jac=(lambda x: run.at(x)["J"]) if run.use_jac else None, options=options)
    except ValueError as exc:   # an optimiser refusing the problem (bounds it cannot search, ...)
        raise FitError(f"--optimiser {optimiser!r}: {exc}") from None


def fit(model: Any, observations: Observations, free: Sequence[str] | None = None, *,
        weighting: str = "noise", optimiser: str = "scipy-lsq", start: dict[str, float] | None = None,
        ftol: float = 1e-6, xtol: float = 1e-3, max_iterations: int = 50, jacobian: str = "analytic",
        checkpoint: str | os.PathLike[str] | None = None,
        bounds: dict[str, tuple[float, float]] | None = None,
        progress: Callable[[int, float, dict[str, float]], None] | None = None) -> FitResult:
    """Fit ``free`` parameters of ``model`` to the non-held-out protocols of ``observations``.

    ``weighting``: one of :data:`skinkit.inverse.WEIGHTINGS`. ``optimiser``: a
    ``skinkit.optimisers`` plugin. Stopping rules (thesis 7.6): relative change of the objective
    below ``ftol``, scaled step below ``xtol``, at most ``max_iterations`` evaluations.
    ``jacobian``: ``"analytic"`` (the model's sensitivities, default), ``"fd"`` (the optimiser
    differences the residual itself, as FEBio and GIBBON do) or ``"none"`` (derivative-free
    optimisers); the last two exist for comparison (``skinkit bench fit``).
    ``bounds``: name -> (lower, upper) [SI], narrowing the model's admissible bounds for the fit.
    ``checkpoint``: a directory keeping every evaluation, so that a killed fit resumes
    (:class:`_Evaluations`). ``progress(evaluation, objective, values)`` after each evaluation.
    A forward solve that fails during the fit gives a non-finite residual there, which the
    optimiser answers by shrinking its step; a start the model cannot solve is a
    :class:`FitError`.
    """
    if jacobian not in ("analytic", "fd", "none"):
        raise FitError(f"jacobian must be 'analytic', 'fd' or 'none', got {jacobian!r}")
    use_jac = jacobian == "analytic"
    t0 = time.perf_counter()
    params = _start_parameters(model, free, bounds, start)
    names = params.free_names
    obj = Objective(model, observations.fitted(), names, weighting)
    sc = Scaling.for_parameters(params, names)
    opt = _optimiser(optimiser, use_jac)
    evals = _Evaluations(Path(checkpoint) if checkpoint is not None else None)
    run = _FitRun(params, obj, sc, evals, use_jac, progress)
    result = _minimise(run, opt, optimiser, _options(optimiser, ftol, xtol, max_iterations))
    n_fit_forward, n_fit_sens = obj.n_forward, obj.n_sensitivity
    x_best = np.asarray(result.x, float)
    final = run.at(x_best, need_jac=True)
    if not final["ok"]:
        raise FitError(f"the optimiser ended where the model cannot be solved: {final['error']}")
    out = _fit_result(model, observations, run, x_best, final, result, weighting, t0)
    out.extra.update({
        "weighting": weighting, "optimiser": optimiser, "free": names, "history": run.history,
        "scaling": dict(zip(names, sc.kinds, strict=True)), "n_replayed": run.n_replayed,
        "n_failed_solves": sum(1 for h in run.history if not h["solved"]),
        "n_forward_optimiser": n_fit_forward, "n_sensitivity_optimiser": n_fit_sens,
        "ftol": ftol, "xtol": xtol, "max_iterations": max_iterations,
    })
    return out


def _fit_result(model: Any, observations: Observations, run: _FitRun, x_best: np.ndarray,
                final: dict[str, Any], result: Any, weighting: str, t0: float) -> FitResult:
    """The :class:`FitResult` at the optimum ``x_best``: uncertainty and identifiability from the
    final residual and Jacobian, AIC, held-out error; ``extra`` holds ``chi2`` and ``n_observations``."""
    names, sc, obj = run.names, run.sc, run.obj
    best = run.params.with_free_vector(sc.to_values(x_best))
    z = final["z"]
    J = final["J"] / sc.dvalue_dscaled(x_best)[None, :]     # back to ∂z/∂p in SI
    res = Residual(z, None, [(p, c, slice(a, b)) for p, c, a, b in final["blocks"]])
    from skinkit.inverse.overlap import overlap_meat

    meat, overlap = overlap_meat(J, res.blocks, obj.observations) if weighting == "noise" else (None, {})
    ident = analyse(J, z, names, best.free_vector(), sc.dvalue_dscaled(x_best),
                    noise_weighted=weighting == "noise", meat=meat)
    n_obs = z.size
    chi2 = float(z @ z)
    a, ac = aic(chi2, n_obs, len(names))
    se = dict(zip(names, ident["se"], strict=True))
    identifiability = {k: ident[k] for k in ("metrics", "weak_directions", "problems", "identifiable",
                                             "inflation")}
    held = held_out_rms(model, best, observations, weighting)
    wall = time.perf_counter() - t0
    n_fwd, n_sens = obj.n_forward, obj.n_sensitivity
    out = FitResult(model.name, best, 0.5 * chi2, n_fwd, bool(result.success), str(result.message),
                    covariance=np.array(ident["covariance"]), aic=a, aicc=ac, se=se,
                    correlation=np.array(ident["correlation"]), identifiability=identifiability,
                    chi2_per_dof=ident["chi2_per_dof"], residual_by_protocol=res.by("protocol"),
                    residual_by_channel=res.by("channel"), held_out=held, n_forward=n_fwd,
                    n_sensitivity=n_sens, wall_s=wall)
    out.extra.update({"chi2": chi2, "n_observations": n_obs, "overlap": overlap})
    return out


def _start_parameters(model: Any, free: Sequence[str] | None, bounds: dict[str, tuple[float, float]] | None,
                      start: dict[str, float] | None) -> ParameterSet:
    """The model's parameters with ``free`` free, the fit's ``bounds`` and the ``start`` values
    [SI], each checked (a free one, non-empty bounds, a start inside them)."""
    params = free_set(model.parameters(), free)
    names = params.free_names
    if not names:
        raise FitError(f"model {model.name!r} has no free parameter")
    if bounds:
        params = with_bounds(params, bounds)
    for n in names:
        p = params.param(n)
        if not p.lower < p.upper:
            raise FitError(f"bounds of {n} are inverted or empty: "
                           f"[{p.lower:g}, {p.upper:g}]{unit_suffix(p.unit)}")
    if start:
        for k, v in start.items():
            if k not in params:
                raise FitError(f"start: the model has no parameter {k!r}")
            p = params.param(k)
            if not p.lower <= v <= p.upper:
                raise FitError(f"start of {k} = {format_quantity(v, p.unit)} is outside its bounds "
                               f"[{p.lower:g}, {p.upper:g}]")
        params = params.with_values(start)
    return params


def _component_hint(model: Any, observations: Observations) -> str:
    """Why a start may not be solvable: the model reads tip components (``record_components``)
    that no tip channel of the session holds -- a one-axis CSV record read along another axis;
    "" when that is not the case."""
    wanted = str(getattr(model, "record_components", "") or "")
    held = {"xyz"[j] for p in observations for c in p.channels.values() if not c.is_points
            for j in range(min(c.valid.shape[1], 3)) if c.valid[:, j].any()}
    if not wanted or not held or set(wanted) & held:
        return ""
    axis = wanted[0]
    return (f"; the session's tip channels hold component(s) {', '.join(sorted(held))} only, and model "
            f"{model.name!r} reads {', '.join(wanted)}: read a one-axis CSV record along the model's axis "
            f"(skinkit.fit(model, path), skinkit.forward.session.read_session(model, path), or "
            f"read_observations(path, axis={axis!r}))")


def _describe(pset: ParameterSet, names: Sequence[str]) -> str:
    return ", ".join(f"{n} = {format_quantity(pset[n], pset.param(n).unit, '.4g')}" for n in names)


def _options(optimiser: str, ftol: float, xtol: float, max_iterations: int) -> dict[str, Any]:
    if optimiser == "scipy-lsq":
        return {"ftol": ftol, "xtol": xtol, "max_nfev": max_iterations, "x_scale": 1.0}
    return {"ftol_rel": ftol, "xtol_rel": xtol, "maxeval": max_iterations}


def fit_json(result: FitResult) -> dict[str, Any]:
    """The ``skinkit fit --json`` shape. Strict JSON has no infinity: an unbounded bound is
    null with ``lower_reason``/``upper_reason`` ``"unbounded"``, an undetermined standard error
    null with ``se_reason``, an infinite condition number null with ``cond_H_reason``."""
    ident = result.identifiability.get("identifiable", {})
    pars = {p.name: _parameter_json(p, result.se.get(p.name), ident) for p in result.parameters}
    corr = None if result.correlation is None else np.asarray(result.correlation).tolist()
    return {"parameters": pars, "objective": result.objective, "chi2_per_dof": result.chi2_per_dof,
            "correlation": corr, "identifiability": _identifiability_json(result.identifiability),
            "aic": result.aic, "aicc": result.aicc, "n_forward": result.n_forward,
            "n_sensitivity": result.n_sensitivity, "wall_s": result.wall_s,
            "converged": result.converged, "message": result.message, "held_out": result.held_out,
            "residual_by_protocol": result.residual_by_protocol,
            "residual_by_channel": result.residual_by_channel, "starts": result.starts,
            "n_replayed": result.extra.get("n_replayed", 0),
            "n_failed_solves": result.extra.get("n_failed_solves", 0),
            **{k: result.extra[k] for k in ("discretisation", "model_error", "model_error_failed")
               if k in result.extra}}


#: a parameter within this fraction of its admissible range from a bound sits on it
ON_BOUND = 1e-4


def on_bound(p: Any) -> str | None:
    """``"lower"`` or ``"upper"`` when parameter ``p`` (value, lower, upper) sits on that bound —
    within :data:`ON_BOUND` of its range (of its magnitude, or 1, when the range is infinite) —
    else None. A fit that ends there was stopped by the bound, not by the data."""
    span = p.upper - p.lower if np.isfinite(p.upper - p.lower) else max(abs(p.value), 1.0)
    for side, b in (("lower", p.lower), ("upper", p.upper)):
        if np.isfinite(b) and abs(p.value - b) <= ON_BOUND * span:
            return side
    return None


def _parameter_json(p: Any, se: float | None, identifiable: dict[str, bool]) -> dict[str, Any]:
    out: dict[str, Any] = {"value": p.value, "unit": p.unit}
    if se is not None and not np.isfinite(se):   # an undetermined one: no number, and why
        out.update(se=None, se_reason=SE_NOT_A_NUMBER if np.isnan(se) else SE_UNDETERMINED)
    else:
        out["se"] = None if se is None else float(se)
    bounds = bound_entries(p.lower, p.upper)
    out.update(lower=p.lower, upper=p.upper, **{k: v for k, v in bounds.items() if k.endswith("_reason")})
    out.update(free=p.free, identifiable=identifiable.get(p.name, True) if p.free else None)
    out["on_bound"] = on_bound(p) if p.free else None
    return out


def _identifiability_json(ident: dict[str, Any]) -> dict[str, Any]:
    """``ident`` with ``metrics.cond_H_reason`` beside an infinite condition number."""
    metrics = ident.get("metrics")
    cond = metrics.get("cond_H") if isinstance(metrics, dict) else None
    if cond is None or np.isfinite(cond):
        return ident
    why = "singular: the objective is flat along some direction of the parameters (infinite condition number)"
    return {**ident, "metrics": {**metrics, "cond_H_reason": why}}


__all__ = ["ON_BOUND", "FitError", "aic", "fit", "fit_json", "free_set", "on_bound", "with_bounds"]

