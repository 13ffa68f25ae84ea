"""Neo-Hookean laws: compressible, nearly incompressible (uncoupled), and by E and ν.

* ``neo-hookean``: W = μ/2 (I1 - 3) - μ ln J + λ/2 (ln J)² (FEBio's "neo-Hookean");
* ``neo-hookean-ni``: W = μ/2 (Ī1 - 3) + U(J), U = K/2 (J - 1)² by default — the thesis's
  Eq 7.8 with C10 = μ/2 and D = 2/K, and sfepy's ``dw_tl_he_neohook`` + ``dw_tl_bulk_penalty``;
* ``neo-hookean-enu``: the same law given by Young's modulus E and Poisson's ratio ν
  (thesis Eqs 7.9-7.10: C10 = E / (4 (1 + ν)), D = 6 (1 - 2ν) / E).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit.plugin.laws import (
    I3,
    check_volumetric,
    iso_I1,
    kinematics,
    outer,
    require_positive,
    sym_product,
    volumetric_energy,
    volumetric_stress,
)
from skinkit.schemas import Parameter


def _b(x: Any) -> Any:
    """A parameter ready to broadcast over the two tensor axes."""
    x = np.asarray(x)
    return x[..., None, None]


class NeoHookean:
    """Compressible neo-Hookean law (FEBio form), parameters ``mu`` and ``lam`` [Pa]."""

    name = "neo-hookean"
    complex_safe = True

    @staticmethod
    def verification_cases() -> list[dict[str, Any]]:
        """The cases ``skinkit verify`` runs for this law (keys: :mod:`skinkit.fem.verify`)."""
        return [{"name": "neo-hookean"}]

    def parameters(self) -> list[Parameter]:
        """Declared parameters: ``mu``, ``lam`` [Pa] (Lamé)."""
        return [Parameter("mu", 1e4, "Pa", 0.0, np.inf),
                Parameter("lam", 4e4, "Pa", 0.0, np.inf)]

    def inadmissible(self, p: Mapping[str, Any]) -> list[tuple[str, str]]:
        """μ > 0: the small-strain shear modulus (the bulk modulus λ + 2μ/3 is then positive
        too, λ being bounded below by 0)."""
        return require_positive(p, ["mu"], "the small-strain shear modulus")

    def energy(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Strain-energy density W (...) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        _, J, I1 = kinematics(C)
        lnJ = np.log(J)
        return 0.5 * p["mu"] * (I1 - 3) - p["mu"] * lnJ + 0.5 * p["lam"] * lnJ ** 2

    def stress(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Second Piola-Kirchhoff stress S (..., 3, 3) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        Cinv, J, _ = kinematics(C)
        lnJ = np.log(J)
        return _b(p["mu"]) * (I3 - Cinv) + _b(p["lam"] * lnJ) * Cinv

    def tangent(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Material tangent 2 ∂S/∂C (..., 3, 3, 3, 3) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        Cinv, J, _ = kinematics(C)
        lnJ = np.log(J)
        a = np.asarray(p["lam"])[..., None, None, None, None]
        b = np.asarray(2 * (p["mu"] - p["lam"] * lnJ))[..., None, None, None, None]
        return a * outer(Cinv, Cinv) + b * sym_product(Cinv)


class NeoHookeanNI:
    """Nearly incompressible (uncoupled) neo-Hookean, parameters ``mu`` and ``K`` [Pa].

    Option ``volumetric``: ``"quadratic"`` (K/2 (J-1)², default) or ``"log"`` (K/2 (ln J)²).
    """

    name = "neo-hookean-ni"
    complex_safe = True

    def __init__(self, volumetric: str = "quadratic") -> None:
        check_volumetric(volumetric)
        self.volumetric = volumetric

    @staticmethod
    def verification_cases() -> list[dict[str, Any]]:
        """The cases ``skinkit verify`` runs for this law (keys: :mod:`skinkit.fem.verify`), the
        pre-stretch derivatives included."""
        return [{"name": "neo-hookean-ni"},
                {"name": "prestretch", "checks": ("sensitivities",), "prestress": (1.08, 1.03, 0.4)}]

    def parameters(self) -> list[Parameter]:
        """Declared parameters: ``mu`` (shear) and ``K`` (bulk modulus) [Pa]."""
        return [Parameter("mu", 1e4, "Pa", 0.0, np.inf),
                Parameter("K", 2.5e5, "Pa", 0.0, np.inf)]

    def _mu_K(self, p: Mapping[str, Any]) -> tuple[Any, Any]:
        return p["mu"], p["K"]

    def inadmissible(self, p: Mapping[str, Any]) -> list[tuple[str, str]]:
        """μ > 0 and K > 0: the small-strain shear and bulk moduli."""
        return (require_positive(p, ["mu"], "the small-strain shear modulus")
                + require_positive(p, ["K"], "the small-strain bulk modulus"))

    def energy(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Strain-energy density W (...) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        mu, K = self._mu_K(p)
        Cinv, J, I1 = kinematics(C)
        I1b, _ = iso_I1(C, Cinv, J, I1)
        return 0.5 * mu * (I1b - 3) + volumetric_energy(self.volumetric, K, J)

    def stress(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Second Piola-Kirchhoff stress S (..., 3, 3) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        mu, K = self._mu_K(p)
        Cinv, J, I1 = kinematics(C)
        _, dI1b = iso_I1(C, Cinv, J, I1)
        return _b(mu) * dI1b + volumetric_stress(self.volumetric, K, J, Cinv)

    def response(self, C: np.ndarray, p: Mapping[str, Any], with_tangent: bool = True):
        """Stress and tangent sharing the kinematics (the engine's hot path)."""
        mu, K = self._mu_K(p)
        Cinv, J, I1 = kinematics(C)
        _, dI1b = iso_I1(C, Cinv, J, I1)
        S = _b(mu) * dI1b + volumetric_stress(self.volumetric, K, J, Cinv)
        if not with_tangent:
            return S, None
        # CC = a C⁻¹⊗C⁻¹ + b C⁻¹⊙C⁻¹ - c (I⊗C⁻¹ + C⁻¹⊗I): isochoric plus volumetric parts
        # gathered so that each fourth-order product is formed once
        c = 2.0 / 3.0 * np.asarray(mu) * J ** (-2.0 / 3.0)
        if self.volumetric == "quadratic":
            dU, pstar = K * (J - 1), K * (2 * J - 1)
        else:
            lnJ = np.log(J)
            dU = K * lnJ / J
            pstar = dU + J * K * (1 - lnJ) / J ** 2
        a = c * I1 / 3.0 + J * pstar
        b = c * I1 - 2 * J * dU
        X = b[..., None, None, None, None] * sym_product(Cinv)
        X += a[..., None, None, None, None] * outer(Cinv, Cinv)
        IC = outer(np.broadcast_to(I3, Cinv.shape), Cinv)
        IC += np.swapaxes(np.swapaxes(IC, -4, -2), -3, -1)
        X -= c[..., None, None, None, None] * IC
        return S, X

    def tangent(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Material tangent 2 ∂S/∂C (..., 3, 3, 3, 3) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        return self.response(C, p, True)[1]


class NeoHookeanEnu(NeoHookeanNI):
    """The uncoupled neo-Hookean given by ``E`` [Pa] and ``nu`` [1] (thesis Eqs 7.8-7.10)."""

    name = "neo-hookean-enu"

    @staticmethod
    def verification_cases() -> list[dict[str, Any]]:
        """The cases ``skinkit verify`` runs for this law (keys: :mod:`skinkit.fem.verify`)."""
        return [{"name": "neo-hookean-enu", "checks": ("sensitivities",)}]

    def parameters(self) -> list[Parameter]:
        """Declared parameters: ``E`` [Pa] and ``nu`` [1] (below 0.5)."""
        # ν < 0.5 strictly: K = E / (3 (1 - 2ν)) is infinite at 0.5
        return [Parameter("E", 3e4, "Pa", 0.0, np.inf),
                Parameter("nu", 0.48, "1", -0.99, 0.4999)]

    def inadmissible(self, p: Mapping[str, Any]) -> list[tuple[str, str]]:
        """E > 0 (with ν in its bounds (-1, 1/2), shear and bulk moduli are then positive)."""
        return require_positive(p, ["E"], "Young's modulus; the shear modulus is E / (2 (1 + nu))")

    def _mu_K(self, p: Mapping[str, Any]) -> tuple[Any, Any]:
        E, nu = p["E"], p["nu"]
        return E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu))
