"""Conformance check any law author can run: ``check_law(law)``, offered to law authors as
:mod:`skinkit.plugin.conformance.laws` (the declared, stable API; this engine module may change).

It verifies, on a seeded set of deformations (stretches of up to ±20 %, shears, rotations):

* ``stress``: the law's stress against central differences of its energy;
* ``tangent``: the law's (or derived) tangent against central differences of its stress,
  and its minor and major symmetries;
* ``objectivity``: the Cauchy stress of ``Q F`` equals ``Q σ(F) Qᵀ`` for random rotations
  (it catches a stress that is not a function of C, or not symmetric);
* ``reference``: zero stress at ``C = I``;
* ``initial moduli``: at the parameters checked, the tangent at ``C = I`` is positive definite
  (positive small-strain bulk modulus Σᵢⱼ CCᵢᵢⱼⱼ/9 and shear moduli CCᵢⱼᵢⱼ, i ≠ j);
* ``tension``: an isochoric stretch of 0.1 %, 10 % and 20 % along x, y and z gives a Cauchy
  stress along the stretch above the mean of the two across it, and a volumetric expansion a
  positive mean stress;
* ``admissible ranges``: the same two checks on parameter sets spread over the declared bounds
  (each bound, and seeded draws between them) that the law's own conditions
  (``inadmissible(p)``, see :mod:`skinkit.fem.lawkit`) accept — what a model file may set must
  respond physically, for third-party laws as for the built-in ones.

Tolerances follow from the difference formula: a central difference with step h has a
truncation error ~h² |f'''| and a rounding error ~eps |f| / h; with h = 1e-5 on O(1)
strains both are below 1e-8 of the stress scale, so a relative error above 1e-6 is a bug.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.fem import lawkit
from skinkit.fem.tensors import VOIGT, sym_direction

#: finite-difference step in C for the checks (see module docstring)
_H = 1e-5
#: relative tolerance of derivative checks (see module docstring)
DERIVATIVE_RTOL = 1e-6


@dataclass
class CheckResult:
    """One check: its name, outcome, worst relative error and tolerance."""

    name: str
    passed: bool
    error: float
    tolerance: float
    detail: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The check as a plain dict (JSON-ready)."""
        return {"name": self.name, "passed": self.passed, "error": self.error,
                "tolerance": self.tolerance, "detail": self.detail}


@dataclass
class ConformanceReport:
    """All checks of one law; ``passed`` when every one passed."""

    law: str
    checks: list[CheckResult] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        """True when every check passed."""
        return all(c.passed for c in self.checks)

    def to_dict(self) -> dict[str, Any]:
        """The law's checks as a plain dict (JSON-ready)."""
        return {"law": self.law, "passed": self.passed, "checks": [c.to_dict() for c in self.checks]}

    def __str__(self) -> str:
        lines = [f"law {self.law}: {'PASS' if self.passed else 'FAIL'}"]
        for c in self.checks:
            lines.append(f"  {'ok  ' if c.passed else 'FAIL'} {c.name}: error {c.error:.2e} "
                         f"(tolerance {c.tolerance:.0e}) {c.detail}")
        return "\n".join(lines)


def random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """``(n, 3, 3)`` uniformly random proper rotations."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


def sample_deformations(n: int = 12, seed: int = 0, amplitude: float = 0.2) -> np.ndarray:
    """``(n, 3, 3)`` deformation gradients: stretches and shears within ±``amplitude``."""
    rng = np.random.default_rng(seed)
    F = np.eye(3) + rng.uniform(-amplitude, amplitude, size=(n, 3, 3))
    F[0] = np.diag([1 + amplitude, 1 / np.sqrt(1 + amplitude), 1 / np.sqrt(1 + amplitude)])
    F[1] = np.diag([1 + amplitude, 1 + amplitude, 1 / (1 + amplitude) ** 2])
    return F


def _rel(a: np.ndarray, b: np.ndarray, scale: float) -> float:
    return float(np.max(np.abs(a - b)) / scale)


def check_law(law: Any, p: Mapping[str, Any] | None = None, n: int = 12,
              seed: int = 0) -> ConformanceReport:
    """Run the conformance checks on ``law`` with parameters ``p`` (defaults if None)."""
    p = lawkit.default_parameters(law) if p is None else lawkit.check_parameters(law, p)
    rep = ConformanceReport(getattr(law, "name", type(law).__name__))
    F = sample_deformations(n, seed)
    C = np.einsum("nkI,nkJ->nIJ", F, F)
    S = lawkit.stress(law, C, p)
    CC = lawkit.tangent(law, C, p)
    scale_S = max(float(np.max(np.abs(S))), 1e-300)
    scale_CC = max(float(np.max(np.abs(CC))), 1e-300)

    # stress against the energy
    S_fd = np.zeros_like(S)
    for K, L in VOIGT:
        E = sym_direction(K, L)
        d = (np.asarray(law.energy(C + _H * E, p)) - np.asarray(law.energy(C - _H * E, p))) / (2 * _H)
        S_fd[:, K, L] = S_fd[:, L, K] = 2 * d
    err = _rel(S, S_fd, scale_S)
    rep.checks.append(CheckResult("stress", err <= DERIVATIVE_RTOL, err, DERIVATIVE_RTOL,
                                  "vs central differences of the energy"))

    # tangent against the stress (its own), or the energy's second differences (when the
    # stress itself is a difference, differencing it again would square the rounding)
    if lawkit.has_own(law, "stress"):
        CC_fd = np.zeros_like(CC)
        for K, L in VOIGT:
            E = sym_direction(K, L)
            dS = (lawkit.stress(law, C + _H * E, p) - lawkit.stress(law, C - _H * E, p)) / (2 * _H)
            CC_fd[..., K, L] = CC_fd[..., L, K] = 2 * dS
        how = "vs central differences of the stress"
    else:
        CC_fd = lawkit.energy_hessian(law, C, p)
        how = "vs second differences of the energy"
    err = _rel(CC, CC_fd, scale_CC)
    rep.checks.append(CheckResult("tangent", err <= DERIVATIVE_RTOL, err, DERIVATIVE_RTOL, how))
    sym_err = max(_rel(CC, CC.transpose(0, 2, 1, 3, 4), scale_CC),
                  _rel(CC, CC.transpose(0, 1, 2, 4, 3), scale_CC),
                  _rel(CC, CC.transpose(0, 3, 4, 1, 2), scale_CC))
    # rounding only: symmetries hold exactly in exact arithmetic
    rep.checks.append(CheckResult("tangent symmetries", sym_err <= 1e-10, sym_err, 1e-10,
                                  "minor and major"))

    # objectivity of the Cauchy stress
    Q = random_rotations(np.random.default_rng(seed + 1), n)
    def cauchy(F_: np.ndarray) -> np.ndarray:
        C_ = np.einsum("nkI,nkJ->nIJ", F_, F_)
        S_ = lawkit.stress(law, C_, p)
        return np.einsum("niI,nIJ,njJ->nij", F_, S_, F_) / np.linalg.det(F_)[:, None, None]
    s1 = cauchy(F)
    QF = np.einsum("nij,njK->niK", Q, F)
    err = _rel(cauchy(QF), np.einsum("nij,njk,nlk->nil", Q, s1, Q), scale_S)
    # the same arithmetic in a rotated frame: rounding-level agreement, amplified by 1/h
    # when the stress is a central difference of the energy
    tol = 1e-9 if lawkit.has_own(law, "stress") or lawkit.is_complex_safe(law) else 1e-7
    rep.checks.append(CheckResult("objectivity", err <= tol, err, tol,
                                  "sigma(QF) = Q sigma(F) Q^T"))
    asym = _rel(S, S.transpose(0, 2, 1), scale_S)
    rep.checks.append(CheckResult("stress symmetry", asym <= 1e-12, asym, 1e-12, ""))

    # reference state
    S0 = lawkit.stress(law, np.eye(3)[None], p)
    err = float(np.max(np.abs(S0)) / scale_S)
    tol = 1e-9 if lawkit.has_own(law, "stress") or lawkit.is_complex_safe(law) else 1e-7
    rep.checks.append(CheckResult("reference", err <= tol, err, tol, "S(I) = 0"))

    # physical response at p, then over the declared ranges
    bad = _response_problem(law, p)
    # error: 1 when the response is unphysical, 0 when not (a yes/no check)
    rep.checks.append(CheckResult("initial moduli and tension", bad is None, float(bad is not None), 0.0,
                                  bad or "positive moduli at C = I, tensile stress in tension"))
    rep.checks.append(check_ranges(law, seed=seed))
    return rep


#: relative size below which a modulus counts as zero: tangents by central differences carry
#: errors of about 1e-8 of their scale (see the module docstring), complex-step ones far less
MODULUS_RTOL = 1e-7
#: isochoric stretches of the tension check [1]: the small-strain limit and finite strains
TENSION_STRETCHES = (1.001, 1.1, 1.2)
#: volumetric stretch of the bulk check [1]
VOLUME_STRETCH = 1.01


def _mandel(CC: np.ndarray) -> np.ndarray:
    """``(6, 6)`` Mandel matrix of a tangent with minor symmetries: E:CC:E = e·M·e."""
    w = [1.0 if K == L else np.sqrt(2.0) for K, L in VOIGT]
    M = np.empty((6, 6))
    for a, (i, j) in enumerate(VOIGT):
        for b, (k, l) in enumerate(VOIGT):
            M[a, b] = w[a] * w[b] * CC[i, j, k, l]
    return M


def initial_moduli(law: Any, p: Mapping[str, Any]) -> dict[str, float]:
    """Small-strain moduli of ``law`` at ``p`` [Pa] from its tangent at ``C = I``: ``bulk``
    (Σᵢⱼ CCᵢᵢⱼⱼ/9, λ + 2μ/3 for an isotropic law), ``shear`` (the least of CCᵢⱼᵢⱼ, i ≠ j:
    μ), ``min_eigenvalue`` of the Mandel matrix (positive: stable at the reference) and
    ``scale`` (its largest eigenvalue magnitude)."""
    CC = np.real(lawkit.tangent(law, np.eye(3)[None], p))[0]
    ev = np.linalg.eigvalsh(0.5 * (_mandel(CC) + _mandel(CC).T))
    return {"bulk": float(np.einsum("iijj->", CC) / 9.0),
            "shear": float(min(CC[0, 1, 0, 1], CC[0, 2, 0, 2], CC[1, 2, 1, 2])),
            "min_eigenvalue": float(ev.min()), "scale": float(np.abs(ev).max())}


def _cauchy(law: Any, F: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    S = np.real(lawkit.stress(law, (F.T @ F)[None], p))[0]
    return F @ S @ F.T / np.linalg.det(F)


def _response_problem(law: Any, p: Mapping[str, Any]) -> str | None:
    """None when ``law`` at ``p`` has positive initial moduli and answers tension with
    tension, else what is wrong (one line)."""
    with np.errstate(all="ignore"):
        m = initial_moduli(law, p)
        scale = m["scale"]
        if not (np.isfinite(scale) and scale > 0):
            return f"the tangent at C = I is {scale:g} (not a positive finite scale)"
        tol = MODULUS_RTOL * scale
        for key, label in (("bulk", "bulk modulus"), ("shear", "shear modulus"),
                           ("min_eigenvalue", "least eigenvalue of the tangent")):
            if not m[key] > tol:
                return (f"initial {label} {m[key]:.4g} Pa is not positive (tangent scale "
                        f"{scale:.3g} Pa)")
        for lam in TENSION_STRETCHES:
            for a in range(3):
                d = np.full(3, lam ** -0.5)
                d[a] = lam
                sig = _cauchy(law, np.diag(d), p)
                diff = sig[a, a] - 0.5 * (np.trace(sig) - sig[a, a])
                # the small-strain value is about 3 mu (lam - 1): demand a tenth of it at least
                need = 0.1 * 3 * m["shear"] * (lam - 1)
                if not diff > need:
                    return (f"isochoric stretch {lam:g} along {'xyz'[a]}: Cauchy stress along it exceeds "
                            f"the mean across it by {diff:.4g} Pa (needs > {need:.3g} Pa, a tenth of "
                            "the small-strain 3 mu (lambda - 1))")
        sig = _cauchy(law, VOLUME_STRETCH * np.eye(3), p)
        if not np.trace(sig) / 3 > 0:
            return (f"volumetric stretch {VOLUME_STRETCH:g}: mean stress {np.trace(sig) / 3:.4g} Pa "
                    "(needs > 0)")
    return None


def _candidates(q: Any, rng: np.random.Generator, k: int) -> list[float]:
    """Bounds of parameter ``q`` (an infinite one stands in as ten times its default's
    magnitude) and ``k`` seeded draws between them (log-uniform over decades when positive)."""
    ref = max(abs(float(q.value)), 1e-3)
    lo = float(q.lower) if np.isfinite(q.lower) else -10 * ref
    hi = float(q.upper) if np.isfinite(q.upper) else 10 * ref
    out = [lo, hi]
    if lo > 0:
        out += list(np.exp(rng.uniform(np.log(lo), np.log(hi), k)))
    else:
        out += list(rng.uniform(lo, hi, k))
    return out


def parameter_sets(law: Any, n: int = 48, seed: int = 0) -> list[dict[str, float]]:
    """Parameter sets over the declared ranges: the defaults; each parameter at each of its
    bounds with the others at their defaults; ``n`` seeded draws of every parameter at once
    (a bound one time in four, else between them)."""
    rng = np.random.default_rng(seed)
    params = list(law.parameters())
    base = {q.name: float(q.value) for q in params}
    cands = {q.name: _candidates(q, rng, 8) for q in params}
    out = [dict(base)]
    for q in params:
        for v in cands[q.name][:2]:
            out.append(dict(base, **{q.name: v}))
    for _ in range(n):
        out.append({q.name: float(cands[q.name][rng.integers(0, 2)] if rng.random() < 0.25
                                  else cands[q.name][2 + rng.integers(0, 8)]) for q in params})
    return out


def check_ranges(law: Any, n: int = 48, seed: int = 0) -> CheckResult:
    """The ``admissible ranges`` check (see the module docstring): every parameter set of
    :func:`parameter_sets` the law accepts (bounds and its own conditions) must have positive
    initial moduli and answer tension with tension. ``error`` is the number of offending sets."""
    from skinkit.fem.errors import ModelError
    accepted = refused = 0
    for q in parameter_sets(law, n, seed):
        try:
            lawkit.check_parameters(law, q)
        except ModelError:
            refused += 1
            continue
        accepted += 1
        bad = _response_problem(law, q)
        if bad is not None:
            shown = ", ".join(f"{k}={v:.4g}" for k, v in q.items())
            return CheckResult("admissible ranges", False, 1.0, 0.0,
                               f"the declared ranges and the law's conditions admit {shown}, where {bad}; "
                               "narrow the bounds or refuse it in inadmissible(p)")
    return CheckResult("admissible ranges", True, 0.0, 0.0,
                       f"{accepted} parameter sets in the declared ranges respond physically "
                       f"({refused} refused by the bounds or the law's conditions)")
