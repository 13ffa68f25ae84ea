"""What the data determine at an optimum: covariance, correlation, the thesis's metrics.

With noise-weighted residuals z (each a standard normal under the noise model) and their
Jacobian J with respect to the free parameters, the Fisher information is F = JᵀJ and the
Gauss–Newton Hessian of φ = ½ Σ z² is H = JᵀJ (thesis Eqs 7.15–7.16). The covariance of the
estimate is F⁻¹, inflated by χ²/ν when the fit is worse than the noise explains (a model
error the noise level does not cover); standard errors and the correlation matrix follow.

Metrics (Eqs 7.16–7.18, Table 15), in the scaled coordinates of the fit (Eq 7.13): det H
(the indifference region's volume shrinks as it grows), the condition number λmax/λmin (1 is
ideal; the thesis tabulates λmin/λmax), and det H̃ with H̃ᵢⱼ = Hᵢⱼ/√(Hᵢᵢ Hⱼⱼ) (1: no
correlation; 0: a valley). The eigen-directions of H with the smallest eigenvalues are the
long axes of the indifference ellipsoid; the parameters with large components along them
are those the data trade off.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: |correlation| above which a pair is reported as not separately identifiable, unless both
#: standard errors are within PAIR_RELATIVE_SE of the values (then: "correlated", still determined)
PAIR_LIMIT = 0.95
PAIR_RELATIVE_SE = 0.1
#: |correlation| above which a pair is reported when one of the two is undetermined
PAIR_LIMIT_WITH_UNDETERMINED = 0.8
#: |correlation| above which a pair is a valley whatever its standard errors
PAIR_HARD_LIMIT = 0.999
#: a standard error above this fraction of the parameter's value (or scaled range) is "not determined"
RELATIVE_SE_LIMIT = 0.5


def analyse(J: np.ndarray, z: np.ndarray, names: list[str], values: np.ndarray,
            dvalue_dscaled: np.ndarray, noise_weighted: bool = True,
            meat: np.ndarray | None = None) -> dict[str, Any]:
    """Identifiability at an optimum (module docstring).

    ``J`` ``(m, n)``: ∂z/∂p [1 per SI unit]; ``z`` ``(m,)``; ``values`` ``(n,)`` the estimate [SI];
    ``dvalue_dscaled`` ``(n,)`` dp/dθ of the fit's scaling. JSON-ready dict with
    ``covariance`` (SI²), ``se``, ``correlation``, the metrics, the weak directions, and
    ``problems`` (pairs that trade off and parameters the data do not determine, in words,
    each with a suggestion). ``meat`` ``(n, n)``: Jᵀ C J when the residuals are correlated
    (C their correlation, e.g. :func:`skinkit.inverse.overlap.overlap_meat`); the covariance is
    then the sandwich F⁻¹ (Jᵀ C J) F⁻¹ before the χ²/ν inflation.
    """
    m, n = J.shape
    dof = max(m - n, 1)
    chi2 = float(z @ z)
    F = J.T @ J
    # inverted in the fit's scaled coordinates (each column in units of the parameter's scale):
    # in SI the columns may differ by 1e15 (newtons against 1/m), and a relative eigenvalue
    # cut would call a well-determined parameter flat
    D0 = np.asarray(dvalue_dscaled, dtype=float) if n else np.ones(0)
    D0 = np.where(np.isfinite(D0) & (np.abs(D0) > 0), np.abs(D0), 1.0)
    Fs = F * np.outer(D0, D0)
    w, V = np.linalg.eigh(Fs)
    tol = max(w.max(), 0.0) * 1e-14 * n if n else 0.0
    inv_w = np.where(w > tol, 1.0 / np.where(w > tol, w, 1.0), 0.0)
    cov = ((V * inv_w) @ V.T) * np.outer(D0, D0)
    if meat is not None:
        cov = cov @ np.asarray(meat, float) @ cov
    singular = [i for i in range(n) if w[i] <= tol]
    inflation = max(1.0, chi2 / dof) if noise_weighted else chi2 / dof
    cov = cov * inflation
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    for i in singular:   # a flat direction: infinite uncertainty along it
        se = np.where(np.abs(V[:, i]) > 0.1, np.inf, se)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    np.fill_diagonal(corr, 1.0)
    # Hessian in scaled coordinates (Eq 7.13): H_θ = D F D, D = dp/dθ
    D = np.diag(dvalue_dscaled)
    H = D @ F @ D
    hw, hV = np.linalg.eigh(H)
    dH = np.sqrt(np.maximum(np.diag(H), 1e-300))
    Ht = H / np.outer(dH, dH)
    metrics = {
        "det_H": float(np.linalg.det(H)) if n else 1.0,
        "cond_H": float(hw.max() / hw.min()) if n and hw.min() > 0 else float("inf"),
        "inverse_cond_H": float(hw.min() / hw.max()) if n and hw.max() > 0 else 0.0,
        "det_H_normalised": float(np.linalg.det(Ht)) if n else 1.0,
    }
    directions = []
    for k in np.argsort(hw)[: min(n, 3)]:
        v = hV[:, k]
        comps = {names[i]: float(v[i]) for i in np.argsort(-np.abs(v)) if abs(v[i]) > 0.3}
        directions.append({"eigenvalue": float(hw[k]), "couples": comps})
    problems = []
    for i in range(n):
        for j in range(i + 1, n):
            rel = [se[k] / abs(values[k]) if values[k] != 0 else se[k] / abs(dvalue_dscaled[k])
                   for k in (i, j)]
            c = abs(corr[i, j])
            if c > PAIR_LIMIT and max(rel) <= PAIR_RELATIVE_SE and c <= PAIR_HARD_LIMIT:
                # correlated, yet both pinned down: worth saying, not a failure
                problems.append({"kind": "correlated", "parameters": [names[i], names[j]],
                                 "correlation": float(corr[i, j]), "fix": None,
                                 "message": f"{names[i]} and {names[j]} are strongly correlated "
                                            f"({corr[i, j]:+.3f}) but both determined (standard "
                                            f"errors {100 * rel[0]:.2g} % and {100 * rel[1]:.2g} % of "
                                            "their values)"})
                continue
            # a correlated partner of an undetermined parameter: its linearised interval assumes
            # the partner known, which it is not, so neither value can be trusted alone
            weak_pair = c > PAIR_LIMIT_WITH_UNDETERMINED and max(rel) > RELATIVE_SE_LIMIT
            if c > PAIR_LIMIT or weak_pair or (not np.isfinite(se[i]) and not np.isfinite(se[j])):
                fix = names[i] if rel[0] >= rel[1] else names[j]
                msg = (f"{names[i]} and {names[j]} are not separately identifiable from these protocols "
                       f"(correlation {corr[i, j]:+.3f}): they trade off along a valley of the objective; "
                       f"fix {fix} (e.g. at a literature value) and fit the other")
                problems.append({"kind": "pair", "parameters": [names[i], names[j]],
                                 "correlation": float(corr[i, j]), "fix": fix, "message": msg})
    flagged = {p for pr in problems if pr["kind"] != "correlated" for p in pr["parameters"]}
    for i in range(n):
        scale = abs(values[i]) if values[i] != 0 else abs(dvalue_dscaled[i])
        if names[i] not in flagged and (not np.isfinite(se[i]) or se[i] > RELATIVE_SE_LIMIT * scale):
            problems.append({"kind": "parameter", "parameters": [names[i]], "fix": names[i],
                             "message": f"{names[i]} is not determined by these protocols (standard error "
                                        f"{se[i]:.3g} against a value of {values[i]:.3g}); fix it, or add a "
                                        "protocol that moves it (skinkit design)"})
            flagged.add(names[i])
    return {"covariance": cov.tolist(), "se": se.tolist(), "correlation": corr.tolist(),
            "chi2": chi2, "dof": dof, "chi2_per_dof": chi2 / dof, "inflation": inflation,
            "metrics": metrics, "weak_directions": directions, "problems": problems,
            "identifiable": {nm: nm not in flagged for nm in names}}


__all__ = ["PAIR_HARD_LIMIT", "PAIR_LIMIT", "PAIR_RELATIVE_SE", "RELATIVE_SE_LIMIT", "analyse"]
