"""Batched total-Lagrangian assembly of the hyperelastic residual and consistent tangent.

Everything is evaluated at once over elements x quadrature points with array products (no
per-basis-pair Python callback, unlike scikit-fem's ``BilinearForm``), and the tangent is
scattered into a sparse matrix whose pattern is computed once and reused every iteration.
Displacements are stored node-major: dof ``3 * node + component``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from skfem import Basis, ElementHex2

from skinkit.fem.errors import InvertedElementError
from skinkit.fem.mesh import FEMesh
from skinkit.fem.tensors import I3

#: default quadrature degree: 3 Gauss points per direction integrate the 27-node element's
#: stiffness exactly in the linear limit (degree 4 per direction)
DEFAULT_INTORDER = 4


@dataclass
class Geometry:
    """Shape-function gradients and weights of a mesh at its quadrature points.

    Attributes:
        dN: ``(n_el, n_q, 27, 3)`` gradients dNₐ/dX [1/m].
        w: ``(n_el, n_q)`` quadrature weight x det J [m³].
        N: ``(n_q, 27)`` shape function values at the reference quadrature points.
        edofs: ``(n_el, 81)`` vector dofs of each element, ordered (node, component).
        intorder: quadrature degree used.
    """

    dN: np.ndarray
    w: np.ndarray
    N: np.ndarray
    edofs: np.ndarray
    intorder: int


def geometry(mesh: FEMesh, intorder: int = DEFAULT_INTORDER) -> Geometry:
    """Evaluate the isoparametric geometry of ``mesh`` with scikit-fem (``intorder`` explicit)."""
    basis = Basis(mesh.skfem_mesh(), ElementHex2(), intorder=intorder)
    nb = basis.Nbfun
    dN = np.empty((mesh.n_elements, basis.dx.shape[1], nb, 3))
    N = np.empty((basis.dx.shape[1], nb))
    for a in range(nb):
        f = basis.basis[a][0]
        dN[:, :, a, :] = np.moveaxis(np.asarray(f.grad), 0, -1)
        N[:, a] = np.asarray(f.value)[0]
    w = np.asarray(basis.dx)
    if np.any(w <= 0):
        e = int(np.argmin(w.min(axis=1)))
        raise InvertedElementError(e, float(w[e].min()))
    edofs = (3 * np.asarray(basis.element_dofs).T[:, :, None] + np.arange(3)).reshape(mesh.n_elements, -1)
    return Geometry(dN, w, N, edofs, intorder)


def deformation_gradient(geom: Geometry, u: np.ndarray, elements: np.ndarray | None = None) -> np.ndarray:
    """``(n_el, n_q, 3, 3)`` deformation gradients ``F = I + ∂u/∂X`` of displacement ``u`` ``(n_dof,)``."""
    ed = geom.edofs if elements is None else geom.edofs[elements]
    dN = geom.dN if elements is None else geom.dN[elements]
    ue = u[ed].reshape(ed.shape[0], -1, 3)
    return I3 + np.einsum("eai,eqaJ->eqiJ", ue, dN, optimize=True)


def element_residual(dN: np.ndarray, w: np.ndarray, F: np.ndarray, S: np.ndarray) -> np.ndarray:
    """``(n_el, 81)`` internal forces ``∫ F S : ∇δu`` [N]."""
    P = F @ S
    return np.einsum("eqiJ,eqaJ,eq->eai", P, dN, w, optimize=True).reshape(dN.shape[0], -1)


def element_tangent(dN: np.ndarray, w: np.ndarray, F: np.ndarray, S: np.ndarray,
                    CC: np.ndarray) -> np.ndarray:
    """``(n_el, 81, 81)`` consistent tangents [N/m].

    ``K_(ai)(bk) = Σ_q w dNₐ_J A_iJkL dN_b_L`` with ``A = F·CC·Fᵀ + δ S`` (material plus
    geometric stiffness), evaluated as two batched matrix products.
    """
    ne, nq, nb, _ = dN.shape
    A = _material_part(CC, F)
    A += np.einsum("ik,eqJL->eqiJkL", I3, S)
    # T[e, q, a, (i k L)] = Σ_J dN[e,q,a,J] A[e,q,i,J,k,L]
    A2 = A.transpose(0, 1, 3, 2, 4, 5).reshape(ne, nq, 3, 27)
    T = np.matmul(dN, A2)                                   # (e, q, a, 27=(i,k,L))
    T = T.reshape(ne, nq, nb, 3, 3, 3).transpose(0, 2, 3, 4, 1, 5).reshape(ne, nb * 9, nq * 3)
    B = (dN * w[:, :, None, None]).transpose(0, 1, 3, 2).reshape(ne, nq * 3, nb)
    K = np.matmul(T, B)                                     # (e, (a,i,k), b)
    return K.reshape(ne, nb, 3, 3, nb).transpose(0, 1, 2, 4, 3).reshape(ne, nb * 3, nb * 3)


def _material_part(CC: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``F_iI CC_IJKL F_kK`` as ``(..., i, J, k, L)``."""
    sh = CC.shape[:-4]
    # contract K with F_kK: CC(..., IJ L, K) @ F^T(K, k)
    X = np.matmul(CC.transpose(*range(len(sh)), -4, -3, -1, -2).reshape(*sh, 27, 3),
                  np.swapaxes(F, -1, -2))                   # (..., (I,J,L), k)
    X = X.reshape(*sh, 3, 9 * 1 * 3)                         # (..., I, (J,L,k))
    Y = np.matmul(F, X)                                      # (..., i, (J,L,k))
    return Y.reshape(*sh, 3, 3, 3, 3).transpose(*range(len(sh)), -4, -3, -1, -2)


class SparsePattern:
    """The sparsity pattern of a reduced system, built once, reused for every assembly.

    ``dof_map`` ``(n_dof,)`` sends each full dof to its reduced unknown, or -1 when it is
    prescribed (several dofs may share an unknown: a rigid region tied to a reference point).
    """

    def __init__(self, edofs: np.ndarray, dof_map: np.ndarray, n_unknowns: int) -> None:
        self.n = int(n_unknowns)
        self.dof_map = np.asarray(dof_map)
        r = self.dof_map[edofs]                              # (e, 81)
        rows = np.repeat(r, r.shape[1], axis=1).ravel()
        cols = np.tile(r, (1, r.shape[1])).ravel()
        valid = (rows >= 0) & (cols >= 0)
        self.take = np.flatnonzero(valid)
        keys = rows[valid].astype(np.int64) * self.n + cols[valid]
        uniq, self.inv = np.unique(keys, return_inverse=True)
        self.indices = (uniq % self.n).astype(np.int32)
        self.indptr = np.searchsorted(uniq // self.n, np.arange(self.n + 1)).astype(np.int32)
        self.nnz = uniq.size
        rvec = r.ravel()
        self.rtake = np.flatnonzero(rvec >= 0)
        self.rdest = rvec[self.rtake]

    def matrix(self, Ke: np.ndarray) -> sp.csr_matrix:
        """Scatter element matrices ``(n_el, 81, 81)`` into the reduced CSR matrix."""
        data = np.bincount(self.inv, weights=Ke.ravel()[self.take], minlength=self.nnz)
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))

    def vector(self, re: np.ndarray) -> np.ndarray:
        """Scatter element vectors ``(n_el, 81)`` into the reduced vector ``(n_unknowns,)``."""
        return np.bincount(self.rdest, weights=re.ravel()[self.rtake], minlength=self.n)


def full_vector(edofs: np.ndarray, re: np.ndarray, n_dof: int) -> np.ndarray:
    """Scatter element vectors into a full ``(n_dof,)`` vector (e.g. nodal reaction forces)."""
    return np.bincount(edofs.ravel(), weights=re.ravel(), minlength=n_dof)


def check_inversion(F: np.ndarray, elements: np.ndarray | None = None) -> np.ndarray:
    """``det F`` ``(n_el, n_q)``; raises :class:`InvertedElementError` where it is not positive."""
    J = np.linalg.det(F)
    bad = ~(J > 0)
    if bad.any():
        e, q = np.unravel_index(int(np.argmax(bad)), J.shape)
        eid = int(elements[e]) if elements is not None else int(e)
        raise InvertedElementError(eid, float(J[e, q]))
    return J
