"""A discretised solid: mesh + one material (law, parameters, pre-stress) per region.

:class:`Problem` evaluates element residuals and tangents for a displacement field, with
quasi-linear viscoelastic histories where a law has a Prony series.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.fem import lawkit, viscoelastic
from skinkit.fem.assembly import (
    DEFAULT_INTORDER,
    Geometry,
    check_inversion,
    element_residual,
    element_tangent,
    geometry,
)
from skinkit.fem.errors import ModelError
from skinkit.fem.fields import Field
from skinkit.fem.mesh import FEMesh
from skinkit.fem.tensors import I3, push_with
from skinkit.fem.threads import single_threaded_blas


@dataclass
class Material:
    """A law bound to a region.

    Attributes:
        region: region name in the mesh.
        law: a :class:`skinkit.interfaces.Law` object.
        params: parameter name -> SI value.
        F0: optional initial deformation gradient (pre-stress), ``(3, 3)`` or
            ``(n_el_region, n_q, 3, 3)``; the law sees ``C_e = F0ᵀ C F0``.
        prestress: optional in-plane pre-stretch ``(l1, l2, angle [rad])`` (see
            :func:`prestretch`); sets ``F0`` and makes the stretches differentiable.
        bounds: parameter name -> (lower, upper) [SI], the range a fit may give it (narrower
            than the law's admissible range; the model file's ``bounds``).
    """

    region: str
    law: Any
    params: Mapping[str, Any]
    F0: np.ndarray | None = None
    elements: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    prestress: tuple[float, float, float] | None = None
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def prony(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The law's Prony series ``(g (N,), tau (N,) [s])`` at its parameters, or None for an elastic law."""
        f = getattr(self.law, "prony", None)
        return f(self.params) if callable(f) else None


def prestretch(l1: float, l2: float, angle: float = 0.0, l3: float | None = None) -> np.ndarray:
    """``(3, 3)`` in-plane anisotropic pre-stretch: ``l1`` along the in-plane direction at
    ``angle`` [rad] from x, ``l2`` across it, ``l3`` through the thickness (isochoric
    ``1/(l1 l2)`` if None)."""
    if l1 <= 0 or l2 <= 0 or (l3 is not None and l3 <= 0):
        raise ModelError("prestress", f"stretches must be positive, got {l1}, {l2}, {l3}")
    l3 = 1.0 / (l1 * l2) if l3 is None else l3
    c, s = np.cos(angle), np.sin(angle)
    Q = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return Q @ np.diag([l1, l2, l3]) @ Q.T


#: complex step of :meth:`Problem.scale_shape_derivative` [1]
_CS = 1e-30

#: elements per chunk of the law-and-tangent evaluation (see ``evaluate``)
_CHUNK = 48


def _bind_materials(mesh: FEMesh, materials: list[Material]) -> None:
    """One material per region of ``mesh``: give each its elements, checked parameters and
    pre-stretch ``F0`` (in place; ModelError naming the material otherwise)."""
    names = [m.region for m in materials]
    for r in mesh.regions:
        if names.count(r) != 1:
            raise ModelError("materials", f"region {r!r} needs exactly one material, "
                             f"has {names.count(r)}")
    for m in materials:
        if m.region not in mesh.regions:
            raise ModelError("materials", f"no region {m.region!r} in the mesh ({mesh.regions})")
        m.elements = mesh.region_elements(m.region)
        m.params = lawkit.check_parameters(m.law, dict(m.params), f"materials[{m.region}]")
        if m.prestress is not None:
            m.prestress = tuple(float(x) for x in m.prestress)
            m.F0 = prestretch(*m.prestress)
        if m.F0 is not None:
            m.F0 = np.asarray(m.F0, dtype=float)
            if np.linalg.det(m.F0.reshape(-1, 3, 3)).min() <= 0:
                raise ModelError(f"materials[{m.region}].prestress", "det F0 must be positive")


class Problem:
    """Mesh, geometry and materials; evaluates element forces and tangents.

    ``materials`` must cover every region of the mesh exactly once.
    """

    def __init__(self, mesh: FEMesh, materials: list[Material], intorder: int = DEFAULT_INTORDER,
                 geom: Geometry | None = None, fields: Sequence[Field] = ()) -> None:
        self.mesh = mesh
        #: the time [s] (or load factor) the solver is at: time-dependent fields read it
        self.t = 0.0
        self.geom = geom if geom is not None else geometry(mesh, intorder)
        _bind_materials(mesh, materials)
        self.materials = materials
        # group the elements material by material once, so that each material works on a
        # contiguous slice of the geometry arrays (no gathers in the hot path)
        order = np.concatenate([m.elements for m in materials])
        self.order = order
        if not np.array_equal(order, np.arange(order.size)):
            g = self.geom
            self.geom = Geometry(g.dN[order], g.w[order], g.N, g.edofs[order], g.intorder, g.dNT[order])
        start = 0
        self.slices: list[slice] = []
        for m in materials:
            self.slices.append(slice(start, start + m.elements.size))
            start += m.elements.size
        nq = self.geom.w.shape[1]
        self.fields = list(fields)
        self._field_points: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._static_phi: dict[int, np.ndarray | None] = {}
        for f in self.fields:
            for layer in f.layers:
                if layer not in [m.region for m in materials]:
                    raise ModelError(f"fields[{f.name}].layers", f"no layer {layer!r}")
        for k, m in enumerate(materials):
            if self.fields_of(k):
                self._field_points[k] = self._quadrature_points(m.elements)
                static = [f for f in self.fields_of(k) if f.kind != "softening"]
                phi = None
                for f in static:
                    v = f.value(*self._field_points[k], 0.0)
                    phi = v if phi is None else phi * v
                self._static_phi[k] = phi
        self.state: dict[int, viscoelastic.PronyState] = {}
        for k, m in enumerate(materials):
            pr = m.prony()
            if pr is not None:
                self.state[k] = viscoelastic.PronyState.zeros(len(pr[0]), (m.elements.size, nq))

    def _quadrature_points(self, elements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Reference positions ``(n, n_q, 3)`` [m] and depths below the top ``(n, n_q)`` [m]."""
        el = self.mesh.elements[elements]
        Xq = np.einsum("qa,eai->eqi", self.geom.N, self.mesh.nodes[el])
        depth_n = self.mesh.depth if self.mesh.depth is not None else \
            self.mesh.nodes[:, 2].max() - self.mesh.nodes[:, 2]
        dq = np.einsum("qa,ea->eq", self.geom.N, depth_n[el])
        return Xq, dq

    def fields_of(self, k: int) -> list[Field]:
        """The fields acting on material ``k``."""
        return [f for f in self.fields if self.materials[k].region in f.layers]

    def scale(self, k: int, sub: slice | None = None) -> np.ndarray | None:
        """φ ``(n_el_k, n_q)`` of material ``k`` at the current time (None: no field)."""
        fs = self.fields_of(k)
        if not fs:
            return None
        phi = self._static_phi[k]
        for f in fs:
            if f.kind == "softening":
                v = f.value(*self._field_points[k], self.t)
                phi = v if phi is None else phi * v
        return phi if sub is None else phi[sub]

    def scale_derivative(self, k: int, name: str) -> np.ndarray | None:
        """∂φ/∂``name`` ``(n_el_k, n_q)`` for a field parameter ``"<field>.<key>"`` (None if
        that field does not act on material ``k``)."""
        fs = self.fields_of(k)
        target = [f for f in fs if name in f.parameter_names]
        if not target:
            return None
        f = target[0]
        Xq, dq = self._field_points[k]
        d = f.derivative(name[len(f.name) + 1:], Xq, dq, self.t)
        if len(fs) > 1:
            # the other fields' product as every field's over this one's (φ > 0 always: a ratio is
            # positive, a softening below 1): one division, not each other field evaluated again —
            # a region scan puts hundreds of fields on one layer
            d = d * (self.scale(k) / f.value(Xq, dq, self.t))
        return d

    def scale_shape_derivative(self, k: int, Vq: np.ndarray, Vd: np.ndarray) -> np.ndarray | None:
        """dφ/dp ``(n_el_k, n_q)`` of material ``k`` at the current time when its quadrature points
        move with velocity ``Vq`` ``(n_el_k, n_q, 3)`` and their depths with ``Vd`` ``(n_el_k, n_q)``
        [m per unit of p] (a geometry parameter; None: no field), by the complex step (φ is
        analytic in position and depth, so exact to rounding)."""
        fs = self.fields_of(k)
        if not fs:
            return None
        Xq, dq = self._field_points[k]
        phi = None
        for f in fs:
            v = f.complex_value(Xq + 1j * _CS * Vq, dq + 1j * _CS * Vd, self.t)
            phi = v if phi is None else phi * v
        return np.imag(phi) / _CS

    def elastic_response(self, k: int, Ce: np.ndarray, with_tangent: bool, sub: slice | None = None):
        """``(Se, CCe)``: material ``k``'s elastic stress and tangent in its natural configuration
        (``Ce = F0ᵀ C F0``), scaled by its fields."""
        m = self.materials[k]
        S, CC = lawkit.response(m.law, Ce, m.params, with_tangent)
        phi = self.scale(k, sub)
        if phi is not None:
            S = phi[..., None, None] * S
            if CC is not None:
                CC = phi[..., None, None, None, None] * CC
        return S, CC

    @property
    def n_dof(self) -> int:
        """Number of degrees of freedom (3 per node)."""
        return self.mesh.n_dof

    @property
    def viscous(self) -> bool:
        """True when some material carries a viscous (Prony) history."""
        return bool(self.state)

    def material_response(self, k: int, F: np.ndarray, with_tangent: bool, dt: float | None,
                          sub: slice | None = None, keep: list | None = None):
        """``(S, CC)`` of material ``k`` at deformation gradients ``F`` of its elements (or of
        the elements ``sub`` of them, a slice relative to the material). ``keep``: a list to
        which ``(C, Ce, Se, CCe)`` (right Cauchy-Green tensor, its natural-configuration form
        and the elastic response there) are appended, for a sensitivity pass at this state."""
        m = self.materials[k]
        C0 = np.swapaxes(F, -1, -2) @ F
        C = C0 if m.F0 is None else np.swapaxes(m.F0, -1, -2) @ C0 @ m.F0
        S, CC = self.elastic_response(k, C, with_tangent, sub)
        if keep is not None:
            keep.append((C0, C, S, CC))
        if k in self.state and dt is not None:
            g, tau = m.prony()
            st = self.state[k]
            if sub is not None:
                st = viscoelastic.PronyState(st.h[:, sub], st.Se[sub])
            S, fac, _ = viscoelastic.trial(st, g, tau, dt, S)
            if CC is not None:
                CC = fac * CC
        if m.F0 is not None:
            S, CC = push_with(m.F0, S, CC)
        return S, CC

    def evaluate(self, u: np.ndarray, with_tangent: bool = True, dt: float | None = None,
                 keep: dict | None = None):
        """Element forces ``(n_el, 81)`` [N] and tangents ``(n_el, 81, 81)`` [N/m] (or None).

        ``dt`` [s] advances viscous histories by a trial step (None: elastic response of
        viscous laws, as for a static solve). Raises :class:`InvertedElementError`.
        ``keep`` (with a tangent only): filled with material -> ``(F, C, Ce, Se, CCe)`` at
        ``u``, so a sensitivity pass does not evaluate the laws a second time.
        """
        g = self.geom
        ne = self.mesh.n_elements
        re = np.empty((ne, g.edofs.shape[1]))
        Ke = np.empty((ne, g.edofs.shape[1], g.edofs.shape[1])) if with_tangent else None
        for k in range(len(self.materials)):
            el = self.slices[k]
            F = self._F(u, k)
            if not with_tangent:
                S, _ = self.material_response(k, F, False, dt)
                re[el] = element_residual(g.dN[el], g.w[el], F, S, g.dNT[el])
                continue
            # tangents chunk by chunk: the fourth-order arrays stay in cache
            n = el.stop - el.start
            parts: list | None = [] if keep is not None else None
            for a in range(0, n, _CHUNK):
                sub = slice(a, min(a + _CHUNK, n))
                ge = slice(el.start + sub.start, el.start + sub.stop)
                S, CC = self.material_response(k, F[sub], True, dt, sub, parts)
                re[ge] = element_residual(g.dN[ge], g.w[ge], F[sub], S, g.dNT[ge])
                element_tangent(g.dN[ge], g.w[ge], F[sub], S, CC, g.dNT[ge], out=Ke[ge])
            if keep is not None:
                keep[k] = (F, *(np.concatenate([p[i] for p in parts]) for i in range(4)))
        return re, Ke

    def linearise(self, u: np.ndarray, dt: float | None = None, keep: dict | None = None) -> list:
        """Per material, ``(F, S, CC)`` at ``u``: what the element tangents are made of
        (deformation gradients ``F`` ``(n_el_k, n_q, 3, 3)``, PK2 stress ``S`` [Pa] and its
        tangent ``CC`` ``(n_el_k, n_q, 3, 3, 3, 3)`` [Pa] as :meth:`evaluate` uses them), without
        the ``(81, 81)`` element matrices (see :func:`skinkit.fem.assembly.element_tangent_apply`).
        ``dt`` and ``keep`` as in :meth:`evaluate`."""
        out = []
        for k in range(len(self.materials)):
            F = self._F(u, k)
            parts: list | None = [] if keep is not None else None
            S, CC = self.material_response(k, F, True, dt, None, parts)
            if keep is not None:
                keep[k] = (F, *parts[0])
            out.append((F, S, CC))
        return out

    def _F(self, u: np.ndarray, k: int) -> np.ndarray:
        """Deformation gradients ``(n_el_k, n_q, 3, 3)`` of material ``k``'s elements."""
        el = self.slices[k]
        g = self.geom
        ue = u[g.edofs[el]].reshape(-1, 1, 3, g.dN.shape[2])
        with single_threaded_blas():
            F = I3 + np.matmul(ue, g.dN[el])   # (e, 1, i, a) @ (e, q, a, J) -> (e, q, i, J)
        check_inversion(F, self.order[el])
        return F

    def commit(self, u: np.ndarray, dt: float) -> None:
        """Accept a converged time step: store the viscous histories at ``u``."""
        for k, st in self.state.items():
            m = self.materials[k]
            F = self._F(u, k)
            C = np.swapaxes(F, -1, -2) @ F
            if m.F0 is not None:
                C = np.swapaxes(m.F0, -1, -2) @ C @ m.F0
            Se = self.elastic_response(k, C, False)[0]
            g, tau = m.prony()
            _, _, h_new = viscoelastic.trial(st, g, tau, dt, Se)
            st.h = h_new
            st.Se = Se

    def save_state(self) -> dict[int, viscoelastic.PronyState]:
        """A copy of the viscous history (material index -> Prony state), for :meth:`restore_state`."""
        return {k: s.copy() for k, s in self.state.items()}

    def restore_state(self, saved: dict[int, viscoelastic.PronyState]) -> None:
        """Restore a history saved by :meth:`save_state` (copied: the saved one stays intact)."""
        self.state = {k: s.copy() for k, s in saved.items()}

    def stress_at(self, u: np.ndarray, dt: float | None = None) -> np.ndarray:
        """``(n_el, n_q, 3, 3)`` PK2 stress [Pa] (with respect to the mesh configuration)."""
        nq = self.geom.w.shape[1]
        out = np.zeros((self.mesh.n_elements, nq, 3, 3))
        for k, m in enumerate(self.materials):
            F = self._F(u, k)
            out[m.elements] = self.material_response(k, F, False, dt)[0]
        return out

    def deformation_gradients(self, u: np.ndarray) -> np.ndarray:
        """``(n_el, n_q, 3, 3)`` deformation gradients, in mesh element order."""
        nq = self.geom.w.shape[1]
        out = np.zeros((self.mesh.n_elements, nq, 3, 3))
        for k, m in enumerate(self.materials):
            out[m.elements] = self._F(u, k)
        return out

    def cauchy_at(self, u: np.ndarray, dt: float | None = None) -> np.ndarray:
        """``(n_el, n_q, 3, 3)`` Cauchy stress [Pa]."""
        S = self.stress_at(u, dt)
        F = self.deformation_gradients(u)
        return F @ S @ np.swapaxes(F, -1, -2) / np.linalg.det(F)[..., None, None]
