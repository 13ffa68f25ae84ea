"""Uncoupled Mooney-Rivlin law: W = c1 (Ī1 - 3) + c2 (Ī2 - 3) + U(J)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from skinkit.plugin.laws import (
    check_volumetric,
    iso_I1,
    iso_I2,
    kinematics,
    require_positive,
    volumetric_energy,
    volumetric_stress,
)
from skinkit.schemas import Parameter


class MooneyRivlin:
    """Parameters ``c1``, ``c2``, ``K`` [Pa] (small-strain shear modulus 2 (c1 + c2)).

    Option ``volumetric``: ``"quadratic"`` (K/2 (J-1)², default) or ``"log"``. The tangent is
    derived by the engine (complex step of the analytic stress).
    """

    name = "mooney-rivlin"
    complex_safe = True

    def __init__(self, volumetric: str = "quadratic") -> None:
        check_volumetric(volumetric)
        self.volumetric = volumetric

    @staticmethod
    def verification_cases() -> list[dict[str, Any]]:
        """The cases ``skinkit verify`` runs for this law (keys: :mod:`skinkit.fem.verify`)."""
        return [{"name": "mooney-rivlin"}]

    def parameters(self) -> list[Parameter]:
        """Declared parameters: ``c1``, ``c2``, ``K`` [Pa]."""
        return [Parameter("c1", 4e3, "Pa", 0.0, np.inf),
                Parameter("c2", 1e3, "Pa", 0.0, np.inf),
                Parameter("K", 2.5e5, "Pa", 0.0, np.inf)]

    def inadmissible(self, p: Mapping[str, Any]) -> list[tuple[str, str]]:
        """c1 + c2 > 0 (the small-strain shear modulus is 2 (c1 + c2)) and K > 0."""
        out = []
        mu = np.real(np.asarray(p["c1"]) + np.asarray(p["c2"]))
        if np.any(~(mu > 0)):
            out.append(("", f"c1 + c2 must be positive (half the small-strain shear modulus), got "
                            f"{np.min(mu):g} Pa"))
        return out + require_positive(p, ["K"], "the small-strain bulk modulus")

    def energy(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Strain-energy density W (...) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        Cinv, J, I1 = kinematics(C)
        I1b, _ = iso_I1(C, Cinv, J, I1)
        I2b, _ = iso_I2(C, Cinv, J, I1)
        return (p["c1"] * (I1b - 3) + p["c2"] * (I2b - 3)
                + volumetric_energy(self.volumetric, p["K"], J))

    def stress(self, C: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        """Second Piola-Kirchhoff stress S (..., 3, 3) [Pa] of ``C`` (..., 3, 3) at parameters ``p``."""
        Cinv, J, I1 = kinematics(C)
        _, d1 = iso_I1(C, Cinv, J, I1)
        _, d2 = iso_I2(C, Cinv, J, I1)
        c1 = np.asarray(p["c1"])[..., None, None]
        c2 = np.asarray(p["c2"])[..., None, None]
        return 2 * c1 * d1 + 2 * c2 * d2 + volumetric_stress(self.volumetric, p["K"], J, Cinv)
