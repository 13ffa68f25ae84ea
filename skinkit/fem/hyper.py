"""Helpers for hyperelastic law authors: invariants and the volumetric part of uncoupled laws.

All functions are batched and complex-step safe (they accept complex ``C`` and parameters),
so a law built from them can declare ``complex_safe = True`` and get an exact tangent.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from skinkit.fem.tensors import I3, inv3, outer, sym_product, trace

VOLUMETRIC_KINDS = ("quadratic", "log")


def check_volumetric(kind: str) -> str:
    """``kind`` if it names a volumetric energy in :data:`VOLUMETRIC_KINDS` (a law's
    ``volumetric`` option), else a ValueError naming the choices."""
    if kind not in VOLUMETRIC_KINDS:
        raise ValueError(f"volumetric must be one of {VOLUMETRIC_KINDS}, got {kind!r}")
    return kind


def b2(v: Any) -> np.ndarray:
    """A batch of scalars shaped to scale ``(..., 3, 3)`` tensors."""
    return np.asarray(v)[..., None, None]


def b4(v: Any) -> np.ndarray:
    """A batch of scalars shaped to scale ``(..., 3, 3, 3, 3)`` tensors."""
    return np.asarray(v)[..., None, None, None, None]


def kinematics(C: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(Cinv, J, I1)`` of ``C`` ``(..., 3, 3)``: inverse, ``J = sqrt(det C)``, first invariant."""
    Cinv, d = inv3(C)
    return Cinv, np.sqrt(d), trace(C)


def volumetric_energy(kind: str, K: Any, J: np.ndarray) -> np.ndarray:
    """``U(J)``: ``"quadratic"`` = K/2 (J-1)² (Abaqus, sfepy), ``"log"`` = K/2 (ln J)² (FEBio)."""
    if kind == "quadratic":
        return 0.5 * K * (J - 1) ** 2
    if kind == "log":
        return 0.5 * K * np.log(J) ** 2
    raise ValueError(f"volumetric kind must be one of {VOLUMETRIC_KINDS}, got {kind!r}")


def _dU(kind: str, K: Any, J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(U', U'')`` with respect to J."""
    if kind == "quadratic":
        return K * (J - 1), K + 0 * J
    lnJ = np.log(J)
    return K * lnJ / J, K * (1 - lnJ) / J ** 2


def volumetric_stress(kind: str, K: Any, J: np.ndarray, Cinv: np.ndarray) -> np.ndarray:
    """PK2 stress of ``U(J)``: ``J U'(J) C⁻¹``."""
    d1, _ = _dU(kind, K, J)
    return (J * d1)[..., None, None] * Cinv


def volumetric_tangent(kind: str, K: Any, J: np.ndarray, Cinv: np.ndarray) -> np.ndarray:
    """Tangent of ``U(J)``: ``J p* C⁻¹⊗C⁻¹ - 2 J p C⁻¹⊙C⁻¹``, ``p = U'``, ``p* = p + J U''``."""
    d1, d2 = _dU(kind, K, J)
    pstar = d1 + J * d2
    return ((J * pstar)[..., None, None, None, None] * outer(Cinv, Cinv)
            - (2 * J * d1)[..., None, None, None, None] * sym_product(Cinv))


def iso_I1(C: np.ndarray, Cinv: np.ndarray, J: np.ndarray, I1: np.ndarray):
    """``(Ī1, ∂Ī1/∂C)`` with ``Ī1 = J^(-2/3) I1``."""
    Jm23 = J ** (-2.0 / 3.0)
    return Jm23 * I1, Jm23[..., None, None] * (I3 - (I1 / 3.0)[..., None, None] * Cinv)


def iso_I2(C: np.ndarray, Cinv: np.ndarray, J: np.ndarray, I1: np.ndarray):
    """``(Ī2, ∂Ī2/∂C)`` with ``Ī2 = J^(-4/3) (I1² - tr C²)/2``."""
    I2 = 0.5 * (I1 ** 2 - trace(C @ C))
    Jm43 = J ** (-4.0 / 3.0)
    d = Jm43[..., None, None] * (I1[..., None, None] * I3 - C) \
        - (2.0 / 3.0 * Jm43 * I2)[..., None, None] * Cinv
    return Jm43 * I2, d


def iso_I4(C: np.ndarray, Cinv: np.ndarray, J: np.ndarray, a: np.ndarray):
    """``(Ī4, ∂Ī4/∂C)`` for a unit reference fibre direction ``a`` ``(3,)`` (or batched)."""
    A = a[..., :, None] * a[..., None, :]
    I4 = np.einsum("...I,...IJ,...J->...", a, C, a) if a.ndim > 1 else (C * A).sum(axis=(-2, -1))
    Jm23 = J ** (-2.0 / 3.0)
    return Jm23 * I4, Jm23[..., None, None] * (A - (I4 / 3.0)[..., None, None] * Cinv)


def iso_hessian(Cinv: np.ndarray, J: np.ndarray, A: np.ndarray, IA: np.ndarray,
                outer_extra: Any = None, sym_extra: Any = None) -> np.ndarray:
    """``∂²Ī/∂C∂C`` of an isochoric invariant ``Ī = J^(-2/3) A:C`` (A = I for Ī1, a⊗a for Ī4).

    ``= J^(-2/3) [-(A⊗C⁻¹ + C⁻¹⊗A)/3 + IA/9 C⁻¹⊗C⁻¹ + IA/3 C⁻¹⊙C⁻¹]`` with ``IA = A:C``.
    It is linear in ``(A, IA)``: a weighted sum of such Hessians is the Hessian of the weighted
    sums. ``outer_extra`` and ``sym_extra`` (batched scalars) are added to the coefficients of
    ``C⁻¹⊗C⁻¹`` and ``C⁻¹⊙C⁻¹`` (e.g. :func:`volumetric_coefficients`), so that a law's whole
    tangent but its rank-one terms takes one set of fourth-order products.
    """
    j = J ** (-2.0 / 3.0)
    A = np.broadcast_to(A, Cinv.shape)
    X = outer(A, Cinv)
    X = X + np.swapaxes(np.swapaxes(X, -4, -2), -3, -1)
    a = j * IA / 9.0 + (0 if outer_extra is None else outer_extra)
    b = j * IA / 3.0 + (0 if sym_extra is None else sym_extra)
    H = b4(b) * sym_product(Cinv)
    H += b4(a) * outer(Cinv, Cinv)
    H -= b4(j / 3.0) * X
    return H


def volumetric_coefficients(kind: str, K: Any, J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(J p*, −2 J p)``: the coefficients of ``C⁻¹⊗C⁻¹`` and ``C⁻¹⊙C⁻¹`` in
    :func:`volumetric_tangent` (``p = U'``, ``p* = p + J U''``)."""
    d1, d2 = _dU(kind, K, J)
    return J * (d1 + J * d2), -2 * J * d1
