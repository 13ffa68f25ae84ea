"""How much of a calibrated finite-element model's residual, and of its parameters, is
discretisation error.

At the fitted parameters the model is solved once more on a mesh refined ``factor`` times in
every direction. With the coarse and fine predictions ``y_h`` and ``y_{h/f}`` and an assumed
convergence order ``p``, Richardson's estimate of the coarse prediction's error is

    e = (y_{h/f} − y_h) · fᵖ / (fᵖ − 1)            (exact minus coarse)

(``order = 1`` by default: at a bonded punch's edge the stress is singular and uniform
refinement converges with an observed order of 1.3; an order taken lower than the
true one overestimates the error, so the estimate errs on the safe side).

In the fit's whitened residual space (``z`` and ``J`` of the noise-weighted objective):

* ``χ²_disc = |e|²`` — the discretisation error measured in noise units, next to the fit's
  ``χ²`` and its ``ν``;
* ``χ²_exact = |(I − P_J)(z + e)|²`` — the residual an exactly solved model would leave after
  re-adjusting its fitted parameters (linearised: ``P_J`` projects onto J's columns);
* ``bias = (Jᵀ J)⁻¹ Jᵀ e`` — how far the coarse mesh moved each fitted parameter from where the
  exactly solved model would put it (θ_coarse − θ_exact, one Gauss-Newton step; in ln θ for
  positive parameters).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError
from skinkit.inverse.objective import Objective
from skinkit.schemas import ChannelPrediction, FitResult, Observations, ParameterSet, Prediction
from skinkit.schemas.observations import CHANNELS

#: default convergence order assumed by the estimate (module docstring)
DEFAULT_ORDER = 1.0
#: default refinement factor of the check mesh
DEFAULT_FACTOR = 2


class DiscretisationError(SkinkitError):
    """The discretisation check cannot be made (a model without a mesh, a bad factor or order)."""


def has_mesh(model: Any) -> bool:
    """Whether ``model`` can be solved on a refined mesh (finite-element forward models)."""
    return callable(getattr(model, "refined", None))


def richardson_factor(factor: float, order: float) -> float:
    """``fᵖ / (fᵖ − 1)``: (exact − coarse) = this × (fine − coarse) for refinement ``factor`` f
    and convergence ``order`` p."""
    if not factor > 1:
        raise DiscretisationError(f"refinement factor must be > 1, got {factor!r}")
    if not order > 0:
        raise DiscretisationError(f"convergence order must be > 0, got {order!r}")
    r = float(factor) ** float(order)
    return r / (r - 1.0)


def extrapolated(coarse: Prediction, fine: Prediction, factor: float, order: float) -> Prediction:
    """The Richardson-extrapolated prediction ``y_h + R (y_{h/f} − y_h)`` (values only; the
    coarse sensitivities are kept). An entry the fine mesh does not predict keeps its coarse
    value."""
    R = richardson_factor(factor, order)
    out: dict[str, dict[str, ChannelPrediction]] = {}
    for proto, cname, cp in coarse.items():
        fp = fine.protocols.get(proto, {}).get(cname)
        values = np.array(cp.values, float, copy=True)
        if fp is not None and np.shape(fp.values) == values.shape:
            ok = np.isfinite(fp.values) & np.isfinite(values)
            if fp.predicted is not None:
                ok &= np.asarray(fp.predicted, bool)
            values[ok] += R * (np.asarray(fp.values)[ok] - values[ok])
        out.setdefault(proto, {})[cname] = ChannelPrediction(values, dict(cp.d), cp.predicted)
    return Prediction(out, dict(coarse.methods), dict(coarse.inputs), dict(coarse.info))


def _channel_errors(coarse: Prediction, exact: Prediction, observations: Observations) -> dict[str, dict]:
    """RMS and largest |exact − coarse| per channel name over the fitted protocols, in the
    channel's unit (N for forces, m for positions)."""
    acc: dict[str, list[np.ndarray]] = {}
    units: dict[str, str] = {}
    for proto, cname, cp in coarse.items():
        if proto not in observations.names:
            continue
        ch = observations[proto].channels[cname]
        m = cp.mask(ch)
        d = (np.asarray(exact.protocols[proto][cname].values) - np.asarray(cp.values))[m]
        acc.setdefault(cname, []).append(d[np.isfinite(d)])
        units[cname] = CHANNELS[cname][0]
    out = {}
    for cname, parts in acc.items():
        d = np.concatenate(parts) if parts else np.zeros(0)
        out[cname] = {"rms": float(np.sqrt(np.mean(d ** 2))) if d.size else 0.0,
                      "max": float(np.max(np.abs(d))) if d.size else 0.0, "unit": units[cname]}
    return out


def residual_check(z: np.ndarray, J: np.ndarray, e: np.ndarray, values: np.ndarray | None = None,
                   positive: np.ndarray | None = None) -> dict[str, Any]:
    """The whitened residual ``z`` ``(m,)`` of a fit with Jacobian ``J`` ``(m, k)`` (∂z/∂θ, SI)
    against the discretisation error ``e`` ``(m,)`` (exact − coarse prediction, whitened):
    ``chi2`` |z|², ``chi2_discretisation`` |e|², ``chi2_exact`` |(I − P_J)(z + e)|² and the
    share of the excess over ν it removes (``explained_fraction``: rests on the assumed order),
    ``chi2_signature`` |(I − P_[J e]) z|² and its share (``explained_by_signature``: e's
    direction at any size), and the parameter ``bias`` ``(k,)`` [SI] (θ_coarse − θ_exact).

    ``values`` ``(k,)`` [SI] and ``positive`` ``(k,)`` bool: parameters known positive (moduli)
    take the shift in ln θ, θ_exact = θ exp(−Δ): a modulus scales a force, so the shift is
    multiplicative, and a linear step would understate a large bias (a coarse mesh twice too
    stiff halves the fitted modulus; the linear step from the coarse side recovers only half of
    that)."""
    z, e = np.asarray(z, float), np.asarray(e, float)
    J = np.asarray(J, float).reshape(z.size, -1)
    k = J.shape[1]
    nu = max(z.size - k, 1)
    if k:
        step, *_ = np.linalg.lstsq(J, -(z + e), rcond=None)    # the exact model's re-adjustment
        r_exact = z + e + J @ step
        if values is not None and positive is not None and np.any(positive):
            v = np.asarray(values, float)
            pos = np.asarray(positive, bool) & (v > 0)
            scale = np.where(pos, v, 1.0)
            shift, *_ = np.linalg.lstsq(J * scale[None, :], e, rcond=None)
            bias = np.where(pos, v * (1.0 - np.exp(-np.clip(shift, -50, 50))), shift)
        else:
            bias, *_ = np.linalg.lstsq(J, e, rcond=None)
    else:
        r_exact, bias = z + e, np.zeros(0)
    # scale-free: the residual left once the error's direction is free beside the parameters
    # (what the gap diagnosis tests against; its size rests on the assumed order, its shape not)
    A = np.column_stack([J, e]) if np.any(e) else J
    r_sig = z - A @ np.linalg.lstsq(A, z, rcond=None)[0] if A.shape[1] else z
    chi2, chi2_x, chi2_s = float(z @ z), float(r_exact @ r_exact), float(r_sig @ r_sig)
    return {"chi2": chi2, "dof": nu, "chi2_discretisation": float(e @ e), "chi2_exact": chi2_x,
            "explained_fraction": explained_share(chi2, chi2_x, nu), "chi2_signature": chi2_s,
            "explained_by_signature": explained_share(chi2, chi2_s, nu), "bias": bias}


def explained_share(chi2: float, left: float, dof: float) -> float | None:
    """The share of the excess χ² − ν that a residual of χ² ``left`` no longer has (in [0, 1];
    None without an excess): what an error model or a re-adjustment accounts for."""
    excess = chi2 - dof
    if excess <= 0:
        return None
    return float(min(max((chi2 - max(left, dof)) / excess, 0.0), 1.0))


def error_in_residual(model: Any, observations: Observations, params: ParameterSet | dict[str, float],
                      coarse: Prediction, *, weighting: str = "noise", factor: int = DEFAULT_FACTOR,
                      order: float = DEFAULT_ORDER, progress: Any = None
                      ) -> tuple[np.ndarray, dict[str, Any], Prediction]:
    """The discretisation error ``e`` ``(m,)`` of ``coarse`` (``model``'s prediction at
    ``params``) on the fitted protocols of ``observations``, whitened and masked as the
    ``weighting`` objective's residual (exact − coarse); with a JSON-ready summary (``factor``,
    ``order``, ``unknowns``, ``unknowns_refined``, ``channels``: name -> ``rms``, ``max``
    [channel unit], ``unit``) and the extrapolated prediction."""
    if not has_mesh(model):
        raise DiscretisationError(f"model {getattr(model, 'name', '?')!r} has no mesh: a discretisation "
                                  "error estimate needs a finite-element model")
    if isinstance(factor, bool) or not isinstance(factor, int) or factor < 2:
        raise DiscretisationError(f"refinement factor must be a whole number >= 2, got {factor!r}")
    richardson_factor(factor, order)
    fitted = observations.fitted()
    coarse = Prediction({p: c for p, c in coarse.protocols.items() if p in fitted.names},
                        dict(coarse.methods), dict(coarse.inputs), dict(coarse.info))
    fine_model = model.refined(factor)
    try:
        if progress is not None:
            progress(f"discretisation check: solving on a mesh refined {factor}x")
        if not isinstance(params, ParameterSet):
            params = fine_model.parameters().with_values(dict(params))
        fine = fine_model.predict(params, fitted, sensitivities=False)
    finally:
        fine_model.close()
    exact = extrapolated(coarse, fine, factor, order)
    obj = Objective(model, fitted, [], weighting)
    zc, zx = obj.residual(coarse, jacobian=False).z, obj.residual(exact, jacobian=False).z
    if zx.size != zc.size:   # cannot happen: the masks are the coarse prediction's
        raise DiscretisationError("the refined prediction does not cover the coarse one's entries")
    summary = {"factor": factor, "order": order,
               "unknowns": int(coarse.info.get("n_dof", 0)),
               "unknowns_refined": int(fine.info.get("n_dof", 0)),
               "channels": _channel_errors(coarse, exact, fitted)}
    return zx - zc, summary, exact


def estimate(model: Any, observations: Observations, params: ParameterSet, free: Sequence[str], *,
             weighting: str = "noise", factor: int = DEFAULT_FACTOR, order: float = DEFAULT_ORDER,
             coarse: Prediction | None = None, progress: Any = None) -> dict[str, Any]:
    """The discretisation error of ``model`` (a finite-element forward model) at ``params``
    on the fitted protocols of ``observations``, for the parameters ``free``.

    Returns a JSON-ready dict: :func:`error_in_residual`'s summary, the residual figures of
    :func:`residual_check` (``chi2``, ``dof``, ``chi2_discretisation``, ``chi2_exact``,
    ``explained_fraction``), ``parameters`` (name -> ``value``, ``bias`` [SI], θ_coarse −
    θ_exact) and ``wall_s``. ``coarse``: the model's own prediction at ``params`` with
    sensitivities to ``free``, when already at hand.
    """
    t0 = time.perf_counter()
    names = list(free)
    fitted = observations.fitted()
    if coarse is None:
        if not has_mesh(model):
            raise DiscretisationError(f"model {getattr(model, 'name', '?')!r} has no mesh: a discretisation "
                                      "error estimate needs a finite-element model")
        coarse = model.predict(params, fitted, sensitivities=names)
    e, summary, _ = error_in_residual(model, observations, params, coarse, weighting=weighting,
                                      factor=factor, order=order, progress=progress)
    rc = Objective(model, fitted, names, weighting).residual(
        Prediction({p: c for p, c in coarse.protocols.items() if p in fitted.names}), jacobian=True)
    values = params.values()
    chk = residual_check(rc.z, rc.J, e, np.array([values[n] for n in names]),
                         np.array([params.param(n).lower >= 0 for n in names]))
    return {**summary, **{k: v for k, v in chk.items() if k != "bias"},
            "parameters": {n: {"value": float(values[n]), "bias": float(b)}
                           for n, b in zip(names, chk["bias"], strict=True)},
            "wall_s": time.perf_counter() - t0}


def attach(result: FitResult, est: dict[str, Any]) -> FitResult:
    """Store ``est`` in ``result.extra["discretisation"]``, each
    parameter's bias beside its standard error."""
    d = dict(est)
    for n, row in d.get("parameters", {}).items():
        se = result.se.get(n)
        row["se"] = float(se) if se is not None and np.isfinite(se) else None
    result.extra["discretisation"] = d
    return result


def describe(est: dict[str, Any]) -> list[str]:
    """Lines for a terminal: the channels' errors, χ² beside the residual, each parameter's bias."""
    lines = [f"discretisation (mesh refined {est['factor']}x, {est['unknowns']:,} -> "
             f"{est['unknowns_refined']:,} unknowns, order {est['order']:g} assumed):"]
    for cname, row in est["channels"].items():
        unit, k = row.get("unit") or "", 1.0
        if unit == "m":   # positions read in micrometres
            unit, k = "µm", 1e6
        lines.append(f"  {cname}: error {k * row['rms']:.3g} {unit} RMS, {k * row['max']:.3g} {unit} largest")
    frac = est.get("explained_fraction")
    lines.append(f"  χ² {est['chi2']:.5g} (ν {est['dof']}); discretisation error alone "
                 f"{est['chi2_discretisation']:.4g}; an exactly solved model would leave "
                 f"{est['chi2_exact']:.5g}"
                 + ("" if frac is None else f" ({100 * frac:.0f} % of the excess explained)"))
    for n, row in est["parameters"].items():
        rel = abs(row["bias"]) / abs(row["value"]) if row["value"] else float("nan")
        se = row.get("se")
        lines.append(f"  {n}: bias {row['bias']:+.3g} ({100 * rel:.2g} %)"
                     + ("" if se is None else f", standard error {se:.3g}"))
    return lines


__all__ = ["DEFAULT_FACTOR", "DEFAULT_ORDER", "DiscretisationError", "attach", "describe", "estimate",
           "error_in_residual", "explained_share", "extrapolated", "has_mesh", "residual_check",
           "richardson_factor"]
