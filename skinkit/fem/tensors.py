"""Batched small-tensor helpers. Arrays carry leading batch axes; tensors are the last axes."""

from __future__ import annotations

import numpy as np

#: the six independent components of a symmetric 3x3 tensor
VOIGT: tuple[tuple[int, int], ...] = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))

I3 = np.eye(3)


def sym_direction(K: int, L: int) -> np.ndarray:
    """``(3, 3)`` symmetric unit direction ``(e_K e_L + e_L e_K)/2``."""
    E = np.zeros((3, 3))
    E[K, L] += 0.5
    E[L, K] += 0.5
    return E


def det3(A: np.ndarray) -> np.ndarray:
    """Determinant of ``(..., 3, 3)`` arrays; works for complex entries (complex-step safe)."""
    return (A[..., 0, 0] * (A[..., 1, 1] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 1])
            - A[..., 0, 1] * (A[..., 1, 0] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 0])
            + A[..., 0, 2] * (A[..., 1, 0] * A[..., 2, 1] - A[..., 1, 1] * A[..., 2, 0]))


def inv3(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse and determinant of ``(..., 3, 3)`` arrays by cofactors (complex-step safe)."""
    cof = np.empty_like(A)
    cof[..., 0, 0] = A[..., 1, 1] * A[..., 2, 2] - A[..., 1, 2] * A[..., 2, 1]
    cof[..., 0, 1] = A[..., 0, 2] * A[..., 2, 1] - A[..., 0, 1] * A[..., 2, 2]
    cof[..., 0, 2] = A[..., 0, 1] * A[..., 1, 2] - A[..., 0, 2] * A[..., 1, 1]
    cof[..., 1, 0] = A[..., 1, 2] * A[..., 2, 0] - A[..., 1, 0] * A[..., 2, 2]
    cof[..., 1, 1] = A[..., 0, 0] * A[..., 2, 2] - A[..., 0, 2] * A[..., 2, 0]
    cof[..., 1, 2] = A[..., 0, 2] * A[..., 1, 0] - A[..., 0, 0] * A[..., 1, 2]
    cof[..., 2, 0] = A[..., 1, 0] * A[..., 2, 1] - A[..., 1, 1] * A[..., 2, 0]
    cof[..., 2, 1] = A[..., 0, 1] * A[..., 2, 0] - A[..., 0, 0] * A[..., 2, 1]
    cof[..., 2, 2] = A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0]
    d = A[..., 0, 0] * cof[..., 0, 0] + A[..., 0, 1] * cof[..., 1, 0] + A[..., 0, 2] * cof[..., 2, 0]
    return cof / d[..., None, None], d


def trace(A: np.ndarray) -> np.ndarray:
    """Trace of ``(..., 3, 3)``."""
    return A[..., 0, 0] + A[..., 1, 1] + A[..., 2, 2]


def outer(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``(A ⊗ B)_IJKL = A_IJ B_KL`` for ``(..., 3, 3)`` arrays."""
    return A[..., :, :, None, None] * B[..., None, None, :, :]


def sym_product(A: np.ndarray) -> np.ndarray:
    """``(A ⊙ A)_IJKL = (A_IK A_JL + A_IL A_JK)/2`` for symmetric ``A`` ``(..., 3, 3)``."""
    return 0.5 * (A[..., :, None, :, None] * A[..., None, :, None, :]
                  + A[..., :, None, None, :] * A[..., None, :, :, None])


def push_with(F0: np.ndarray, S: np.ndarray, CC: np.ndarray | None = None):
    """``F0 S F0ᵀ`` and ``F0_Ia F0_Jb CC_abcd F0_Kc F0_Ld`` (pre-stress transformation).

    With an initial deformation ``F0`` the energy per unit reference volume is
    ``W(F0ᵀ C F0)``; its stress and tangent are these transforms of the law's ones.
    """
    S2 = np.einsum("...Ia,...ab,...Jb->...IJ", F0, S, F0)
    if CC is None:
        return S2, None
    CC2 = np.einsum("...Ia,...Jb,...abcd,...Kc,...Ld->...IJKL", F0, F0, CC, F0, F0, optimize=True)
    return S2, CC2
