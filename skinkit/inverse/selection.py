"""Model selection over free-parameter subsets: AIC and AICc beside held-out error (thesis 7.6, Table 13).

For each subset of free parameters the model is fitted (:func:`skinkit.inverse.fit`) to the
session's fitted protocols and scored by

* **AIC** (thesis Eq 7.14, after Anderson, Burnham & White): AIC = N ln(SSE/N) + 2(M + 1),
  N the number of residual samples, SSE = Σz² of the fit's weighted residual (with the
  ``noise`` weighting a χ²), M the number of *fitted* parameters (the + 1 counts the residual
  variance). Table 13 counts every parameter of the constitutive law in M, fixed ones too;
  that adds the same constant to every row of a table over one law, so ΔAIC is unchanged.
* **AICc** = AIC + 2(M + 1)(M + 2)/(N − M − 2), the small-sample correction (equal to AIC when
  N ≫ M²);
* ΔAIC (from the smallest) and **Akaike weights** wᵢ = exp(−Δᵢ/2) / Σⱼ exp(−Δⱼ/2), the
  relative support for each subset given the data;
* **held-out error**: the RMS of the weighted residual (noise levels, with ``noise``) of
  protocols the fit did not see — (a) those the session marks held out, predicted by the fit
  on the others, and (b) **k-fold by protocol**: each fitted protocol left out in turn, the
  subset refitted to the rest, the left-out one predicted. Pooled over protocols as
  √(Σ z² / Σ n). For a model whose structure is right, this is ≈ 1 noise level (slightly
  above: the estimate's own error adds ≈ M/N_fit); a missing parameter the data need raises
  it, a superfluous one barely moves it, and an over-fitted one raises it again.

Subsets are ranked by AICc (``rank_by``), ties kept in the order given.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError
from skinkit.inverse.fit import fit, free_set
from skinkit.inverse.objective import Objective
from skinkit.schemas import Observations, ParameterSet

FOLDS = ("protocol", None)
RANK_BY = ("aicc", "aic", "kfold")


class SelectionError(SkinkitError):
    """A model-selection request that cannot run: bad subsets, folds on one protocol."""


def parse_subsets(text: str) -> list[list[str]]:
    """``"a,b;a,b,c"`` as ``[["a", "b"], ["a", "b", "c"]]`` (the CLI's ``--subsets``)."""
    out = [[s.strip() for s in part.split(",") if s.strip()] for part in str(text).split(";")]
    out = [s for s in out if s]
    if not out:
        raise SelectionError(f"--subsets {text!r}: no subset named (use 'a,b;a,b,c')")
    return out


def check_subsets(params: ParameterSet, subsets: Sequence[Sequence[str]]) -> list[list[str]]:
    """The subsets as lists, each checked against the model's parameters; a one-line
    :class:`SelectionError` for an empty, repeated or unknown one."""
    if not subsets:
        raise SelectionError("--subsets: no subset given")
    seen: dict[frozenset[str], int] = {}
    out = []
    for i, s in enumerate(subsets, 1):
        s = [str(n) for n in s]
        if not s:
            raise SelectionError(f"--subsets: subset {i} is empty")
        unknown = [n for n in s if n not in params.names]
        if unknown:
            raise SelectionError(f"--subsets: subset {i} names {', '.join(unknown)}, which the model does "
                                 f"not have; it has {', '.join(params.names)}")
        if len(set(s)) != len(s):
            raise SelectionError(f"--subsets: subset {i} names a parameter twice ({','.join(s)})")
        key = frozenset(s)
        if key in seen:
            raise SelectionError(f"--subsets: subset {i} repeats subset {seen[key]} ({','.join(s)})")
        seen[key] = i
        out.append(s)
    return out


def _residual_of(model: Any, params: ParameterSet, obs: Observations,
                 weighting: str) -> dict[str, np.ndarray]:
    """Weighted residual per protocol of ``obs`` at ``params`` (one prediction, no sensitivities)."""
    obj = Objective(model, obs, [], weighting)
    res, _ = obj.evaluate(params, jacobian=False)
    out: dict[str, list[np.ndarray]] = {}
    for p, _, sl in res.blocks:
        out.setdefault(p, []).append(res.z[sl])
    return {p: np.concatenate(v) for p, v in out.items()}


def _pooled(z: dict[str, np.ndarray]) -> float | None:
    """√(Σz² / Σn) over protocols, None without samples."""
    n = sum(v.size for v in z.values())
    return float(np.sqrt(sum(float(v @ v) for v in z.values()) / n)) if n else None


def _rms(z: dict[str, np.ndarray]) -> dict[str, float]:
    return {p: float(np.sqrt(np.mean(v ** 2))) for p, v in z.items() if v.size}


def akaike_weights(values: Sequence[float]) -> list[float]:
    """wᵢ = exp(−Δᵢ/2) / Σ exp(−Δⱼ/2), Δᵢ = valueᵢ − min (AIC or AICc)."""
    v = np.asarray(values, float)
    w = np.exp(-0.5 * (v - v.min()))
    return (w / w.sum()).tolist()


def select(model: Any, observations: Observations, subsets: Sequence[Sequence[str]], weighting: str = "noise",
           folds: str | None = "protocol", *, optimiser: str = "scipy-lsq", max_iterations: int = 50,
           start: dict[str, float] | None = None, rank_by: str = "aicc",
           progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Fit ``model`` with each subset of free parameters and score it (module docstring).

    ``observations``: the session (protocols marked held out are predicted, never fitted);
    ``subsets``: lists of parameter names; ``weighting``: as :func:`skinkit.inverse.fit`;
    ``folds``: ``"protocol"`` (k-fold by protocol over the fitted protocols; needs at least
    two) or None; ``start``: start values (default the model's, the same for every subset
    and fold); ``rank_by``: ``"aicc"``, ``"aic"`` or ``"kfold"``; ``progress(message)``.

    Returns a JSON-ready dict: ``rows`` (one per subset, ranked best first: ``rank``, ``free``,
    ``k``, ``n``, ``chi2``, ``chi2_per_dof``, ``aic``, ``aicc``, ``delta_aic``, ``delta_aicc``,
    ``weight_aic``, ``weight_aicc``, ``held_out`` {protocol: RMS}, ``held_out_rms``, ``kfold``
    {protocol: RMS}, ``kfold_rms``, ``parameters`` {name: {value, se, unit}}, ``converged``,
    ``problems``), ``best`` (the free list of the first row), and the settings.
    """
    if folds not in FOLDS:
        raise SelectionError(f"--folds {folds!r}: must be 'protocol' or none")
    if rank_by not in RANK_BY:
        raise SelectionError(f"rank_by {rank_by!r}: must be one of {', '.join(RANK_BY)}")
    base = model.parameters()
    subsets = check_subsets(base, subsets)
    fitted = observations.fitted()
    names = fitted.names
    if not names:
        raise SelectionError("session: every protocol is held out; nothing is left to fit")
    if folds == "protocol" and len(names) < 2:
        raise SelectionError(f"--folds protocol: the session has one fitted protocol ({names[0]}); k-fold by "
                             "protocol needs at least two (or use --folds none)")
    if rank_by == "kfold" and folds is None:
        raise SelectionError("rank_by 'kfold' needs folds='protocol'")
    held = observations.held_out()
    rows = []
    for i, subset in enumerate(subsets, 1):
        say = progress or (lambda _m: None)
        say(f"subset {i}/{len(subsets)} [{','.join(subset)}]: fit on {len(names)} protocol(s)")
        r = fit(model, fitted, subset, weighting=weighting, optimiser=optimiser, start=start,
                max_iterations=max_iterations)
        chi2, n, k = float(r.extra["chi2"]), int(r.extra["n_observations"]), len(subset)
        z_held = _residual_of(model, r.parameters, held, weighting) if len(held) else {}
        z_fold: dict[str, np.ndarray] = {}
        if folds == "protocol":
            for p in names:
                say(f"subset {i}/{len(subsets)} [{','.join(subset)}]: fold without {p}")
                rest = fitted.select([q for q in names if q != p])
                rf = fit(model, rest, subset, weighting=weighting, optimiser=optimiser, start=start,
                         max_iterations=max_iterations)
                z_fold.update(_residual_of(model, rf.parameters, fitted.select([p]), weighting))
        pset = free_set(r.parameters, subset)
        rows.append({
            "free": list(subset), "k": k, "n": n, "chi2": chi2, "chi2_per_dof": chi2 / max(n - k, 1),
            "aic": float(r.aic), "aicc": float(r.aicc),
            "held_out": _rms(z_held), "held_out_rms": _pooled(z_held),
            "kfold": _rms(z_fold), "kfold_rms": _pooled(z_fold),
            "parameters": {nm: {"value": pset[nm], "se": _finite(r.se.get(nm)), "unit": pset.param(nm).unit}
                           for nm in subset},
            "converged": bool(r.converged),
            "problems": [pr["message"] for pr in r.identifiability.get("problems", [])],
        })
    for crit in ("aic", "aicc"):
        best = min(row[crit] for row in rows)
        for row, w in zip(rows, akaike_weights([row[crit] for row in rows]), strict=True):
            row[f"delta_{crit}"] = row[crit] - best
            row[f"weight_{crit}"] = w
    key = "kfold_rms" if rank_by == "kfold" else rank_by
    order = sorted(range(len(rows)), key=lambda j: (rows[j][key], j))
    ranked = []
    for rank, j in enumerate(order, 1):
        ranked.append({"rank": rank, **rows[j]})
    return {"model": getattr(model, "name", "model"), "weighting": weighting, "folds": folds,
            "rank_by": rank_by, "fitted_protocols": names, "held_out_protocols": held.names,
            "rows": ranked, "best": ranked[0]["free"]}


def _finite(x: float | None) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def format_table(result: dict[str, Any]) -> list[str]:
    """The rows of :func:`select` as text lines (the CLI's table)."""
    has_fold = result["folds"] is not None
    has_held = bool(result["held_out_protocols"])
    w = max([15] + [len(",".join(row["free"])) for row in result["rows"]])
    head = f"{'rank':>4}  {'free parameters':{w}s} {'k':>2} {'chi2/dof':>9} {'AIC':>12} {'dAIC':>8} " \
           f"{'AICc':>12} {'dAICc':>8} {'weight':>6}"
    if has_fold:
        head += f" {'k-fold':>7}"
    if has_held:
        head += f" {'held-out':>8}"
    lines = [head]
    for row in result["rows"]:
        free = ",".join(row["free"])
        line = (f"{row['rank']:>4}  {free:{w}s} {row['k']:>2} {row['chi2_per_dof']:>9.4g} "
                f"{row['aic']:>12.6g} {row['delta_aic']:>8.2f} {row['aicc']:>12.6g} "
                f"{row['delta_aicc']:>8.2f} {row['weight_aicc']:>6.3f}")
        if has_fold:
            line += f" {row['kfold_rms']:>7.3f}"
        if has_held:
            line += f" {row['held_out_rms']:>8.3f}" if row["held_out_rms"] is not None else f" {'-':>8}"
        lines.append(line)
    return lines


__all__ = ["FOLDS", "RANK_BY", "SelectionError", "akaike_weights", "check_subsets", "format_table",
           "parse_subsets", "select"]
