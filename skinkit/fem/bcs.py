"""Boundary conditions: prescribed displacements and a rigid region tied to a reference point.

A load programme is a function of a time-like variable ``t`` (the load factor in [0, 1]
for a static solve, seconds for a viscoelastic history).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from skinkit.fem.errors import ModelError

Programme = Callable[[float], np.ndarray]


def ramp(value) -> Programme:
    """``t -> t * value`` (a static load ramp over the load factor ``t`` in [0, 1])."""
    v = np.asarray(value, dtype=float)
    return lambda t: t * v


@dataclass
class Prescribed:
    """Displacements ``values(t)`` ``(len(dofs),)`` [m] imposed on ``dofs``."""

    dofs: np.ndarray
    values: Programme


@dataclass
class Rigid:
    """A rigid (translating) region: ``nodes`` move together with a reference point.

    ``mode`` ``"displacement"``: the point's displacement ``programme(t)`` ``(3,)`` [m] is
    imposed; ``"force"``: the force ``programme(t)`` ``(3,)`` [N] is applied to the point and
    its displacement is solved for. ``components`` are the tied directions (default all:
    a bonded indenter); ``(2,)`` gives a frictionless one (the nodes slide freely in x, y).
    """

    nodes: np.ndarray
    mode: str
    programme: Programme
    components: tuple[int, ...] = (0, 1, 2)
    #: drive parameter name -> ``t -> (3,)`` derivative of the programme [N or m per SI unit]
    derivatives: dict[str, Programme] = field(default_factory=dict)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Parameters of the programme (e.g. an instrument's bias) that sensitivities cover."""
        return tuple(self.derivatives)

    def derivative(self, name: str, t: float) -> np.ndarray:
        """``(3,)`` ∂programme(t)/∂``name``."""
        return np.asarray(self.derivatives[name](t), dtype=float)

    def __post_init__(self) -> None:
        if self.mode not in ("displacement", "force"):
            raise ModelError("indenter.mode", f"must be 'displacement' or 'force', got {self.mode!r}")
        self.nodes = np.asarray(self.nodes, dtype=int)
        if self.nodes.size == 0:
            raise ModelError("indenter.nodes", "the rigid region has no nodes")
        self.components = tuple(int(c) for c in self.components)
        if not self.components or any(c not in (0, 1, 2) for c in self.components):
            raise ModelError("indenter.components", f"must be a subset of (0, 1, 2), got {self.components}")


@dataclass
class ComplianceSupport:
    """The rim held by a distributed elastic support of compliance ``value`` [m/Pa] (traction =
    −u/value): its ``dofs`` ``(n,)`` — those no other set fixes — and the face area each one
    carries, ``area`` ``(n,)`` [m²]. ``value = 0`` is the fixed rim; the derivative there is
    that of the rim's motion −c f/A (the support's own force over its stiffness)."""

    dofs: np.ndarray
    area: np.ndarray
    value: float
    #: the model parameter's name
    name: str = "boundary.compliance"


@dataclass
class BoundaryConditions:
    """Prescribed displacements and an optional rigid reference point on a mesh of ``n_dof`` dofs."""

    n_dof: int
    prescribed: list[Prescribed] = field(default_factory=list)
    rigid: Rigid | None = None
    #: distributed elastic supports: (dofs, stiffness per dof [N/m]) — traction = -u / compliance
    springs: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    #: the ``[boundary] compliance`` support as a differentiable parameter (also at 0, where its
    #: sets stay fixed): :class:`ComplianceSupport`
    compliance: ComplianceSupport | None = None

    def support(self, nodes: np.ndarray, stiffness_N_per_m: np.ndarray) -> BoundaryConditions:
        """Hold ``nodes`` by springs to ground, ``stiffness_N_per_m`` ``(len(nodes),)`` in every
        direction; returns self."""
        k = np.asarray(stiffness_N_per_m, dtype=float)
        dofs = (3 * np.asarray(nodes)[:, None] + np.arange(3)[None, :]).ravel()
        self.springs.append((dofs, np.repeat(k, 3)))
        return self

    def fix(self, nodes: np.ndarray, components=(0, 1, 2)) -> BoundaryConditions:
        """Fix ``components`` of ``nodes`` at zero; returns self for chaining."""
        dofs = (3 * np.asarray(nodes)[:, None] + np.asarray(components)[None, :]).ravel()
        self.prescribed.append(Prescribed(dofs, lambda t, n=dofs.size: np.zeros(n)))
        return self

    def prescribe(self, nodes: np.ndarray, component: int, programme: Callable[[float], float]
                  ) -> BoundaryConditions:
        """Impose ``programme(t)`` [m] on ``component`` of every node in ``nodes``."""
        dofs = 3 * np.asarray(nodes) + int(component)
        self.prescribed.append(Prescribed(dofs, lambda t, f=programme, n=dofs.size: np.full(n, f(t))))
        return self

    def compile(self) -> DofMap:
        """The :class:`DofMap` of these constraints (free and prescribed dofs)."""
        return DofMap(self)


class DofMap:
    """Full dofs -> reduced unknowns: free dofs, then (force mode) the reference point's 3."""

    def __init__(self, bc: BoundaryConditions) -> None:
        self.bc = bc
        n = bc.n_dof
        role = np.zeros(n, dtype=int)  # 0 free, 1 prescribed, 2 rigid
        for pr in bc.prescribed:
            role[pr.dofs] = 1
        self.rigid_dofs = None
        if bc.rigid is not None:
            self.rigid_components = np.array(bc.rigid.components)
            rd = 3 * bc.rigid.nodes[:, None] + self.rigid_components[None, :]
            if np.any(role[rd] == 1):
                raise ModelError("indenter", "indenter nodes are also fixed by another condition")
            role[rd] = 2
            self.rigid_dofs = rd
        free = np.flatnonzero(role == 0)
        self.n_free = free.size
        self.map = np.full(n, -1, dtype=np.int64)
        self.map[free] = np.arange(free.size)
        self.force_mode = bc.rigid is not None and bc.rigid.mode == "force"
        if self.force_mode:
            self.map[self.rigid_dofs] = self.n_free + np.arange(rd.shape[1])[None, :]
        self.n_unknowns = self.n_free + (self.rigid_dofs.shape[1] if self.force_mode else 0)
        # springs act on free dofs only (a dof also fixed stays fixed)
        self.spring_dofs = np.zeros(0, dtype=np.int64)
        self.spring_k = np.zeros(0)
        if bc.springs:
            d = np.concatenate([a for a, _ in bc.springs])
            k = np.concatenate([b for _, b in bc.springs])
            free_ = self.map[d] >= 0
            self.spring_dofs, self.spring_k = d[free_], k[free_]

    def spring_forces(self, u: np.ndarray) -> np.ndarray:
        """``(n_unknowns,)`` spring forces k u on the reduced unknowns [N]."""
        f = np.zeros(self.n_unknowns)
        if self.spring_dofs.size:
            np.add.at(f, self.map[self.spring_dofs], self.spring_k * u[self.spring_dofs])
        return f

    def spring_matrix(self):
        """Sparse ``(n_unknowns, n_unknowns)`` diagonal spring stiffness, or None."""
        if not self.spring_dofs.size:
            return None
        import scipy.sparse as sp
        diag = np.zeros(self.n_unknowns)
        np.add.at(diag, self.map[self.spring_dofs], self.spring_k)
        return sp.diags(diag, format="csr")

    def apply_prescribed(self, u: np.ndarray, t: float) -> None:
        """Write the prescribed values at ``t`` into ``u`` (in place)."""
        for pr in self.bc.prescribed:
            u[pr.dofs] = pr.values(t)
        rg = self.bc.rigid
        if rg is not None and rg.mode == "displacement":
            u[self.rigid_dofs] = np.asarray(rg.programme(t), dtype=float)[self.rigid_components][None, :]

    def external(self, t: float) -> np.ndarray:
        """``(n_unknowns,)`` external forces on the unknowns at ``t`` [N]."""
        f = np.zeros(self.n_unknowns)
        if self.force_mode:
            f[self.n_free:] = np.asarray(self.bc.rigid.programme(t), dtype=float)[self.rigid_components]
        return f

    def scatter(self, u: np.ndarray, dq: np.ndarray, alpha: float = 1.0) -> np.ndarray:
        """``u + alpha * dq`` expanded onto the full dofs (prescribed dofs unchanged)."""
        out = u.copy()
        m = self.map >= 0
        out[m] += alpha * dq[self.map[m]]
        return out

    def rigid_displacement(self, u: np.ndarray) -> np.ndarray | None:
        """``(3,)`` reference-point displacement [m] (None without a rigid region)."""
        if self.rigid_dofs is None:
            return None
        out = np.full(3, np.nan)  # untied directions have no single displacement
        out[self.rigid_components] = u[self.rigid_dofs[0]]
        return out

    def rigid_force(self, r_full: np.ndarray) -> np.ndarray | None:
        """``(3,)`` total internal force on the rigid region [N] (the force it exerts)."""
        if self.rigid_dofs is None:
            return None
        nodes = self.bc.rigid.nodes
        return r_full.reshape(-1, 3)[nodes].sum(axis=0)
