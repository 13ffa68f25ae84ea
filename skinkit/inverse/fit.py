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

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from skinkit import registry
from skinkit.errors import PluginError, SkinkitError
from skinkit.inverse.identifiability import analyse
from skinkit.inverse.objective import Objective, held_out_rms
from skinkit.inverse.scaling import Scaling
from skinkit.schemas import FitResult, Observations, ParameterSet


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


def aic(chi2: float, n: int, k: int) -> tuple[float, float]:
    """AIC and AICc of a fit with Σz² = ``chi2`` over ``n`` observations and ``k`` free
    parameters: Eq 7.14, AIC = n ln(SSE/n) + 2(k + 1), and the small-sample correction."""
    a = n * np.log(max(chi2, 1e-300) / n) + 2 * (k + 1)
    c = a + 2 * (k + 1) * (k + 2) / max(n - k - 2, 1)
    return float(a), float(c)


def fit(model: Any, observations: Observations, free: Sequence[str] | None = None, *,
        weighting: str = "noise", optimiser: str = "scipy-lsq", start: dict[str, float] | None = None,
        ftol: float = 1e-6, xtol: float = 1e-3, max_iterations: int = 50, jacobian: str = "analytic",
        progress: Callable[[int, float, dict[str, float]], None] | None = None) -> FitResult:
    """Fit ``free`` parameters of ``model`` to the non-held-out protocols of ``observations``.

    ``jacobian``: ``"analytic"`` (the model's sensitivities, default), ``"fd"`` (the optimiser
    differences the residual itself, as FEBio and GIBBON do) or ``"none"`` (derivative-free
    optimisers); the last two exist for comparison (``skinkit bench fit``).
    """
    if jacobian not in ("analytic", "fd", "none"):
        raise FitError(f"jacobian must be 'analytic', 'fd' or 'none', got {jacobian!r}")
    use_jac = jacobian == "analytic"
    t0 = time.perf_counter()
    params = free_set(model.parameters(), free)
    names = params.free_names
    if not names:
        raise FitError(f"model {model.name!r} has no free parameter")
    if start:
        for k, v in start.items():
            p = params.param(k)
            if not p.lower <= v <= p.upper:
                raise FitError(f"start of {k} = {v:g} {p.unit} is outside its bounds "
                               f"[{p.lower:g}, {p.upper:g}]")
        params = params.with_values(start)
    fitted = observations.fitted()
    obj = Objective(model, fitted, names, weighting)
    sc = Scaling.for_parameters(params, names)
    lo, hi = sc.bounds()
    x0 = sc.to_scaled(params.free_vector())
    try:
        opt = registry.create("skinkit.optimisers", optimiser)
    except PluginError as exc:
        raise FitError(f"--optimiser {optimiser!r}: {exc}") from None
    cache: dict[str, Any] = {}
    history: list[dict[str, Any]] = []

    def at(x: np.ndarray):
        key = np.asarray(x, float).tobytes()
        if cache.get("key") != key:
            pset = params.with_free_vector(sc.to_values(x))
            try:
                res, _ = obj.evaluate(pset, jacobian=use_jac)
                J = res.J * sc.dvalue_dscaled(x)[None, :] if use_jac else None
                cache.update(key=key, z=res.z, J=J, ok=True)
            except (SkinkitError, ArithmeticError) as exc:
                # the model cannot be solved there: a large residual makes the optimiser step back
                size = cache.get("z", np.ones(1)).size
                cache.update(key=key, z=np.full(size, 1e6), J=np.zeros((size, len(names))), ok=False,
                             error=str(exc))
            phi = 0.5 * float(cache["z"] @ cache["z"])
            history.append({"x": sc.to_values(x).tolist(), "objective": phi, "solved": cache["ok"]})
            if progress is not None:
                progress(len(history), phi, dict(zip(names, sc.to_values(x).tolist(), strict=True)))
        return cache

    result = opt.minimise(lambda x: at(x)["z"], x0, lo, hi, jac=(lambda x: at(x)["J"]) if use_jac else None,
                          options=_options(optimiser, ftol, xtol, max_iterations))
    n_fit_forward, n_fit_sens = obj.n_forward, obj.n_sensitivity
    best = params.with_free_vector(sc.to_values(result.x))
    res, pred = obj.evaluate(best, jacobian=True)
    J = res.J
    ident = analyse(J, res.z, names, best.free_vector(), sc.dvalue_dscaled(result.x),
                    noise_weighted=weighting == "noise")
    n_obs = res.z.size
    chi2 = float(res.z @ res.z)
    a, ac = aic(chi2, n_obs, len(names))
    out = FitResult(model.name, best, 0.5 * chi2, obj.n_forward, bool(result.success), str(result.message),
                    covariance=np.array(ident["covariance"]), aic=a)
    out.extra.update({
        "aicc": ac, "chi2": chi2, "n_observations": n_obs, "chi2_per_dof": ident["chi2_per_dof"],
        "se": dict(zip(names, ident["se"], strict=True)), "correlation": ident["correlation"],
        "identifiability": {k: ident[k] for k in ("metrics", "weak_directions", "problems", "identifiable",
                                                 "inflation")},
        "residual_by_protocol": res.by("protocol"), "residual_by_channel": res.by("channel"),
        "n_forward": n_fit_forward, "n_sensitivity": n_fit_sens, "wall_s": time.perf_counter() - t0,
        "weighting": weighting, "optimiser": optimiser, "free": names, "history": history,
        "held_out": held_out_rms(model, best, observations, weighting),
        "scaling": dict(zip(names, sc.kinds, strict=True)),
    })
    return out


def _options(optimiser: str, ftol: float, xtol: float, max_iterations: int) -> dict[str, Any]:
    if optimiser == "scipy-lsq":
        return {"ftol": ftol, "xtol": xtol, "max_nfev": max_iterations, "x_scale": 1.0}
    return {"ftol_rel": ftol, "xtol_rel": xtol, "maxeval": max_iterations}


def fit_json(result: FitResult) -> dict[str, Any]:
    """The ``skinkit fit --json`` shape (issue 10)."""
    ex = result.extra
    se = ex.get("se", {})
    ident = ex.get("identifiability", {}).get("identifiable", {})
    pars = {}
    for p in result.parameters:
        s = se.get(p.name)
        pars[p.name] = {"value": p.value, "unit": p.unit, "se": s, "lower": p.lower, "upper": p.upper,
                        "free": p.free, "identifiable": ident.get(p.name, True) if p.free else None}
    return {"parameters": pars, "objective": result.objective, "chi2_per_dof": ex.get("chi2_per_dof"),
            "correlation": ex.get("correlation"), "identifiability": ex.get("identifiability"),
            "aic": result.aic, "aicc": ex.get("aicc"), "n_forward": ex.get("n_forward"),
            "n_sensitivity": ex.get("n_sensitivity"), "wall_s": ex.get("wall_s"),
            "converged": result.converged, "message": result.message, "held_out": ex.get("held_out", {}),
            "residual_by_protocol": ex.get("residual_by_protocol"),
            "residual_by_channel": ex.get("residual_by_channel")}


__all__ = ["FitError", "aic", "fit", "fit_json", "free_set"]

