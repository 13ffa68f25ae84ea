"""The model's discretisation error carried as noise: the approximation-error approach.

A finite-element model solved on a mesh of size h predicts y_h(θ); the skin (or a truth solved on
a finer, different mesh) behaves like the exact solution y(θ). Their difference ε(θ) = y − y_h is
not noise, but the data cannot tell it from a physical effect: a fit that ignores it biases its
parameters and a diagnosis names it as an effect. Following Kaipio & Somersalo (J Comput Appl
Math 198, 2007) and Arridge et al. (Inverse Problems 22, 2006), ε is modelled as a Gaussian
independent of the noise, with a mean and a covariance estimated where the model is used:

    y = y_h(θ) + ε + n,    ε ~ N(m, Γ),    n ~ N(0, Σ)
    χ²(θ) = (y − y_h(θ) − m)ᵀ (Σ + Γ)⁻¹ (y − y_h(θ) − m)

**Estimate.** At the calibrated θ̂ the model is solved on its own mesh and on one refined
``factor`` times, d = y_{h/f}(θ̂) − y_h(θ̂). With a convergence order p the exact minus coarse
prediction is R(p) d (Richardson, R = fᵖ/(fᵖ − 1)). The order is not known (quadratic elements
converge at 2–3 in smooth regions and near 1.3 at a bonded punch's edge), so R is taken uniform
between R(:data:`ORDER_HIGH`) and R(:data:`ORDER_LOW`), independently for each component of each
channel of each protocol, and for tracked points in each of :data:`BANDS` radial bands (a force
at a bonded edge converges near order 1, a displacement field far from the indenter near 2):
m = R̄ d, and Γ = B Bᵀ with B's columns, per group, the order's σ_R · d on that group alone
(σ_R = (R_hi − R_lo)/√12) and the error's change over the parameters' plausible spread (each
positive parameter scaled by exp(s ξ), ξ standard normal, s = :data:`SPREAD`): to first order
R̄ (∂d/∂θ_j) s θ_j per free parameter, from the derivatives both solves return with their
values (the fit's sensitivities on each mesh), with ``draws=None``. By default (and where a
derivative is not analytic) the spread is sampled instead: d_k at ``draws`` seeded points θ_k
besides θ̂, m = R̄ · mean_k d_k and columns (R̄ d_k − m)/√K. The tangent form is not the default:
it carries the spread in full (the sampled form, from one draw, a quarter of it in expectation),
and on the README tour's session (one seed) it left the fitted shear modulus more than three
standard errors from the truth, where the sampled form stays within them. Γ has rank ≤ the
number of groups (3 per tip channel, 9 per point channel and protocol) + the free parameters
(or K).

**Whiten.** In the objective's noise-whitened coordinates (z = W(y_h + m − y), V = W B), (I +
V Vᵀ)^(−1/2) = I − Q diag(1 − 1/√(1 + s²)) Qᵀ with V = Q S Rᵀ (thin SVD): a rank-r
correction of z and of its Jacobian (r = rank of Γ), applied by
:class:`skinkit.inverse.objective.Objective` to every residual of observations that carry the
estimate (:meth:`Observations.with_model_error`). A direction whose variance is thousands of
noise variances is in effect projected out; the projection of one refined-mesh direction the
diagnosis made before is its special case.

**Cost.** ``draws + 1`` solves on the model's mesh and as many on the refined one (``factor³``
times the unknowns); the tangent form one of each, with the free parameters' sensitivities —
per step a few conjugate-gradient iterations preconditioned by the Newton loop's factorisation,
no tangent factorised again. The estimate
is made once per calibration and reused by every refit and candidate of a diagnosis (the mean
and basis are stored with the observations).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.inverse.discretisation import (
    DEFAULT_FACTOR,
    DiscretisationError,
    explained_share,
    has_mesh,
    richardson_factor,
)
from skinkit.inverse.lowrank import apply, whitening
from skinkit.schemas import Observations, ParameterSet, Prediction
from skinkit.schemas.observations import CHANNELS

#: convergence orders bracketing the model's (the bonded punch's singular edge, smooth regions)
ORDER_LOW, ORDER_HIGH = 1.0, 2.0
#: log-spread of each positive parameter in the draws around the calibration (10 %)
SPREAD = 0.1
#: draws besides the calibration point (the spread sampled; None: from derivatives)
DEFAULT_DRAWS = 1
#: radial bands of tracked points with an error amplitude of their own
BANDS = 3
#: estimate-and-refit passes (:func:`refit`)
DEFAULT_PASSES = 2


@dataclass
class ModelError:
    """The model's discretisation error as a Gaussian: per ``(protocol, channel)`` its ``mean``
    (the channel's shape [unit], exact minus model) and ``basis`` ``(r, *shape)`` [unit] with
    covariance Σ_j basis_j basis_jᵀ; ``summary``: JSON-ready figures (:func:`estimate`)."""

    mean: dict[tuple[str, str], np.ndarray]
    basis: dict[tuple[str, str], np.ndarray]
    rank: int
    summary: dict[str, Any] = field(default_factory=dict)

    def cut(self, keep: Mapping[tuple[str, str], tuple[slice, ...]]) -> ModelError:
        """The same error on sliced channels (``keep``: key -> the slice of its values)."""
        mean = {k: v[keep[k]] for k, v in self.mean.items() if k in keep}
        basis = {k: v[(slice(None), *keep[k])] for k, v in self.basis.items() if k in keep}
        return ModelError(mean, basis, self.rank, self.summary)


def not_estimated(exc: BaseException) -> str:
    """What to say when :func:`refit` failed with ``exc``: the estimate could not be made, and
    why (the solver's where and why, from ``exc``)."""
    return (f"the model's discretisation error could not be estimated (its mesh refined 2x, or the fit "
            f"carrying it, failed: {exc})")


def _scaled(params: ParameterSet, name: str) -> bool:
    """Whether ``name`` spreads on a log scale around the calibration: a positive value with a
    non-negative lower bound (a modulus); others spread by a share of their magnitude."""
    return float(params.values()[name]) > 0 and params.param(name).lower >= 0


def _draws(params: ParameterSet, free: Sequence[str], n: int, seed: int) -> list[dict[str, float]]:
    """The calibration's values and ``n`` draws around it (log-scaled parameters, :func:`_scaled`,
    multiplied by exp(SPREAD ξ), others shifted by SPREAD ξ |θ|; clipped to the bounds)."""
    rng = np.random.default_rng(seed)
    base = dict(params.values())
    out = [dict(base)]
    for _ in range(n):
        v = dict(base)
        for name in free:
            p = params.param(name)
            xi = float(rng.standard_normal())
            x = base[name] * math.exp(SPREAD * xi) if _scaled(params, name) else \
                base[name] + SPREAD * xi * max(abs(base[name]), 1e-12)
            v[name] = float(min(max(x, p.lower), p.upper))
        out.append(v)
    return out


def _kept(cp: Any, fp: Any, channel: Any) -> np.ndarray:
    """Entries observed, predicted on both meshes and not a measured reference frame."""
    m = cp.mask(channel)
    return m & np.asarray(fp.predicted, bool) if fp.predicted is not None else m


def _differences(coarse: Prediction, fine: Prediction, observations: Observations
                 ) -> dict[tuple[str, str], np.ndarray]:
    """fine − coarse per observed, predicted entry (0 where either is missing)."""
    out = {}
    for proto, cname, cp in coarse.items():
        if proto not in observations.names or cname not in observations[proto].channels:
            continue
        fp = fine.protocols.get(proto, {}).get(cname)
        if fp is None or np.shape(fp.values) != np.shape(cp.values):
            continue
        m = _kept(cp, fp, observations[proto].channels[cname])
        d = np.where(m, np.asarray(fp.values, float) - np.asarray(cp.values, float), 0.0)
        out[(proto, cname)] = np.nan_to_num(d)
    return out


def _groups(ch: Any) -> list[np.ndarray]:
    """Boolean masks (the channel's shape) over which the error's amplitude is one unknown: each
    component of a tip channel; each component of a point channel in each of :data:`BANDS`
    bands of the points' distance from their centroid (equal counts)."""
    shape = ch.values.shape
    out = []
    if not ch.is_points:
        for j in range(shape[-1]):
            m = np.zeros(shape, bool)
            m[..., j] = True
            out.append(m)
        return out
    ref = ch.reference if ch.reference is not None else np.nan_to_num(ch.values[:, 0])
    xy = np.asarray(ref, float)[:, :2]
    r = np.hypot(*(xy - xy.mean(axis=0)).T)
    edges = np.quantile(r, np.linspace(0, 1, BANDS + 1)[1:-1]) if r.size else []
    band = np.searchsorted(edges, r, side="right")
    for k in range(BANDS):
        for j in range(shape[-1]):
            m = np.zeros(shape, bool)
            m[band == k, :, j] = True
            if m.any():
                out.append(m)
    return out


def _channel_figures(mean: Mapping[tuple[str, str], np.ndarray], observations: Observations
                     ) -> dict[str, dict[str, Any]]:
    """Per channel name: RMS and largest |mean| [unit], the noise level, and their ratio."""
    acc: dict[str, list[np.ndarray]] = {}
    noise: dict[str, float] = {}
    for (proto, cname), m in mean.items():
        ch = observations[proto].channels[cname]
        sel = ch.fit_mask()
        acc.setdefault(cname, []).append(m[sel])
        noise[cname] = float(np.sqrt(np.mean(np.square(ch.sigma()[sel])))) if sel.any() else \
            float(np.sqrt(np.mean(np.square(ch.noise))))
    out = {}
    for cname, parts in acc.items():
        d = np.concatenate(parts)
        rms = float(np.sqrt(np.mean(d ** 2))) if d.size else 0.0
        out[cname] = {"rms": rms, "max": float(np.max(np.abs(d))) if d.size else 0.0,
                      "noise": noise[cname], "rms_over_noise": rms / noise[cname] if noise[cname] else None,
                      "unit": CHANNELS[cname][0]}
    return out


#: per ``(protocol, channel)`` an array of the channel's shape (or with a leading axis)
Diffs = dict[tuple[str, str], np.ndarray]


def _step(params: ParameterSet, name: str) -> float:
    """The draws' standard deviation of ``name`` to first order [its SI unit] (:func:`_draws`)."""
    v = float(params.values()[name])
    return SPREAD * abs(v) if _scaled(params, name) else SPREAD * max(abs(v), 1e-12)


def _tangents(coarse: Prediction, fine: Prediction, observations: Observations, params: ParameterSet,
              free: Sequence[str], keys: Sequence[tuple[str, str]]) -> dict[tuple[str, str], np.ndarray]:
    """Per channel of ``keys`` (those :func:`_differences` kept) ``(len(free), *shape)``:
    ∂(fine − coarse)/∂θ_j times θ_j's draw spread."""
    out: dict[tuple[str, str], np.ndarray] = {}
    for key in keys:
        cp, fp = coarse.protocols[key[0]][key[1]], fine.protocols[key[0]][key[1]]
        m = _kept(cp, fp, observations[key[0]].channels[key[1]])
        cols = [np.nan_to_num(np.where(m, np.asarray(fp.d[n], float) - np.asarray(cp.d[n], float), 0.0))
                * _step(params, n) if n in fp.d and n in cp.d else np.zeros(np.shape(cp.values))
                for n in free]
        out[key] = np.stack(cols) if cols else np.zeros((0, *np.shape(cp.values)))
    return out


def _solve_points(model: Any, fine_model: Any, fitted: Observations, params: ParameterSet,
                  free: Sequence[str], draws: int | None, seed: int, factor: int, say: Callable[[str], None]
                  ) -> tuple[list[Diffs], Diffs | None, dict[str, int]]:
    """``(differences at each point, tangent columns or None, unknowns)`` (:func:`estimate`)."""
    tangent = draws is None and bool(free)
    say(f"model error: the calibration on the model's mesh and one refined {factor}x"
        + (", with the parameters' derivatives" if tangent else ""))
    coarse = model.predict(params, fitted, sensitivities=list(free) if tangent else False)
    # derivatives another way than analytic would cost the refined mesh 2 solves per parameter
    tangent = tangent and all(str(v).startswith("analytic") for v in coarse.methods.values())
    fine_params = fine_model.parameters().with_values(params.values())
    fine = fine_model.predict(fine_params, fitted, sensitivities=list(free) if tangent else False)
    info = {"unknowns": int(coarse.info.get("n_dof", 0)), "unknowns_refined": int(fine.info.get("n_dof", 0))}
    diffs = [_differences(coarse, fine, fitted)]
    if tangent:
        return diffs, _tangents(coarse, fine, fitted, params, free, list(diffs[0])), info
    # nothing free: the error does not vary, the calibration alone says it
    points = _draws(params, free, (DEFAULT_DRAWS if draws is None else draws) if free else 0, seed)[1:]
    for i, v in enumerate(points):
        say(f"model error: draw {i + 1}/{len(points)} on the model's mesh and one refined {factor}x")
        coarse = model.predict(params.with_values(v), fitted, sensitivities=False)
        fine = fine_model.predict(fine_params.with_values(v), fitted, sensitivities=False)
        diffs.append(_differences(coarse, fine, fitted))
    return diffs, None, info


def estimate(model: Any, observations: Observations, params: ParameterSet, free: Sequence[str], *,
             draws: int | None = DEFAULT_DRAWS, factor: int = DEFAULT_FACTOR, seed: int = 0,
             progress: Callable[[str], None] | None = None) -> ModelError:
    """The model's discretisation error on the fitted protocols of ``observations`` (see the
    module): ``model`` a finite-element forward model, ``params`` the calibration, ``free`` the
    parameters around it, ``factor`` the refinement. ``draws``: that many random draws around
    the calibration (default :data:`DEFAULT_DRAWS`), or None for the error's variation with the
    parameters from its derivatives at the calibration (one solve on each mesh, with
    sensitivities; random draws when a derivative is not analytic).

    ``summary``: ``factor``, ``orders``, ``draws``, ``variation`` ("tangent" or "draws"),
    ``unknowns``, ``unknowns_refined``, ``solves`` (on each mesh), ``channels`` (name -> ``rms``,
    ``max`` of the mean error [unit], ``noise``, ``rms_over_noise``), ``wall_s``.
    """
    if not has_mesh(model):
        raise DiscretisationError(f"model {getattr(model, 'name', '?')!r} has no mesh: the approximation "
                                  "error needs a finite-element model")
    if draws is not None and (isinstance(draws, bool) or not isinstance(draws, int) or draws < 0):
        raise DiscretisationError(f"draws must be a whole number >= 0 or None, got {draws!r}")
    if isinstance(factor, bool) or not isinstance(factor, int) or factor < 2:
        raise DiscretisationError(f"refinement factor must be a whole number >= 2, got {factor!r}")
    t0 = time.perf_counter()
    say = progress or (lambda _m: None)
    fitted = observations.fitted()
    fine_model = model.refined(factor)
    try:
        diffs, tangents, info = _solve_points(model, fine_model, fitted, params, free, draws, seed, factor,
                                              say)
    finally:
        fine_model.close()
    r_lo, r_hi = richardson_factor(factor, ORDER_HIGH), richardson_factor(factor, ORDER_LOW)
    r_mid, r_sd = 0.5 * (r_lo + r_hi), (r_hi - r_lo) / math.sqrt(12.0)
    K = len(diffs)
    keys = list(diffs[0])
    groups = {key: _groups(fitted[key[0]].channels[key[1]]) for key in keys}
    n_amp = sum(len(g) for g in groups.values())
    n_var = len(free) if tangents is not None else (K if K > 1 else 0)
    rank = n_amp + n_var
    mean, basis = {}, {}
    col = 0
    for key in keys:
        ds = np.stack([d[key] for d in diffs])
        dbar = ds.mean(axis=0)
        mean[key] = r_mid * dbar
        b = np.zeros((rank, *dbar.shape))
        # the order differs from place to place (a force at a bonded edge near 1, a displacement
        # field far from the indenter near 2): one amplitude per component and radial band
        for sel in groups[key]:
            b[col][sel] = r_sd * dbar[sel]
            col += 1
        if tangents is not None:
            # the error's change over the parameters' spread, to first order: the covariance
            # the draws sample, without their sampling noise
            b[n_amp:] = r_mid * tangents[key]
        elif K > 1:
            b[n_amp:] = np.stack([r_mid * (d - dbar) / math.sqrt(K) for d in ds])
        basis[key] = b
    figures = _channel_figures(mean, fitted)
    worst = max((row["rms_over_noise"] or 0.0 for row in figures.values()), default=0.0)
    summary = {"method": "approximation error (mean and covariance of the refined-minus-model prediction)",
               "largest_over_noise": worst,
               # error ∝ hᵖ: the refinement that brings the largest channel's error to the noise
               "refine_to_noise": {"order_1": max(worst, 1.0), "order_2": max(math.sqrt(worst), 1.0)},
               "factor": factor, "orders": [ORDER_LOW, ORDER_HIGH], "draws": K - 1, "spread": SPREAD,
               "variation": "tangent" if tangents is not None else "draws",
               **info, "solves": {"model_mesh": K, "refined_mesh": K},
               "channels": figures, "wall_s": time.perf_counter() - t0}
    return ModelError(mean, basis, rank, summary)


def refit(model: Any, observations: Observations, result: Any, free: Sequence[str], fit: Callable[..., Any],
          *, draws: int | None = DEFAULT_DRAWS, factor: int = DEFAULT_FACTOR, passes: int = DEFAULT_PASSES,
          seed: int = 0, progress: Callable[[str], None] | None = None, **options: Any
          ) -> tuple[Any, Observations]:
    """Estimate the model's error at ``result`` (a calibration of ``free``) and fit again, from
    there, with the error carried as noise; ``passes`` times, each estimate made at the previous
    pass's parameters (the error of a mesh too stiff grows with the modulus the first
    calibration underestimated: two passes move the parameters, a third no more than their
    standard error). Returns ``(the last result, the observations carrying the last estimate)``.
    ``fit(model, observations, free, start=..., **options)`` is the fit to run
    (:func:`skinkit.inverse.fit`). The result's ``extra["model_error"]`` holds the last
    estimate's summary plus ``passes``, ``chi2_without`` (the first calibration's χ²),
    ``chi2_with``, ``dof`` and ``accounts_for`` (the share of the excess it removed:
    :func:`skinkit.inverse.discretisation.explained_share`)."""
    if isinstance(passes, bool) or not isinstance(passes, int) or passes < 1:
        raise DiscretisationError(f"passes must be a whole number >= 1, got {passes!r}")
    first, new, carried = result, result, observations
    err = None
    for k in range(passes):
        err = estimate(model, observations, new.parameters, free, draws=draws, factor=factor, seed=seed + k,
                       progress=progress)
        carried = observations.with_model_error(err)
        values = new.parameters.values()
        if progress is not None:
            progress("model error: calibrating again with the mesh's error carried as noise "
                     f"(pass {k + 1}/{passes})")
        new = fit(model, carried, list(free), start={n: float(values[n]) for n in free}, **options)
    c0, c1 = sum(first.residual_by_protocol.values()), sum(new.residual_by_protocol.values())
    dof = c0 / float(first.chi2_per_dof) if first.chi2_per_dof else float("nan")
    err.summary.update(passes=passes, chi2_without=c0, chi2_with=c1, dof=dof,
                       accounts_for=explained_share(c0, c1, dof))
    new.extra["model_error"] = err.summary
    return new, carried


def describe(summary: Mapping[str, Any]) -> list[str]:
    """Lines for a terminal: per channel the model's mesh error against the noise."""
    lines = [f"model error (mesh refined {summary['factor']}x, {summary.get('unknowns', 0):,} -> "
             f"{summary.get('unknowns_refined', 0):,} unknowns; carried as noise):"]
    for cname, row in summary.get("channels", {}).items():
        unit, k = row.get("unit") or "", 1.0
        if unit == "m":
            unit, k = "µm", 1e6
        ratio = row.get("rms_over_noise")
        times = "?" if ratio is None else f"{ratio:.3g}"
        lines.append(f"  {cname}: {k * row['rms']:.3g} {unit} RMS ({times} "
                     f"noise levels), {k * row['max']:.3g} {unit} largest")
    share = summary.get("accounts_for")
    if share is not None:
        lines.append(f"  accounts for {100 * share:.0f} % of the residual's excess over the noise")
    return lines


__all__ = ["DEFAULT_DRAWS", "DEFAULT_PASSES", "ModelError", "ORDER_HIGH", "ORDER_LOW", "SPREAD",
           "apply", "describe", "estimate", "not_estimated", "refit", "whitening"]
