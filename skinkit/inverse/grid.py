"""The objective over a grid of two parameters (thesis Fig 7-10) and profile likelihoods.

**Objective grid.** φ(θ) = ½ Σ z² of the weighted residual (:class:`skinkit.inverse.Objective`,
the quantity :func:`skinkit.inverse.fit` minimises) on an n × n grid of two parameters, every
other parameter fixed at ``around``. The thesis plotted such a grid for k1 and k2 and found a
diagonal, flat-bottomed valley (Fig 7-10): a pair the data cannot separate. The grid is laid
out in the fit's scaled coordinates (:mod:`skinkit.inverse.scaling`: Eq 7.13 for bounded
parameters, decades for parameters spanning more than two, fractions of the value otherwise),
so equal steps mean what they mean to the optimiser. Each grid point is one forward
prediction without sensitivities; a point the model cannot solve is recorded as such (None),
never as a penalty.

With the noise weighting, z is a vector of standard normals under the noise model, so
2Δφ = Δχ², and near the optimum (Eq 7.15) φ − φ̂ ≈ ½ δᵀHδ, H = JᵀJ the Gauss–Newton
Hessian: the contours are the ellipses of the indifference region (Eq 7.17, written there
with H⁻¹ by a slip; the quadratic form is in H). With the others held fixed, the grid shows
the *conditional* region, whose covariance is the inverse of the pair's block of the
information matrix; the *marginal* covariance (the fit's standard errors, the others
re-fitted) is wider along a valley. :func:`attach_covariance` puts both beside a grid.

**Profile likelihood** (Bates & Watts 1988, 6.1). For each value v of one parameter, fixed
there, the other free parameters are re-fitted (:func:`skinkit.inverse.fit`); the profile is
the minimum objective φ̃(v). The 95 % interval is {v : 2(φ̃(v) − φ̂) ≤ χ²₁(0.95) · s}, with
χ²₁(0.95) = 3.841 and s the same inflation the covariance of
:mod:`skinkit.inverse.identifiability` carries: with the noise weighting s = max(1, χ²/ν)
(a fit worse than the noise explains has a model error the noise level does not cover; the
interval widens as the standard errors do), with other weightings s = χ²/ν (the residual
scale is estimated). The crossings are found on the signed root r(v) = sign(v − θ̂)
√(2(φ̃ − φ̂)/s), which is linear in v for a linear model, by linear interpolation: for a
linear model the profile interval is then exactly θ̂ ± 1.96 se (Wald); where they differ,
the model is nonlinear in that parameter over the interval, and the profile is the one to
believe.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError
from skinkit.inverse.objective import Objective
from skinkit.inverse.scaling import Scaling
from skinkit.schemas import Observations, Parameter, ParameterSet
from skinkit.schemas.results import SE_UNDETERMINED
from skinkit.units import format_quantity

#: χ²₁(0.95): the 95 % likelihood-ratio threshold on Δ(2φ) for one parameter
CHI2_1_95 = 3.841458820694124
#: χ²₂(0.95): the same for a pair (the joint 95 % region drawn on a grid)
CHI2_2_95 = 5.991464547107979


class GridError(SkinkitError):
    """A grid or profile request that cannot run: unknown or repeated parameters, too few points."""


def _check_names(params: ParameterSet, names: Sequence[str], what: str) -> None:
    unknown = [n for n in names if n not in params]
    if unknown:
        raise GridError(f"{what}: the model has no parameter {', '.join(unknown)}; "
                        f"it has {', '.join(params.names)}")


def _default_half_width(sc: Scaling, i: int) -> tuple[float, float]:
    """Scaled interval of parameter ``i`` when no span is given: its bounds when finite
    (Eq 7.13: the whole [0, 1]), ±1 decade for log-scaled ones, ±50 % otherwise."""
    lo, hi = sc.bounds()
    if sc.kinds[i] == "bounds":
        return float(lo[i]), float(hi[i])
    if sc.kinds[i] == "log":
        return max(float(lo[i]), -1.0), min(float(hi[i]), 1.0)
    c = 1.0   # value scaling: θ = p/|p0|, the centre is ±1
    return c - 0.5, c + 0.5


def span_from_se(scaling: Scaling, centre: np.ndarray, se: Sequence[float], k: float) -> list[float]:
    """Half-widths in scaled coordinates of ``k`` standard errors ``se`` [SI] at ``centre`` [SI]:
    k se / (dp/dθ) per parameter of ``scaling``."""
    d = scaling.dvalue_dscaled(scaling.to_scaled(np.asarray(centre, float)))
    out = []
    for s, dd in zip(se, d, strict=True):
        if not (s is not None and math.isfinite(s) and s > 0):
            raise GridError("--span in standard errors: a standard error is missing or infinite "
                            "(the fit could not determine it); give the span in scaled units")
        out.append(float(k * s / dd))
    return out


def objective_grid(model: Any, observations: Observations, pair: tuple[str, str], n: int = 11,
                   span: float | Sequence[float] | None = None, weighting: str = "noise",
                   around: ParameterSet | None = None, *,
                   progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """φ = ½Σz² on an ``n`` × ``n`` grid of the parameters ``pair``, the others fixed at ``around``.

    ``model``: a forward model (``parameters()``, ``predict``); ``observations``: the session
    (held-out protocols are left out, as :func:`skinkit.inverse.fit` does); ``span``: half-width
    of the grid about ``around`` in scaled coordinates (one number for both or one each: a
    fraction of the bounds' range for bounded parameters, decades for log-scaled ones, a
    fraction of the value otherwise); None: the bounds (log: ±1 decade, value: ±50 %). The
    grid is clipped to the bounds. ``weighting``: as :func:`skinkit.inverse.fit`; ``around``:
    the parameter set at the centre (default the model's); ``progress(message)`` per row.

    Returns a JSON-ready dict: ``pair``; ``parameters`` {name: ``unit``, ``scaling``,
    ``centre`` [SI], ``values`` (n,) [SI], ``scaled`` (n,)}; ``objective`` n × n nested lists,
    ``objective[i][j]`` at ``values[pair[0]][i]``, ``values[pair[1]][j]`` (None where the model
    could not be solved, the reason in ``failed``); ``minimum`` {the pair's values, ``objective``,
    ``index``}; ``centre_objective`` (φ at ``around``); ``fixed`` (every other parameter [SI]);
    ``n_observations``, ``weighting``, ``n_forward``, ``wall_s``.
    """
    t0 = time.perf_counter()
    if not isinstance(n, int | np.integer) or n < 3:
        raise GridError(f"--n must be an integer of at least 3 (a grid needs a centre and both sides), "
                        f"got {n}")
    pair = tuple(str(p) for p in pair)
    if len(pair) != 2:
        raise GridError(f"--pair: name exactly two parameters, got {len(pair)} ({','.join(pair)})")
    if pair[0] == pair[1]:
        raise GridError(f"--pair names {pair[0]} twice; name two different parameters")
    base = around if around is not None else model.parameters()
    _check_names(base, pair, "--pair")
    sc = Scaling.for_parameters(base, list(pair))
    centre = np.array([base[p] for p in pair], float)
    c_scaled = sc.to_scaled(centre)
    if span is None:
        ranges = [_default_half_width(sc, i) for i in range(2)]
    else:
        hw = np.broadcast_to(np.asarray(span, float), (2,))
        if not np.all(np.isfinite(hw)) or np.any(hw <= 0):
            raise GridError(f"--span must be positive and finite, got {np.asarray(span).tolist()}")
        lo, hi = sc.bounds()
        ranges = [(max(float(lo[i]), c_scaled[i] - hw[i]), min(float(hi[i]), c_scaled[i] + hw[i]))
                  for i in range(2)]
    axes = [np.linspace(a, b, n) for a, b in ranges]
    values = [np.array([sc.to_values(np.where(np.arange(2) == i, a, c_scaled))[i] for a in axes[i]])
              for i in range(2)]
    obj = Objective(model, observations.fitted(), [], weighting)
    phi: list[list[float | None]] = []
    failed = []
    m = 0
    for i, va in enumerate(values[0]):
        row: list[float | None] = []
        for j, vb in enumerate(values[1]):
            try:
                at = base.with_values({pair[0]: float(va), pair[1]: float(vb)})
                res, _ = obj.evaluate(at, jacobian=False)
                row.append(0.5 * float(res.z @ res.z))
                m = int(res.z.size)
            except (SkinkitError, ArithmeticError) as exc:
                row.append(None)
                failed.append({"index": [i, j], "values": [float(va), float(vb)], "error": str(exc)})
        phi.append(row)
        if progress is not None:
            done = [v for v in row if v is not None]
            best = f"{min(done):.6g}" if done else "-"
            progress(f"grid row {i + 1}/{n}: {pair[0]} = {va:.4g}, lowest objective in the row {best}")
    arr = np.array([[np.nan if v is None else v for v in row] for row in phi])
    if not np.isfinite(arr).any():
        raise GridError(f"the model could not be solved anywhere on the grid of {pair[0]}, {pair[1]} "
                        f"(first error: {failed[0]['error']})")
    i, j = np.unravel_index(np.nanargmin(arr), arr.shape)
    centre_phi = None
    try:
        res, _ = obj.evaluate(base, jacobian=False)
        centre_phi = 0.5 * float(res.z @ res.z)
        m = int(res.z.size)
    except (SkinkitError, ArithmeticError):
        pass
    return {
        "model": getattr(model, "name", "model"), "pair": list(pair), "n": int(n), "weighting": weighting,
        "parameters": {p: {"unit": base.param(p).unit, "scaling": sc.kinds[k], "centre": float(centre[k]),
                           "values": values[k].tolist(), "scaled": axes[k].tolist()}
                       for k, p in enumerate(pair)},
        "objective": phi, "failed": failed,
        "minimum": {pair[0]: float(values[0][i]), pair[1]: float(values[1][j]), "objective": float(arr[i, j]),
                    "index": [int(i), int(j)]},
        "centre_objective": centre_phi,
        "fixed": {p.name: p.value for p in base if p.name not in pair},
        "n_observations": m, "n_forward": obj.n_forward, "wall_s": time.perf_counter() - t0,
    }


def conditional_and_marginal(covariance: np.ndarray, names: Sequence[str],
                             pair: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """The pair's 2 × 2 covariances [SI²] from a fit's ``covariance`` over ``names``:
    *marginal* (its block: the others re-fitted, as the fit's standard errors) and *conditional*
    (the inverse of the pair's block of the information matrix: the others held fixed, as on
    a grid). Equal when the pair is uncorrelated with the others."""
    C = np.asarray(covariance, float)
    idx = [list(names).index(p) for p in pair]
    marginal = C[np.ix_(idx, idx)]
    try:
        info = np.linalg.inv(C)
        conditional = np.linalg.inv(info[np.ix_(idx, idx)])
    except np.linalg.LinAlgError:
        conditional = marginal   # a singular covariance: no better statement than the block
    return conditional, marginal


def attach_covariance(grid: dict[str, Any], names: Sequence[str], covariance: np.ndarray,
                      centre: dict[str, float], inflation: float = 1.0) -> dict[str, Any]:
    """``grid`` with a fit's uncertainty beside it, for :func:`skinkit.inverse.plots.grid_plot`:
    ``covariance_conditional`` and ``covariance_marginal`` (2 × 2, SI²), ``ellipse_centre``
    (the fit's values of the pair), ``inflation`` (the χ²/ν factor already in the covariance)
    and ``ellipse_level`` = χ²₂(0.95). The fit's free parameters ``names`` must include the pair."""
    pair = grid["pair"]
    missing = [p for p in pair if p not in names]
    if missing:
        raise GridError(f"--at: {', '.join(missing)} was not free in that fit; its covariance says nothing "
                        "about it (fit it free, or grid without --at)")
    cond, marg = conditional_and_marginal(covariance, names, pair)
    out = dict(grid)
    out.update({"covariance_conditional": cond.tolist(), "covariance_marginal": marg.tolist(),
                "ellipse_centre": [float(centre[p]) for p in pair], "inflation": float(inflation),
                "ellipse_level": CHI2_2_95})
    return out


def _inflation(chi2: float, dof: int, weighting: str) -> float:
    """The factor of :func:`skinkit.inverse.identifiability.analyse`: max(1, χ²/ν) with the
    noise weighting, χ²/ν otherwise."""
    r = chi2 / max(dof, 1)
    return max(1.0, r) if weighting == "noise" else r


def _crossing(v: np.ndarray, r: np.ndarray, level: float) -> float | None:
    """First v where |r| reaches ``level`` moving away from the estimate (r sorted by |v − θ̂|),
    by linear interpolation of r; None if it never does."""
    for k in range(1, len(v)):
        if abs(r[k]) >= level:
            a, b = abs(r[k - 1]), abs(r[k])
            return float(v[k - 1] + (level - a) / (b - a) * (v[k] - v[k - 1])) if b > a else float(v[k])
    return None


def profile_likelihood(model: Any, observations: Observations, name: str, free: Sequence[str] | None = None,
                       values: Sequence[float] | None = None, n: int = 9, weighting: str = "noise", *,
                       optimiser: str = "scipy-lsq", ftol: float = 1e-10, xtol: float = 1e-8,
                       max_iterations: int = 50,
                       progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """The profile of ``name``: at each value, the other ``free`` parameters re-fitted (module docstring).

    ``free``: the parameters re-fitted at each value (default: the model's free ones); ``name``
    is taken out of them. ``values`` [SI]: where to profile (default ``n`` values over
    θ̂ ± 3 se of a first fit with ``name`` free too, clipped to the bounds). Tolerances are
    tighter than a fit's default because the profile is read in differences of φ of order 1.
    Each re-fit starts from the previous value's result, moving outward from θ̂.

    Returns a JSON-ready dict: ``parameter``, ``unit``, ``free`` (the re-fitted ones),
    ``estimate`` θ̂ and ``objective_min`` φ̂ (the fit with ``name`` free), ``se`` (its standard
    error, with the inflation), ``wald_interval`` (θ̂ ± 1.96 se), ``values``, ``objective``
    (the profile φ̃, None where the fit could not be made), ``delta_2phi`` (2(φ̃ − φ̂)),
    ``signed_root``, ``others`` {name: values}, ``threshold`` (χ²₁(0.95) s), ``inflation`` s,
    ``chi2_per_dof``, ``interval`` [lower, upper] (None for an end the profiled values do not
    reach), ``n_forward``, ``n_sensitivity``, ``wall_s``.
    """
    from skinkit.inverse.fit import fit, free_set

    t0 = time.perf_counter()
    say = progress or (lambda _m: None)
    base = model.parameters()
    _check_names(base, [name], "--parameter")
    if free is not None:
        _check_names(base, list(free), "--free")
    others = [p for p in (free_set(base, list(free)).free_names if free is not None else base.free_names)
              if p != name]
    if values is None and (not isinstance(n, int | np.integer) or n < 3):
        raise GridError(f"--n must be an integer of at least 3, got {n}")
    fitted = observations.fitted()
    say(f"fit with {name} free: {', '.join([name, *others])}")
    central = fit(model, fitted, [name, *others], weighting=weighting, optimiser=optimiser, ftol=ftol,
                  xtol=xtol, max_iterations=max_iterations)
    theta = float(central.parameters[name])
    phi_hat = float(central.objective)
    m = int(central.extra["n_observations"])
    dof = m - 1 - len(others)
    s = _inflation(2 * phi_hat, dof, weighting)
    se = central.se.get(name)
    p = base.param(name)
    vals = _profile_values(p, theta, se, values, n)
    refit = _Refit(model, fitted, name, others, central, weighting,
                   {"optimiser": optimiser, "ftol": ftol, "xtol": xtol, "max_iterations": max_iterations})
    prof = refit.profile(vals, theta, lambda v, rec: say(
        f"profile {name} = {format_quantity(v, p.unit, '.6g')}: objective "
        + (f"{rec['objective']:.6g}" if rec["objective"] is not None else "not solved")))
    vals = np.array(sorted(prof))
    phis = [prof[v]["objective"] for v in vals]
    finite = [f for f in phis if f is not None]
    # a re-fit may find a lower point than the first fit stopped at: the profile's minimum is φ̂ then
    phi_min = min([phi_hat, *finite])
    d2 = [None if f is None else 2 * (f - phi_min) for f in phis]
    root = [None if d is None else math.copysign(math.sqrt(max(d, 0.0) / s), v - theta)
            for d, v in zip(d2, vals, strict=True)]
    level = math.sqrt(CHI2_1_95)
    wald = [theta - level * se, theta + level * se] if se is not None and math.isfinite(se) else None
    return {
        "model": getattr(model, "name", "model"), "parameter": name, "unit": p.unit, "free": others,
        "weighting": weighting, "estimate": theta, "objective_min": phi_min, "se": se,
        **({"se_reason": SE_UNDETERMINED} if se is not None and not math.isfinite(se) else {}),
        "wald_interval": wald, "values": vals.tolist(), "objective": phis, "delta_2phi": d2,
        "signed_root": root, "others": {q: [prof[v]["others"].get(q) for v in vals] for q in others},
        "converged": [prof[v]["converged"] for v in vals],
        "errors": {str(v): prof[v]["error"] for v in vals if "error" in prof[v]},
        "threshold": CHI2_1_95 * s, "inflation": s, "chi2_per_dof": 2 * phi_hat / max(dof, 1),
        "n_observations": m, "interval": _interval(vals, root, theta, level),
        "n_forward": central.n_forward + refit.n_forward,
        "n_sensitivity": central.n_sensitivity + refit.n_sensitivity, "wall_s": time.perf_counter() - t0,
    }


def _profile_values(p: Parameter, theta: float, se: float | None, values: Sequence[float] | None,
                    n: int) -> np.ndarray:
    """Where to profile ``p`` [SI]: ``values`` checked against its bounds, or ``n`` values over
    θ̂ ± 3 se (the bounds, or ±50 %, when se is not determined), clipped to the bounds."""
    if values is None:
        if se is not None and math.isfinite(se) and se > 0:
            lo, hi = theta - 3 * se, theta + 3 * se
        else:   # not determined: the bounds, or ±50 %
            lo = p.lower if math.isfinite(p.lower) else theta - 0.5 * abs(theta)
            hi = p.upper if math.isfinite(p.upper) else theta + 0.5 * abs(theta)
        return np.linspace(max(lo, p.lower), min(hi, p.upper), int(n))
    vals = np.unique(np.asarray(values, float))
    bad = [v for v in vals if not p.lower <= v <= p.upper]
    if bad:
        raise GridError(f"--values: {format_quantity(bad[0], p.unit)} is outside the bounds of {p.name} "
                        f"[{p.lower:g}, {p.upper:g}]")
    if vals.size < 2:
        raise GridError("--values: give at least two values")
    return vals


class _Refit:
    """The profile's re-fits: at each value of ``name``, the ``others`` fitted again, each
    starting from its neighbour's result nearer θ̂; counts the solves they take."""

    def __init__(self, model: Any, fitted: Observations, name: str, others: list[str], central: Any,
                 weighting: str, options: dict[str, Any]) -> None:
        self.model, self.fitted, self.name, self.others = model, fitted, name, others
        self.central, self.weighting, self.options = central, weighting, options
        self.n_forward = 0
        self.n_sensitivity = 0

    def profile(self, vals: np.ndarray, theta: float,
                report: Callable[[float, dict[str, Any]], None]) -> dict[float, dict[str, Any]]:
        """value -> ``{"objective", "others", "converged"[, "error"]}``, moving outward from θ̂."""
        fitted_free = {q: float(self.central.parameters[q]) for q in self.others}
        prof: dict[float, dict[str, Any]] = {}
        up = [v for v in vals if v >= theta]
        down = [v for v in vals[::-1] if v < theta]
        for side in (up, down):
            start = dict(fitted_free)
            for v in side:
                rec = self.at(float(v), start)
                if "error" not in rec:   # the next value starts from this one's fit
                    start = rec["others"]
                prof[float(v)] = rec
                report(v, rec)
        return prof

    def at(self, v: float, start: dict[str, float]) -> dict[str, Any]:
        """The others re-fitted with ``name`` fixed at ``v`` from ``start`` (the objective alone
        when nothing else is free); a fit that fails is recorded with its error."""
        from skinkit.inverse.fit import fit

        rec: dict[str, Any] = {"objective": None, "others": dict(start), "converged": False}
        try:
            if self.others:
                r = fit(self.model, self.fitted, self.others, weighting=self.weighting,
                        start={self.name: v, **start}, **self.options)
                self.n_forward += r.n_forward
                self.n_sensitivity += r.n_sensitivity
                found = {q: float(r.parameters[q]) for q in self.others}
                return {"objective": float(r.objective), "others": found, "converged": bool(r.converged)}
            obj = Objective(self.model, self.fitted, [], self.weighting)
            res, _ = obj.evaluate(self.central.parameters.with_values({self.name: v}), jacobian=False)
            self.n_forward += 1
            return {"objective": 0.5 * float(res.z @ res.z), "others": {}, "converged": True}
        except (SkinkitError, ArithmeticError) as exc:
            rec["error"] = str(exc)
        return rec


def _interval(vals: np.ndarray, root: list[float | None], theta: float, level: float) -> list[float | None]:
    """The profile interval's ends: where the signed root reaches ``level`` below and above θ̂
    (None for an end the profiled values do not reach)."""
    ends: list[float | None] = []
    for sel in (vals < theta, vals >= theta):
        idx = [k for k in np.nonzero(sel)[0] if root[k] is not None]
        idx.sort(key=lambda k: abs(vals[k] - theta))
        v = np.array([theta, *vals[idx]])
        r = np.array([0.0, *[root[k] for k in idx]])
        ends.append(_crossing(v, r, level))
    return ends


__all__ = ["CHI2_1_95", "CHI2_2_95", "GridError", "attach_covariance", "conditional_and_marginal",
           "objective_grid", "profile_likelihood", "span_from_se"]
