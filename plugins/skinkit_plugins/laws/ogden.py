"""Uncoupled N-term Ogden law.

W = Σₚ 2μₚ/αₚ² (λ̄₁^αₚ + λ̄₂^αₚ + λ̄₃^αₚ - 3) + U(J) (Abaqus form: small-strain shear
modulus Σₚ μₚ), with λ̄ₐ = J^(-1/3) λₐ the isochoric principal stretches.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit.plugin.laws import (
    check_volumetric,
    require_positive,
    volumetric_energy,
)
from skinkit.schemas import Parameter

#: smallest admissible |αᵢ|: the energy 2μ/α² (λ̄^α - 1) is singular at α = 0
ALPHA_MIN = 0.01


def _principal(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, N = np.linalg.eigh(np.asarray(C, dtype=float))
    return c, N


class Ogden:
    """Parameters ``mu1, alpha1, ..., muN, alphaN`` and ``K``; option ``terms`` (N ≥ 1).

    The stress uses the spectral form S = Σₐ 2 ∂W/∂cₐ Nₐ⊗Nₐ (cₐ eigenvalues of C), which
    stays exact for repeated eigenvalues; the tangent is derived by the engine by central
    differences of the stress (eigen-decompositions are not complex-step safe).
    """

    name = "ogden"
    complex_safe = False

    def __init__(self, terms: int = 1, volumetric: str = "quadratic") -> None:
        if (isinstance(terms, bool) or not isinstance(terms, (int, float))
                or not float(terms).is_integer() or terms < 1):
            raise ValueError(f"terms must be a positive integer, got {terms!r}")
        check_volumetric(volumetric)
        self.terms = int(terms)
        self.volumetric = volumetric

    @staticmethod
    def verification_cases() -> list[dict[str, Any]]:
        """The cases ``skinkit verify`` runs for this law (keys: :mod:`skinkit.fem.verify`): two terms."""
        return [{"name": "ogden-2", "options": {"terms": 2}}]

    def parameters(self) -> list[Parameter]:
        """Declared parameters: ``mu1, alpha1, ..., muN, alphaN`` ([Pa], [1]), then ``K`` [Pa]."""
        out = []
        for i in range(1, self.terms + 1):
            # μᵢ > 0 is Ogden's condition μᵢαᵢ > 0 in this form (see inadmissible)
            out.append(Parameter(f"mu{i}", 1e4 / self.terms, "Pa", 0.0, np.inf))
            # α = 0 makes the energy singular; admissible are α in [-30, -0.01] U [0.01, 30],
            # which bounds alone cannot express: inadmissible refuses |α| < ALPHA_MIN
            out.append(Parameter(f"alpha{i}", 8.0 if i == 1 else -2.0, "1", -30.0, 30.0))
        out.append(Parameter("K", 2.5e5, "Pa", 0.0, np.inf))
        return out

    def inadmissible(self, p: Mapping[str, Any]) -> list[tuple[str, str]]:
        """Ogden's conditions, per term: αᵢ ≠ 0 and μᵢαᵢ > 0 in the classic form
        W = Σ μᵢᶜ/αᵢ (λ̄₁^αᵢ + λ̄₂^αᵢ + λ̄₃^αᵢ - 3), whose small-strain shear modulus is
        Σ μᵢᶜαᵢ/2. This law's (Abaqus) form has μᵢᶜ = 2μᵢ/αᵢ, so the condition reads μᵢ > 0 and
        the shear modulus Σ μᵢ (> 0 then too); and K > 0, the bulk modulus."""
        out = []
        for i, (mu, al) in enumerate(self._terms(p), start=1):
            al = np.real(np.asarray(al))
            mu = np.real(np.asarray(mu))
            if np.any(~(np.abs(al) >= ALPHA_MIN)):
                out.append((f"alpha{i}", f"must be non-zero (|alpha{i}| >= {ALPHA_MIN:g}: the energy "
                            f"2 mu/alpha^2 (lambda^alpha - 1) is singular at alpha = 0), got "
                            f"{np.min(np.abs(al)):g}"))
            elif np.any(~(mu > 0)):
                out.append((f"mu{i}", f"must be positive: Ogden's condition mu_i alpha_i > 0 (classic "
                            f"form) is mu_i > 0 in this law's form 2 mu_i/alpha_i^2 (...), whose "
                            f"small-strain shear modulus is sum mu_i; got mu{i} = {np.min(mu):g} Pa "
                            f"with alpha{i} = {np.max(al):g}"))
        return out + require_positive(p, ["K"], "the small-strain bulk modulus")

    def _terms(self, p: Mapping[str, Any]):
        return [(p[f"mu{i}"], p[f"alpha{i}"]) for i in range(1, self.terms + 1)]

    def energy(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Strain-energy density W (...) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        c, _ = _principal(C)
        J = np.sqrt(np.prod(c, axis=-1))
        cb = c * J[..., None] ** (-2.0 / 3.0)
        W = volumetric_energy(self.volumetric, p["K"], J)
        for mu, al in self._terms(p):
            mu = np.asarray(mu)[..., None]
            al = np.asarray(al)[..., None]
            W = W + (2 * mu / al ** 2 * (cb ** (al / 2) - 1)).sum(axis=-1)
        return W

    def stress(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Second Piola-Kirchhoff stress S (..., 3, 3) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        c, N = _principal(C)
        J = np.sqrt(np.prod(c, axis=-1))
        cb = c * J[..., None] ** (-2.0 / 3.0)
        beta = np.zeros_like(c)
        for mu, al in self._terms(p):
            mu = np.asarray(mu)[..., None]
            al = np.asarray(al)[..., None]
            pw = cb ** (al / 2)
            beta = beta + mu / al * (pw - pw.mean(axis=-1, keepdims=True))
        K = np.asarray(p["K"])
        if self.volumetric == "quadratic":
            JdU = J * K * (J - 1)
        else:
            JdU = K * np.log(J)
        # 2 ∂W/∂cₐ = (2 βₐ + J U') / cₐ
        coef = (2 * beta + JdU[..., None] * np.ones(3)) / c
        return np.einsum("...ia,...a,...ja->...ij", N, coef, N)
