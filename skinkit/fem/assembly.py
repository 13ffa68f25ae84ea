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
from skinkit.fem.tensors import I3, det3
from skinkit.fem.threads import single_threaded_blas

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
        edofs: ``(n_el, 81)`` vector dofs of each element, ordered (component, node).
        intorder: quadrature degree used.
        dNT: ``(n_el, n_q, 3, 27)`` the gradients transposed (contiguous, for products).
    """

    dN: np.ndarray
    w: np.ndarray
    N: np.ndarray
    edofs: np.ndarray
    intorder: int
    dNT: np.ndarray


def geometry(mesh: FEMesh, intorder: int = DEFAULT_INTORDER) -> Geometry:
    """Evaluate the isoparametric geometry of ``mesh`` with scikit-fem (``intorder`` explicit)."""
    basis = Basis(mesh.skfem_mesh(), ElementHex2(), intorder=intorder)
    nb = basis.Nbfun
    dN = np.empty((mesh.n_elements, basis.dx.shape[1], nb, 3))
    N = np.empty((basis.dx.shape[1], nb))
    for a in range(nb):
        f = basis.basis[a][0]
        dN[:, :, a, :] = np.moveaxis(np.asarray(f.grad), 0, -1)
        N[:, a] = np.asarray(f)[0]
    w = np.asarray(basis.dx)
    if np.any(w <= 0):
        e = int(np.argmin(w.min(axis=1)))
        raise InvertedElementError(e, float(w[e].min()))
    # element dofs component-major, (i, a): the strain operator then comes out of one
    # batched product in this order (see strain_operator)
    nodes = np.asarray(basis.element_dofs).T
    edofs = (3 * nodes[:, None, :] + np.arange(3)[None, :, None]).reshape(mesh.n_elements, -1)
    dNT = np.ascontiguousarray(np.swapaxes(dN, -1, -2))
    return Geometry(dN, w, N, edofs, intorder, dNT)


def deformation_gradient(geom: Geometry, u: np.ndarray, elements: np.ndarray | None = None) -> np.ndarray:
    """``(n_el, n_q, 3, 3)`` deformation gradients ``F = I + ∂u/∂X`` of displacement ``u`` ``(n_dof,)``."""
    ed = geom.edofs if elements is None else geom.edofs[elements]
    dN = geom.dN if elements is None else geom.dN[elements]
    ue = u[ed].reshape(ed.shape[0], 3, -1)
    return I3 + np.einsum("eia,eqaJ->eqiJ", ue, dN, optimize=True)


def element_residual(dN: np.ndarray, w: np.ndarray, F: np.ndarray, S: np.ndarray,
                     dNT: np.ndarray | None = None) -> np.ndarray:
    """``(n_el, 81)`` internal forces ``∫ F S : ∇δu`` [N], ordered (component, node)."""
    ne, nq, nb, _ = dN.shape
    Pw = (F @ S) * w[:, :, None, None]
    # Σ_q,J Pw[e,q,i,J] dN[e,q,a,J] as one batched product over the stacked (q, J) axis
    A = Pw.transpose(0, 2, 1, 3).reshape(ne, 3, nq * 3)
    if dNT is None:
        dNT = np.ascontiguousarray(np.swapaxes(dN, -1, -2))
    with single_threaded_blas():
        return np.matmul(A, dNT.reshape(ne, nq * 3, nb)).reshape(ne, -1)


_VI = np.array([0, 1, 2, 0, 1, 0])
_VJ = np.array([0, 1, 2, 1, 2, 2])


def voigt_tangent(CC: np.ndarray) -> np.ndarray:
    """``(..., 6, 6)`` Voigt form (order 11, 22, 33, 12, 23, 13) of a minor-symmetric tangent."""
    return CC[..., _VI[:, None], _VJ[:, None], _VI[None, :], _VJ[None, :]]


def _selector() -> np.ndarray:
    P = np.zeros((6, 3, 3))
    for v, (I, J) in enumerate(zip(_VI, _VJ, strict=True)):
        P[v, I, J] += 1.0
        if I != J:
            P[v, J, I] += 1.0
    return P


_P = _selector()


def strain_operator(dNT: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``(n_el, n_q, 6, 81)`` B: Voigt Green-strain variation per nodal displacement.

    ``δE_IJ = Σₐ δu_ia (F_iI dNₐ_J + F_iJ dNₐ_I)/2``, shear rows as engineering strains,
    columns ordered (component i, node a). Built as ``(F P) dNᵀ``: one batched product.
    ``dNT`` is ``(n_el, n_q, 3, 27)``.
    """
    ne, nq = F.shape[:2]
    FP = np.einsum("vIJ,eqiI->eqviJ", _P, F, optimize=True).reshape(ne, nq, 18, 3)
    return np.matmul(FP, dNT).reshape(ne, nq, 6, -1)


def element_tangent(dN: np.ndarray, w: np.ndarray, F: np.ndarray, S: np.ndarray,
                    CC: np.ndarray, dNT: np.ndarray | None = None,
                    out: np.ndarray | None = None) -> np.ndarray:
    """``(n_el, 81, 81)`` consistent tangents [N/m]: material plus geometric stiffness.

    Material: ``Σ_q w Bᵀ D B`` with the Voigt tangent D, the quadrature points stacked into
    the contraction so that one matrix product per element does the work. Rows and columns
    are ordered (component, node) like :attr:`Geometry.edofs`. Geometric:
    ``δ_ik Σ_q w dNₐ_J S_JL dN_b_L``.
    """
    with single_threaded_blas():
        return _element_tangent(dN, w, F, S, CC, dNT, out)


#: elements per chunk of the tangent products: keeps the strain operators (~0.1 MB per
#: element) in cache instead of streaming ~70 MB per assembly through memory
CHUNK = 24


def _element_tangent(dN, w, F, S, CC, dNT, out):
    ne, nq, nb, _ = dN.shape
    if dNT is None:
        dNT = np.ascontiguousarray(np.swapaxes(dN, -1, -2))
    if out is None:
        out = np.empty((ne, nb * 3, nb * 3))
    D = voigt_tangent(CC) * w[:, :, None, None]                      # (e, q, 6, 6)
    Sw = S * w[:, :, None, None]
    for a in range(0, ne, CHUNK):
        b = min(a + CHUNK, ne)
        m = b - a
        B = strain_operator(dNT[a:b], F[a:b])                        # (m, q, 6, 81)
        DB = np.matmul(D[a:b], B)                                    # (m, q, 6, 81)
        K = np.matmul(B.reshape(m, nq * 6, nb * 3).transpose(0, 2, 1), DB.reshape(m, nq * 6, nb * 3),
                      out=out[a:b])
        dNS = np.matmul(dN[a:b], Sw[a:b])                            # (m, q, a, L)
        G = np.matmul(dNS.transpose(0, 2, 1, 3).reshape(m, nb, nq * 3),
                      dNT[a:b].reshape(m, nq * 3, nb))               # (m, a, b)
        K4 = K.reshape(m, 3, nb, 3, nb)
        for i in range(3):
            K4[:, i, :, i, :] += G
    return out


def first_elasticity(F: np.ndarray, S: np.ndarray, CC: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``(n_el, n_q, 9, 9)`` weighted tangent ``w ∂P/∂F`` of the first Piola stress ``P = F S``.

    ``A[(J, i), (L, k)] = w (Σ F_iI CC_IJKL F_kK + δ_ik S_LJ)``, rows and columns ordered
    (material index, spatial index) — the order in which ``∇N`` gives ``δF`` — with ``CC`` taken
    minor-symmetric through its Voigt form, exactly as :func:`element_tangent` sees it
    (``Bᵀ D B`` plus the geometric part), so that ``δP = A δF`` reproduces that operator.
    ``F``, ``S`` ``(n_el, n_q, 3, 3)``, ``CC`` ``(n_el, n_q, 3, 3, 3, 3)`` [Pa], ``w`` ``(n_el, n_q)`` [m³].
    """
    ne, nq = F.shape[:2]
    # δE (Voigt) = (F P)ᵀ : δF and F δS = (F P) δS (Voigt): the material part is (F P) D (F P)ᵀ
    with single_threaded_blas():
        FP = np.einsum("vIJ,eqiI->eqJiv", _P, F, optimize=True).reshape(ne, nq, 9, 6)
        A = FP @ (voigt_tangent(CC) @ np.swapaxes(FP, -1, -2))
    ST = np.swapaxes(S, -1, -2)
    A6 = A.reshape(ne, nq, 3, 3, 3, 3)
    for i in range(3):                                                   # geometric: δ_ik S_LJ
        A6[:, :, :, i, :, i] += ST
    A *= w[:, :, None, None]
    return A


def element_tangent_apply(dNT: np.ndarray, A: np.ndarray, ue: np.ndarray) -> np.ndarray:
    """``(n_el, 81, m)`` products ``Kₑ uₑ`` of the element tangents with ``m`` element vectors
    ``ue`` ``(n_el, 81, m)``, without forming the ``(81, 81)`` matrices.

    ``δF = uₑ ∇N``, ``w δP = A δF`` with ``A`` from :func:`first_elasticity`, then
    ``∫ δP : ∇N``: the operator of :func:`element_tangent`, as three batched matrix products
    per element. ``dNT`` ``(n_el, n_q, 3, 27)``. For a few ``m`` it costs a fraction of one
    element-tangent assembly.
    """
    ne, nq, _, nb = dNT.shape
    m = ue.shape[2]
    dN = dNT.reshape(ne, nq * 3, nb)                                             # ((q, J), a)
    U = ue.reshape(ne, 3, nb, m).transpose(0, 2, 1, 3).reshape(ne, nb, 3 * m)    # (a, (i, m))
    with single_threaded_blas():
        dF = np.matmul(dN, U).reshape(ne, nq, 9, m)                              # (q, (J, i), m)
        dP = np.matmul(A, dF)
        out = np.matmul(np.swapaxes(dN, -1, -2), dP.reshape(ne, nq * 3, 3 * m))  # (a, (i, m))
    return out.reshape(ne, nb, 3, m).transpose(0, 2, 1, 3).reshape(ne, 3 * nb, m)


class SparsePattern:
    """The sparsity pattern of a reduced system, built once, reused for every assembly.

    With ``upper`` only the upper triangle is kept (for symmetric solvers).
    ``dof_map`` ``(n_dof,)`` sends each full dof to its reduced unknown, or -1 when it is
    prescribed (several dofs may share an unknown: a rigid region tied to a reference point).
    """

    def __init__(self, edofs: np.ndarray, dof_map: np.ndarray, n_unknowns: int,
                 upper: bool = False) -> None:
        self.n = int(n_unknowns)
        self.upper = bool(upper)
        self.dof_map = np.asarray(dof_map)
        r = self.dof_map[edofs]                              # (e, 81)
        rows = np.repeat(r, r.shape[1], axis=1).ravel()
        cols = np.tile(r, (1, r.shape[1])).ravel()
        valid = (rows >= 0) & (cols >= 0)
        if upper:  # symmetric solvers take the upper triangle only
            valid &= cols >= rows
        self.take = np.flatnonzero(valid)
        keys = rows[valid].astype(np.int64) * self.n + cols[valid]
        uniq, self.inv = np.unique(keys, return_inverse=True)
        self.indices = (uniq % self.n).astype(np.int32)
        self.indptr = np.searchsorted(uniq // self.n, np.arange(self.n + 1)).astype(np.int32)
        self.nnz = uniq.size
        # the scatter as one sparse product (nnz x element entries): about half the time
        # of gathering then bin-counting the element matrices
        n_entries = edofs.shape[0] * edofs.shape[1] ** 2
        self._gather = sp.csr_matrix((np.ones(self.take.size), (self.inv, self.take)),
                                     shape=(self.nnz, n_entries))
        rvec = r.ravel()
        self.rtake = np.flatnonzero(rvec >= 0)
        self.rdest = rvec[self.rtake]

    def matrix(self, Ke: np.ndarray) -> sp.csr_matrix:
        """Scatter element matrices ``(n_el, 81, 81)`` into the reduced CSR matrix."""
        data = self._gather @ Ke.ravel()
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))

    def vector(self, re: np.ndarray) -> np.ndarray:
        """Scatter element vectors ``(n_el, 81)`` into the reduced vector ``(n_unknowns,)``."""
        return np.bincount(self.rdest, weights=re.ravel()[self.rtake], minlength=self.n)


def full_vector(edofs: np.ndarray, re: np.ndarray, n_dof: int) -> np.ndarray:
    """Scatter element vectors into a full ``(n_dof,)`` vector (e.g. nodal reaction forces)."""
    return np.bincount(edofs.ravel(), weights=re.ravel(), minlength=n_dof)


def check_inversion(F: np.ndarray, elements: np.ndarray | None = None) -> np.ndarray:
    """``det F`` ``(n_el, n_q)``; raises :class:`InvertedElementError` where it is not positive."""
    J = det3(F)
    bad = ~(J > 0)
    if bad.any():
        e, q = np.unravel_index(int(np.argmax(bad)), J.shape)
        eid = int(elements[e]) if elements is not None else int(e)
        raise InvertedElementError(eid, float(J[e, q]))
    return J
