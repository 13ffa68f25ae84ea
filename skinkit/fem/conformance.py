"""Conformance check any law author can run: ``check_law(law)``.

It verifies, on a seeded set of deformations (stretches of up to ±20 %, shears, rotations):

* ``stress``: the law's stress against central differences of its energy;
* ``tangent``: the law's (or derived) tangent against central differences of its stress,
  and its minor and major symmetries;
* ``objectivity``: the Cauchy stress of ``Q F`` equals ``Q σ(F) Qᵀ`` for random rotations
  (it catches a stress that is not a function of C, or not symmetric);
* ``reference``: zero stress at ``C = I``.

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
        return {"name": self.name, "passed": self.passed, "error": self.error,
                "tolerance": self.tolerance, "detail": self.detail}


@dataclass
class ConformanceReport:
    """All checks of one law; ``passed`` when every one passed."""

    law: str
    checks: list[CheckResult] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    def to_dict(self) -> dict[str, Any]:
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
        CC_fd = lawkit._energy_hessian(law, C, p)
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
    return rep
