"""Gasser-Ogden-Holzapfel law with fibre dispersion, FEBio's uncoupled conventions.

W = c/2 (Ī1 - 3) + Σ_α k1/(2 k2) [exp(k2 Ē_α²) - 1] + k/2 (ln J)²,
Ē_α = κ (Ī1 - 3) + (1 - 3κ) (Ī4α - 1),

with fibre family α active only in tension. Two switches are offered: ``"febio"`` (the
default) activates a family where Ī4α > 1, as FEBio does — with κ > 0 the energy then jumps
where a family switches on, which can stall Newton's method; ``"macaulay"`` uses ⟨Ē_α⟩,
as Abaqus and the thesis's Eq 7.1 do, continuous with a continuous stress. The fibres lie in the
e1-e2 plane of the local frame at ±γ from e1 (one family: +γ only), exactly as FEBio's
``gamma``; the local frame is the global one turned by the option ``frame_angle`` [rad]
about z. The thesis's Abaqus form (Eq 7.1) has C10 = c/2.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit.plugin.laws import (
    I3,
    b2,
    b4,
    check_volumetric,
    iso_hessian,
    iso_I1,
    iso_I4,
    kinematics,
    outer,
    require_positive,
    volumetric_coefficients,
    volumetric_energy,
    volumetric_stress,
)
from skinkit.schemas import Parameter

#: fibres stiff against the matrix, fibre dispersion kappa = 0.1: the verification parameters [SI]
_VERIFY_P = {"c": 2e4, "k1": 5e4, "k2": 5.0, "kappa": 0.1, "k": 5e5}


class GOH:
    """Parameters ``c``, ``k1``, ``k`` [Pa], ``k2`` [1], ``kappa`` [1] in [0, 1/3], ``gamma`` [rad].

    Options: ``families`` (1 or 2), ``frame_angle`` [rad], ``volumetric`` (``"log"``, FEBio's
    default, or ``"quadratic"``), ``switch`` (``"febio"`` or ``"macaulay"``, see the module).
    """

    name = "goh"
    complex_safe = True

    def __init__(self, families: int = 2, frame_angle: float = 0.0, volumetric: str = "log",
                 switch: str = "febio") -> None:
        if switch not in ("febio", "macaulay"):
            raise ValueError(f"switch must be 'febio' or 'macaulay', got {switch!r}")
        self.switch = switch
        if families not in (1, 2):
            raise ValueError(f"families must be 1 or 2, got {families!r}")
        check_volumetric(volumetric)
        self.families = int(families)
        if isinstance(frame_angle, bool) or not isinstance(frame_angle, (int, float)) \
                or not np.isfinite(frame_angle):
            raise ValueError(f"frame_angle must be a finite angle in rad, got {frame_angle!r}")
        self.frame_angle = float(frame_angle)
        self.volumetric = volumetric

    @staticmethod
    def verification_cases() -> list[dict[str, Any]]:
        """The cases ``skinkit verify`` runs for this law (keys: :mod:`skinkit.fem.verify`):
        stretched along, at 30 degrees to and across the fibres."""
        return [{"name": f"goh-{key}", "parameters": dict(_VERIFY_P, gamma=gamma), "checks": ("homogeneous",)}
                for key, gamma in (("along", 0.0), ("30deg", np.pi / 6), ("across", np.pi / 2))] + \
            [{"name": "goh", "parameters": dict(_VERIFY_P, gamma=0.3), "checks": ("sensitivities",)}]

    def parameters(self) -> list[Parameter]:
        """Declared parameters: ``c``, ``k1``, ``k`` [Pa], ``k2``, ``kappa`` [1], ``gamma`` [rad]."""
        return [Parameter("c", 2e4, "Pa", 0.0, np.inf),
                Parameter("k1", 1e4, "Pa", 0.0, np.inf),
                Parameter("k2", 10.0, "1", 1e-6, 1e3),
                Parameter("kappa", 0.1, "1", 0.0, 1.0 / 3.0),
                Parameter("gamma", 0.0, "rad", -np.pi / 2, np.pi / 2),
                Parameter("k", 5e5, "Pa", 0.0, np.inf)]

    def inadmissible(self, p: Mapping[str, Any]) -> list[tuple[str, str]]:
        """c > 0 and k > 0: in the reference state every fibre family is inactive (FEBio's switch:
        Ī4 = 1 is not > 1; Macaulay: Ē = 0), so the ground matrix alone carries the small-strain
        shear (modulus c) and the volumetric term the bulk response (modulus k)."""
        return (require_positive(p, ["c"], "the small-strain shear modulus: fibres carry no load "
                                 "in the reference state")
                + require_positive(p, ["k"], "the small-strain bulk modulus"))

    def fibres(self, gamma: Any) -> list[np.ndarray]:
        """Reference unit fibre directions, each ``(..., 3)`` (batched over ``gamma``)."""
        th = self.frame_angle
        e1 = np.array([np.cos(th), np.sin(th), 0.0])
        e2 = np.array([-np.sin(th), np.cos(th), 0.0])
        g = np.asarray(gamma)[..., None]
        out = [np.cos(g) * e1 + np.sin(g) * e2]
        if self.families == 2:
            out.append(np.cos(g) * e1 - np.sin(g) * e2)
        return out

    def _fibre_terms(self, C, Cinv, J, I1b, dI1b, p):
        k1, k2, kap = (np.asarray(p[n]) for n in ("k1", "k2", "kappa"))
        for a in self.fibres(p["gamma"]):
            I4b, dI4b = iso_I4(C, Cinv, J, a)
            E = kap * (I1b - 3) + (1 - 3 * kap) * (I4b - 1)
            active = (np.real(I4b) > 1.0) if self.switch == "febio" else (np.real(E) > 0.0)
            E = np.where(active, E, 0.0)
            yield k1, k2, kap, E, dI4b, active

    def energy(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Strain-energy density W (...) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        Cinv, J, I1 = kinematics(C)
        I1b, dI1b = iso_I1(C, Cinv, J, I1)
        W = 0.5 * p["c"] * (I1b - 3) + volumetric_energy(self.volumetric, p["k"], J)
        for k1, k2, _, E, _, active in self._fibre_terms(C, Cinv, J, I1b, dI1b, p):
            W = W + np.where(active, k1 / (2 * k2) * (np.exp(k2 * E ** 2) - 1), 0.0)
        return W

    def tangent(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Analytic tangent: 4 Σ [W'' ∂Ē⊗∂Ē + W' ∂²Ē] over active families + ground + bulk."""
        return self.response(C, p, True)[1]

    def response(self, C: np.ndarray, p: Mapping[str, Any], with_tangent: bool = True):
        """Stress and tangent sharing the kinematics (the engine's hot path).

        The isochoric Hessian ∂²Ī/∂C∂C of Ī = J^(−2/3) A:C is linear in (A, A:C)
        (:func:`~skinkit.fem.hyper.iso_hessian`), so the ground matrix's and every family's
        second-derivative terms, 2c ∂²Ī1 + Σ 4 W′ (κ ∂²Ī1 + (1 − 3κ) ∂²Ī4), are one Hessian of
        the weighted sum of their A's, with the volumetric tangent's coefficients folded in: one
        set of fourth-order products instead of one per invariant."""
        S = self.stress(C, p)
        if not with_tangent:
            return S, None
        Cinv, J, I1 = kinematics(C)
        I1b, dI1b = iso_I1(C, Cinv, J, I1)
        k1, k2, kap = (np.asarray(p[n]) for n in ("k1", "k2", "kappa"))
        w1 = 2 * np.asarray(p["c"]) + 0 * I1         # weight of ∂²Ī1 (batched)
        A_sum, IA_sum = 0 * Cinv, 0 * I1            # Σ weight · A and Σ weight · A:C of the fibres
        rank_one = []                               # 4 W″ G⊗G of each family
        for a in self.fibres(p["gamma"]):
            I4b, dI4b = iso_I4(C, Cinv, J, a)
            E = kap * (I1b - 3) + (1 - 3 * kap) * (I4b - 1)
            active = (np.real(I4b) > 1.0) if self.switch == "febio" else (np.real(E) > 0.0)
            ex = np.exp(k2 * E ** 2)
            d1 = np.where(active, k1 * E * ex, 0.0)                       # ∂W/∂Ē
            d2 = np.where(active, k1 * ex * (1 + 2 * k2 * E ** 2), 0.0)   # ∂²W/∂Ē²
            A = a[..., :, None] * a[..., None, :]
            I4 = (C * A).sum(axis=(-2, -1))
            G = b2(kap) * dI1b + b2(1 - 3 * kap) * dI4b
            w1 = w1 + 4 * d1 * kap
            w4 = 4 * d1 * (1 - 3 * kap)
            A_sum = A_sum + b2(w4) * A
            IA_sum = IA_sum + w4 * I4
            rank_one.append(b4(4 * d2) * outer(G, G))
        vo, vs = volumetric_coefficients(self.volumetric, p["k"], J)
        CC = iso_hessian(Cinv, J, b2(w1) * I3 + A_sum, w1 * I1 + IA_sum, vo, vs)
        for term in rank_one:
            CC += term
        return S, CC

    def stress(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Second Piola-Kirchhoff stress S (..., 3, 3) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        Cinv, J, I1 = kinematics(C)
        I1b, dI1b = iso_I1(C, Cinv, J, I1)
        S = np.asarray(p["c"])[..., None, None] * dI1b \
            + volumetric_stress(self.volumetric, p["k"], J, Cinv)
        for k1, k2, kap, E, dI4b, _ in self._fibre_terms(C, Cinv, J, I1b, dI1b, p):
            w = 2 * k1 * E * np.exp(k2 * E ** 2)  # 2 ∂W/∂Ē, zero where inactive (E = 0)
            S = S + w[..., None, None] * (kap[..., None, None] * dI1b
                                          + (1 - 3 * kap)[..., None, None] * dI4b)
        return S
