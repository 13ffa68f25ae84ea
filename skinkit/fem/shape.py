"""Shape sensitivities: parameters that move the mesh's reference nodes.

A geometry parameter p (a layer's thickness) moves the reference node coordinates X(p)
with the design velocity ``V = dX/dp`` ``(n_nodes, 3)`` [m per unit of p]; the elements,
regions and node sets stay. The quadrature points ride with the elements (same element,
same local coordinates), so the discrete residual is a function of the node coordinates
and its derivative along V at fixed nodal displacements u is (total Lagrangian,
``G = ∇_X V`` at each quadrature point)::

    ∇_X(·) → ∇_X(·) − ∇_X(·) G:   δF = −(F − I) G,   δ(∇w) = −∇w G
    dV → (1 + tr G) dV
    ∂r/∂p = ∫ [ −(∇w G) : P − ∇w : A : ((F − I) G) + (∇w : P) tr G ] dV

with ``P = F S`` the first Piola stress and ``A = ∂P/∂F``. Split as skinkit's direct
differentiation needs it: ``A δF = δF S + F δS`` with ``δS`` the stress change at the moved
point — the law's ``½ ℂ : δC`` (and, where a field scales the law, φ's change as its
quadrature point moves in position and depth), carried through a viscous history by the
same recurrence as any other parameter's — and the rest, ``δF S − P Gᵀ + tr G P``, a
first-Piola-like field integrated against ``∇w`` like a stress.

Everything here is exact (no differences): the design velocity itself is geometry, which
the caller supplies (:class:`DesignVelocity`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skinkit.fem.assembly import Geometry
from skinkit.fem.tensors import I3


@dataclass(frozen=True)
class DesignVelocity:
    """How one geometry parameter moves the mesh, per unit of the parameter.

    Attributes:
        nodes: ``(n_nodes, 3)`` dX/dp of every node [m per unit].
        depth: ``(n_nodes,)`` d(depth below the top surface)/dp [m per unit] as fields by depth
            read it (:attr:`skinkit.fem.mesh.FEMesh.depth`), or None (no field reads depth).
        springs: ``(n_spring_dofs,)`` d(stiffness)/dp [N/m per unit] of the distributed
            support's springs in :attr:`skinkit.fem.bcs.DofMap.spring_dofs` order (their face
            areas change as the rim's nodes move), or None (no springs).
    """

    nodes: np.ndarray
    depth: np.ndarray | None = None
    springs: np.ndarray | None = None


@dataclass
class MaterialShape:
    """One design velocity at one material's quadrature points.

    Attributes:
        G: ``(n_el_k, n_q, 3, 3)`` ∇_X V [1 per unit of p].
        Vq: ``(n_el_k, n_q, 3)`` the quadrature points' velocity [m per unit].
        Vd: ``(n_el_k, n_q)`` their depth's velocity [m per unit] (zeros without one).
    """

    G: np.ndarray
    Vq: np.ndarray
    Vd: np.ndarray


def at_quadrature(geom: Geometry, sl: slice, velocity: DesignVelocity) -> MaterialShape:
    """The design velocity at the quadrature points of the elements ``sl`` of ``geom``."""
    ed = geom.edofs[sl]
    ne, nb = ed.shape[0], geom.dN.shape[2]
    ue = velocity.nodes.reshape(-1)[ed].reshape(ne, 3, nb)
    G = np.einsum("eia,eqaJ->eqiJ", ue, geom.dN[sl], optimize=True)
    nodes = ed[:, :nb] // 3          # element dofs are ordered (component, node)
    Vq = np.einsum("qa,eai->eqi", geom.N, velocity.nodes[nodes])
    Vd = np.zeros(Vq.shape[:2]) if velocity.depth is None else \
        np.einsum("qa,ea->eq", geom.N, velocity.depth[nodes])
    return MaterialShape(G, Vq, Vd)


def deformation_change(F: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``δF = −(F − I) G`` ``(..., 3, 3)``: the deformation gradient's change at fixed nodal
    displacements when the reference moves with velocity gradient ``G``."""
    return -(F - I3) @ G


def explicit_stress(F: np.ndarray, G: np.ndarray, CCe: np.ndarray, F0: np.ndarray | None,
                    dphi: np.ndarray | None = None, law_S: np.ndarray | None = None) -> np.ndarray:
    """``δSₑ`` ``(n_el, n_q, 3, 3)`` [Pa per unit]: the elastic stress's change in the natural
    configuration at fixed nodal displacements, ``½ ℂₑ : F0ᵀ δC F0`` (``ℂₑ`` scaled by the
    fields, as the problem evaluates it) plus ``δφ Sₑ_law`` where a field scales the law.

    ``F`` ``(n_el, n_q, 3, 3)``, ``G`` likewise, ``CCe`` ``(n_el, n_q, 3, 3, 3, 3)`` [Pa],
    ``F0`` the natural state (``(3, 3)`` or per point; None), ``dphi`` ``(n_el, n_q)`` and
    ``law_S`` (unscaled) ``(n_el, n_q, 3, 3)``."""
    dF = deformation_change(F, G)
    G1 = np.swapaxes(F, -1, -2) @ dF
    dC = G1 + np.swapaxes(G1, -1, -2)
    if F0 is not None:
        dC = np.swapaxes(F0, -1, -2) @ dC @ F0
    out = 0.5 * np.einsum("eqIJKL,eqKL->eqIJ", CCe, dC, optimize=True)
    if dphi is not None and law_S is not None:
        out = out + dphi[..., None, None] * law_S
    return out


def geometric_piola(F: np.ndarray, S: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``δF S − P Gᵀ + tr G P`` ``(n_el, n_q, 3, 3)`` [Pa per unit]: the part of ∂r/∂p that is not
    ``F δS``, integrated against ``∇w`` as a first Piola stress is (``P = F S``, ``S`` the
    total second Piola stress at the state, pushed through any natural state)."""
    P = F @ S
    trG = np.trace(G, axis1=-2, axis2=-1)[..., None, None]
    return deformation_change(F, G) @ S - P @ np.swapaxes(G, -1, -2) + trG * P


def element_forces(geom: Geometry, sl: slice, P: np.ndarray) -> np.ndarray:
    """``(n, n_el_k, 81)`` [N per unit] ``∫ P : ∇w dV`` of ``n`` first-Piola-like fields ``P``
    ``(n, n_el_k, n_q, 3, 3)`` over the elements ``sl`` (rows ordered as element dofs)."""
    n, ne, nq = P.shape[:3]
    Pw = P * geom.w[sl][None, :, :, None, None]
    A = Pw.transpose(1, 3, 0, 2, 4).reshape(ne, 3 * n, nq * 3)
    out = np.matmul(A, geom.dNT[sl].reshape(ne, nq * 3, -1))
    return out.reshape(ne, 3, n, -1).transpose(2, 0, 1, 3).reshape(n, ne, -1)


def internal_force_derivative(problem, u: np.ndarray, velocity: DesignVelocity) -> np.ndarray:
    """``(n_dof,)`` [N per unit] ∂f_int/∂p at fixed nodal displacements ``u`` ``(n_dof,)`` of
    a static state (viscous laws answer elastically): the formula of the module docstring,
    assembled on its own (the sensitivity pass, :mod:`skinkit.fem.sensitivity`, assembles it
    with the other parameters' loads and through viscous histories)."""
    from skinkit.fem import lawkit
    from skinkit.fem.assembly import full_vector
    from skinkit.fem.tensors import push_with

    g = problem.geom
    out = np.zeros(problem.n_dof)
    states: dict = {}
    lin = problem.linearise(u, None, keep=states)
    for k, m in enumerate(problem.materials):
        sl = problem.slices[k]
        F, _, Ce, _, CCe = states[k]
        ms = at_quadrature(g, sl, velocity)
        dphi = problem.scale_shape_derivative(k, ms.Vq, ms.Vd)
        law_S = None if dphi is None else lawkit.response(m.law, Ce, m.params, False)[0]
        dS = explicit_stress(F, ms.G, CCe, m.F0, dphi, law_S)
        if m.F0 is not None:
            dS = push_with(m.F0, dS)[0]
        P = F @ dS + geometric_piola(F, lin[k][1], ms.G)
        out += full_vector(g.edofs[sl], element_forces(g, sl, P[None])[0], problem.n_dof)
    return out


__all__ = ["DesignVelocity", "MaterialShape", "at_quadrature", "deformation_change", "element_forces",
           "explicit_stress", "geometric_piola", "internal_force_derivative"]
