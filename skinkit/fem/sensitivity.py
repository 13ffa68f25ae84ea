"""Parameter sensitivities by direct differentiation with the converged tangent.

At a converged state the reduced residual vanishes, ``r(u(p), p) = 0``, so
``K du/dp = -∂r/∂p`` with ``K`` the tangent at that state: one factorisation (the
converged tangent) and one back-substitution per parameter give every derivative, instead
of one nonlinear solve per parameter as finite differences need.

Parameters differentiated (every one the model has, static or through a viscous history):

* **law parameters** ``"<region>.<name>"``: ∂S/∂p at fixed deformation (complex step for
  complex-safe laws, central differences otherwise), Prony parameters through the
  recurrence of the history;
* **pre-stretch** ``"<region>.prestretch.l1|l2|angle"``: the natural state ``F0`` moves, so
  ``Ce = F0ᵀ C F0`` and the push-forward ``F0 S F0ᵀ`` both change (∂F0/∂p by complex step);
* **field parameters** ``"<field>.<key>"``: ∂φ/∂p times the law's elastic stress;
* **drive parameters** (named by the rigid region's programme, e.g. instrument biases):
  the applied force (force control) or the imposed motion (displacement control) changes;
* **geometry parameters** (``shapes``: name -> :class:`skinkit.fem.shape.DesignVelocity`, a
  layer's thickness): the reference nodes move; the shape derivative of the internal force at
  fixed displacement (:mod:`skinkit.fem.shape`) is the pseudo-load, its stress part carried
  through viscous histories like a law parameter's, and a distributed support's springs
  change with the rim's face areas;
* **the support's compliance** ``"boundary.compliance"`` c [m/Pa] (``[boundary] compliance``):
  for c > 0 the rim's springs A/c give ∂r/∂c = −(A/c²) u on its dofs; at c = 0 (the rim fixed)
  the rim moves as −c f/A to first order, f the support's force on it (the internal force at
  its dofs), so its motion's derivative −f/A is imposed as a drive's would be.

Through a viscous history (Prony recurrence hⁿ = e hⁿ⁻¹ + β (Sₑⁿ − Sₑⁿ⁻¹), S = g∞ Sₑ + Σ g h) the
derivative of the stress at fixed displacement carries the derivatives of the history; the
converged algorithmic tangent gives duⁿ/dp, from which the total dSₑⁿ/dp and dhⁿ/dp are
updated for the next step. Outputs: ``du/dp`` (hence embedded points), the indenter's
motion (force control) and its reaction force (both controls), every nodal reaction.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from skinkit.fem import lawkit, viscoelastic
from skinkit.fem import shape as shape_mod
from skinkit.fem.assembly import element_tangent, element_tangent_apply, first_elasticity, full_vector
from skinkit.fem.problem import Problem
from skinkit.fem.tensors import push_with
from skinkit.fem.threads import single_threaded_blas

#: Prony parameters of a QLV law (relative moduli and relaxation times)
_PRONY = re.compile(r"^(g|tau)[0-9]+$")

#: pre-stretch parameters of a material with ``prestress = (l1, l2, angle)`` (local names)
PRESTRESS_NAMES = ("prestretch.l1", "prestretch.l2", "prestretch.angle")
_CS = 1e-30
#: ways of solving with the converged tangent (see HistorySensitivity)
METHODS = ("iterative", "direct")

if TYPE_CHECKING:  # the solver runs this module's trackers; annotations only here
    from skinkit.fem.bcs import ComplianceSupport
    from skinkit.fem.solver import NewtonSolver


def _b5(a) -> np.ndarray:
    """Per-term factors ``(n,)`` shaped to broadcast over ``(n, e, q, 3, 3)`` histories."""
    return np.asarray(a)[:, None, None, None, None]


def _F0(l1, l2, angle):
    """Complex-safe ``prestretch`` (no checks): Q diag(l1, l2, 1/(l1 l2)) Qᵀ."""
    c, s = np.cos(angle), np.sin(angle)
    Q = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=np.result_type(l1, l2, angle, float))
    return Q @ np.diag(np.array([l1, l2, 1.0 / (l1 * l2)])) @ Q.T


def dF0(prestress: tuple[float, float, float], i: int) -> np.ndarray:
    """∂F0/∂(l1, l2, angle)[i] ``(3, 3)`` by the complex step."""
    q: list[Any] = list(prestress)
    q[i] = q[i] + 1j * _CS
    return np.imag(_F0(*q)) / _CS


@dataclass
class Sensitivities:
    """Derivatives at one converged state.

    Attributes:
        names: parameter names, in column order.
        du: ``(n_dof, n_par)`` displacement derivatives [m per parameter unit].
        tip_displacement: ``(3, n_par)`` reference-point motion derivatives (NaN in untied directions).
        tip_force: ``(3, n_par)`` indenter force derivatives [N per parameter unit].
        reaction: ``(n_dof, n_par)`` nodal internal-force derivatives [N per parameter unit], when
            asked for (``HistorySensitivity(reactions=True)``, :func:`sensitivities`), else None.
    """

    names: list[str]
    du: np.ndarray
    tip_displacement: np.ndarray | None
    tip_force: np.ndarray | None
    reaction: np.ndarray | None


@dataclass(frozen=True)
class _Par:
    """One parameter: its name, its kind and, for material parameters, the material."""

    name: str
    kind: str            # "law", "prony", "prestretch", "field", "drive", "compliance", "shape"
    k: int = -1          # material (law, prony, prestretch)
    local: str = ""      # law parameter name, or prestretch index as str


def parameter_list(problem: Problem, drive_names: tuple[str, ...] = (),
                   compliance: ComplianceSupport | None = None, shapes: tuple[str, ...] = ()) -> list[_Par]:
    """Every differentiable parameter of ``problem`` (and of its drive and elastic support), and
    the geometry parameters ``shapes`` whose design velocities the caller gives."""
    out: list[_Par] = []
    for k, m in enumerate(problem.materials):
        pr = m.prony() is not None
        for n in lawkit.parameter_names(m.law):
            kind = "prony" if pr and _PRONY.match(n) else "law"
            out.append(_Par(f"{m.region}.{n}", kind, k, n))
        if m.prestress is not None:
            out.extend(_Par(f"{m.region}.{n}", "prestretch", k, str(i))
                       for i, n in enumerate(PRESTRESS_NAMES))
    for f in problem.fields:
        out.extend(_Par(n, "field") for n in f.parameter_names)
    out.extend(_Par(n, "drive") for n in drive_names)
    if compliance is not None:
        out.append(_Par(compliance.name, "compliance"))
    out.extend(_Par(n, "shape") for n in shapes)
    return out


def parameter_names(problem: Problem, drive_names: tuple[str, ...] = (),
                    compliance: ComplianceSupport | None = None) -> list[str]:
    """Names of :func:`parameter_list`."""
    return [p.name for p in parameter_list(problem, drive_names, compliance)]


class HistorySensitivity:
    """Direct differentiation of a load history, static or viscous.

    Call :meth:`step` after each converged increment and before the problem commits it
    (``NewtonSolver.run(..., sensitivities=True)`` does so); with ``dt = None`` the state is
    static (viscous laws answer elastically, as in a static solve). ``only``: restrict to
    these parameter names (the others are not computed).

    ``method``: how ``K du/dp = -∂r/∂p`` is solved with the converged tangent ``K`` — exact
    either way (see :meth:`_solve`): ``"iterative"`` (default) builds no tangent matrix and
    factorises nothing when the Newton loop's last factorisation is at hand, ``"direct"``
    assembles and factorises ``K`` at every step. ``reactions``: also return every nodal
    reaction derivative (``Sensitivities.reaction``; otherwise None and only the elements
    holding the indenter are differentiated). ``tol``, ``max_iter``: the iterative solve's
    relative error estimate per column and iteration limit (with its final correction the
    error is well below the estimate: on ``skinkit bench fit`` at most 6e-11 of each column
    against a sparse LU of the assembled tangent). ``shapes``: geometry parameters, name ->
    :class:`skinkit.fem.shape.DesignVelocity` (differentiated as the others).
    """

    def __init__(self, solver: NewtonSolver, only: list[str] | None = None, method: str = "iterative",
                 reactions: bool = False, tol: float = 1e-8, max_iter: int = 12,
                 shapes: Mapping[str, shape_mod.DesignVelocity] | None = None) -> None:
        if method not in METHODS:
            from skinkit.fem.errors import ModelError
            raise ModelError("sensitivities", f"method {method!r} is not one of {list(METHODS)}")
        self.method, self.reactions = method, bool(reactions)
        self.tol, self.max_iter = float(tol), int(max_iter)
        #: solves by conjugate gradients, their iterations, and tangents factorised here
        self.stats = {"iterative": 0, "iterations": 0, "factorisations": 0}
        self.solver = solver
        prob = solver.problem
        rigid = solver.dofmap.bc.rigid
        drive = tuple(getattr(rigid, "parameter_names", ())) if rigid is not None else ()
        shapes = dict(shapes or {})
        pars = parameter_list(prob, drive, solver.dofmap.bc.compliance, tuple(shapes))
        if only is not None:
            known = {p.name for p in pars}
            unknown = sorted(set(only) - known)
            if unknown:
                from skinkit.fem.errors import ModelError
                raise ModelError("sensitivities", f"no parameter(s) {unknown} in the model; it has "
                                 f"{sorted(known)}")
            pars = [p for p in pars if p.name in set(only)]
        self.pars = pars
        self.names = [p.name for p in pars]
        #: parameter index -> material -> its design velocity at the quadrature points
        self._shape = {j: [shape_mod.at_quadrature(prob.geom, sl, shapes[p.name]) for sl in prob.slices]
                       for j, p in enumerate(pars) if p.kind == "shape"}
        self._shape_springs = {j: shapes[pars[j].name].springs for j in self._shape}
        nq = prob.geom.w.shape[1]
        npar = len(pars)
        self.dSe: dict[int, np.ndarray] = {}
        self.dh: dict[int, np.ndarray] = {}
        for k, st in prob.state.items():
            ne = prob.materials[k].elements.size
            self.dSe[k] = np.zeros((npar, ne, nq, 3, 3))
            self.dh[k] = np.zeros((npar, st.h.shape[0], ne, nq, 3, 3))
        dm, g = solver.dofmap, prob.geom
        # element vectors -> reduced unknowns, as one sparse product for every column at once
        p_ = solver.pattern
        self._gather = sp.csr_matrix((np.ones(p_.rtake.size), (p_.rdest, p_.rtake)),
                                     shape=(p_.n, g.edofs.size))
        self._expand = self._gather.T.tocsr()   # reduced unknowns -> element vectors
        self._springs = dm.spring_matrix()
        #: material -> parameter index -> ∂Sₑ/∂p at fixed deformation, of the current step
        self._explicit: dict[int, dict[int, np.ndarray]] = {}
        # the elements holding the indenter's nodes: the only ones its force derivative reads
        self._tip_elements = np.zeros(0, dtype=int)
        if dm.rigid_dofs is not None:
            on = np.zeros(prob.n_dof, dtype=bool)
            on[(3 * dm.bc.rigid.nodes[:, None] + np.arange(3)).ravel()] = True
            self._tip_elements = np.flatnonzero(on[g.edofs].any(axis=1))

    # -- explicit derivatives at fixed displacement ------------------------------------------
    def _explicit_dSe(self, k: int, j: int, Ce: np.ndarray, C: np.ndarray, F: np.ndarray,
                      CCe: np.ndarray | None, law_S: np.ndarray | None) -> np.ndarray | None:
        """∂Sₑ/∂p (natural configuration, scaled by the fields) at fixed displacement."""
        prob = self.solver.problem
        m = prob.materials[k]
        p = self.pars[j]
        if p.kind == "shape":
            ms = self._shape[j][k]
            dphi = prob.scale_shape_derivative(k, ms.Vq, ms.Vd)
            return shape_mod.explicit_stress(F, ms.G, CCe, m.F0, dphi, law_S)
        if p.kind == "law" and p.k == k:
            d = lawkit.stress_parameter_derivative(m.law, Ce, m.params, p.local)
            phi = prob.scale(k)
            return d if phi is None else phi[..., None, None] * d
        if p.kind == "prestretch" and p.k == k:
            dF = dF0(m.prestress, int(p.local))
            dCe = np.swapaxes(dF, -1, -2) @ C @ m.F0 + np.swapaxes(m.F0, -1, -2) @ C @ dF
            return 0.5 * np.einsum("eqIJKL,eqKL->eqIJ", CCe, dCe)
        if p.kind == "field":
            dphi = prob.scale_derivative(k, p.name)
            if dphi is None:
                return None
            return dphi[..., None, None] * law_S
        return None

    def _prony_partials(self, k: int, name: str, dt: float):
        """(∂g∞, ∂g (n,), ∂e (n,), ∂β (n,)) of the Prony factors w.r.t. parameter ``name``."""
        g, tau = self.solver.problem.materials[k].prony()
        n = len(g)
        dginf, dg, de, dbeta = 0.0, np.zeros(n), np.zeros(n), np.zeros(n)
        x = dt / tau
        e = np.exp(-x)
        for i in range(n):
            if name == f"g{i + 1}":
                dg[i] = 1.0
                dginf = -1.0
            elif name == f"tau{i + 1}":
                de[i] = e[i] * dt / tau[i] ** 2
                dbeta[i] = (-de[i] * tau[i] + (1 - e[i])) / dt
        return dginf, dg, de, dbeta

    def _partials(self, k: int, p: _Par, dt: float | None, n_terms: int):
        if p.kind == "prony" and p.k == k and dt is not None and dt > 0:
            return self._prony_partials(k, p.local, dt)
        if p.kind == "prony" and p.k == k:   # instantaneous (static) response: only g matters via g∞
            z = np.zeros(n_terms)
            return 0.0, z, z, z
        z = np.zeros(n_terms)
        return 0.0, z, z, z

    def step(self, u: np.ndarray, t: float, dt: float | None) -> Sensitivities:
        """Sensitivities at the converged ``u`` of the increment of length ``dt`` [s] ending at
        ``t`` (``dt`` None: static)."""
        solver, prob, g = self.solver, self.solver.problem, self.solver.problem.geom
        npar = len(self.pars)
        prob.t = t
        viscous = dt is not None and prob.viscous
        states: dict = {}
        # the tangent's ingredients at u (law stress and tangent), not its element matrices
        lin = prob.linearise(u, dt if viscous else None, keep=states)
        lin = [(F, S, first_elasticity(F, S, CC, g.w[sl]), CC)
               for (F, S, CC), sl in zip(lin, prob.slices, strict=True)]
        dre = self._pseudo_loads(states, dt, viscous, lin)
        # right-hand sides: explicit material part, plus the drive
        rhs = self._reduce(dre.transpose(1, 2, 0)) if npar else np.zeros((solver.dofmap.n_unknowns, 0))
        dm = solver.dofmap
        rigid = dm.bc.rigid
        dup = self._drive(rhs, t, lin)
        self._support(rhs, u, lin, dup)
        self._springs_moved(rhs, u)
        dq = -self._solve(rhs, lin, states) if npar else rhs
        mp = dm.map
        du = dup.copy()
        du[mp >= 0] = dq[mp[mp >= 0]]
        react = None
        if self.reactions:
            react = _full(g.edofs, dre.transpose(1, 2, 0) + self._apply(lin, du), prob.n_dof)
        if viscous:
            self._update_history(u, du, dt, states)
        tip_u = tip_f = None
        if dm.rigid_dofs is not None:
            tip_u = np.full((3, npar), np.nan)
            tip_u[dm.rigid_components] = du[dm.rigid_dofs[0]]
            if react is not None:
                tip_f = react.reshape(-1, 3, npar)[rigid.nodes].sum(axis=0)
            else:   # only the elements holding the indenter's nodes carry its force
                el = self._tip_elements
                fe = dre[:, el].transpose(1, 2, 0) + self._apply(lin, du, el)
                tip_f = _full(g.edofs[el], fe, prob.n_dof).reshape(-1, 3, npar)[rigid.nodes].sum(axis=0)
        return Sensitivities(list(self.names), du, tip_u, tip_f, react)

    def _pseudo_loads(self, states: dict, dt: float | None, viscous: bool, lin: list) -> np.ndarray:
        """``(n_par, n_el, 81)`` element forces ∂rₑ/∂p at fixed displacement [N per unit]
        (``lin``: :meth:`step`'s per-material ``(F, S, A, CC)`` at the state)."""
        prob, g = self.solver.problem, self.solver.problem.geom
        npar = len(self.pars)
        dre = np.zeros((npar, g.edofs.shape[0], g.edofs.shape[1]))
        for k, m in enumerate(prob.materials):
            sl = prob.slices[k]
            F, C, Ce, Se, CCe = states[k]
            need_law_S = any(p.kind in ("field", "shape") for p in self.pars) and prob.fields_of(k)
            law_S = lawkit.response(m.law, Ce, m.params, False)[0] if need_law_S else None
            pr = m.prony() if viscous else None
            h_new = None
            S_nat = Se
            if pr is not None:
                gg, tau = pr
                e, beta, _ = viscoelastic.step_factors(gg, tau, dt)
                st = prob.state[k]
                h_new = _b5(e) * st.h + _b5(beta) * (Se - st.Se)[None]
                S_nat = (1 - gg.sum()) * Se + np.tensordot(gg, h_new, axes=(0, 0))
            js, dSs = [], []
            self._explicit[k] = {}
            for j, p in enumerate(self.pars):
                dSe_p = self._explicit_dSe(k, j, Ce, C, F, CCe, law_S)
                if dSe_p is not None:   # the history update reads it again
                    self._explicit[k][j] = dSe_p
                if p.kind == "prony" and p.k == k and pr is None:
                    dSe_p = None   # no history: the instantaneous response has no Prony terms
                if pr is None:
                    dS = dSe_p
                else:
                    dSe_p0 = np.zeros_like(Se) if dSe_p is None else dSe_p
                    dginf, dg, de, dbeta = self._partials(k, p, dt, len(gg))
                    dh = (_b5(e) * self.dh[k][j] + _b5(beta) * (dSe_p0 - self.dSe[k][j])[None]
                          + _b5(de) * st.h + _b5(dbeta) * (Se - st.Se)[None])
                    dS = (dginf * Se + (1 - gg.sum()) * dSe_p0
                          + np.tensordot(np.asarray(dg), h_new, axes=(0, 0))
                          + np.tensordot(gg, dh, axes=(0, 0)))
                if m.F0 is not None:
                    if dS is not None:
                        dS = push_with(m.F0, dS)[0]
                    if p.kind == "prestretch" and p.k == k:
                        dF = dF0(m.prestress, int(p.local))
                        extra = dF @ S_nat @ m.F0.T + m.F0 @ S_nat @ dF.T
                        dS = extra if dS is None else dS + extra
                if dS is not None:
                    js.append(j)
                    dSs.append(dS)
            if js:
                dre[js, sl] = self._residuals(k, F, np.stack(dSs))
            if self._shape:   # the rest of the shape derivative: moved gradients and volume
                jg = list(self._shape)
                Q = np.stack([shape_mod.geometric_piola(F, lin[k][1], self._shape[j][k].G) for j in jg])
                with single_threaded_blas():
                    dre[jg, sl] += shape_mod.element_forces(g, sl, Q)
        return dre

    def _residuals(self, k: int, F: np.ndarray, dS: np.ndarray) -> np.ndarray:
        """``(n, n_el_k, 81)`` element forces of ``n`` stress fields ``dS`` ``(n, n_el_k, n_q, 3, 3)``
        of material ``k`` at deformation ``F``, in one product."""
        g, sl = self.solver.problem.geom, self.solver.problem.slices[k]
        n, ne, nq = dS.shape[:3]
        Pw = np.matmul(F[None], dS) * g.w[sl][None, :, :, None, None]
        A = Pw.transpose(1, 3, 0, 2, 4).reshape(ne, 3 * n, nq * 3)            # rows (i, n)
        with single_threaded_blas():
            out = np.matmul(A, g.dNT[sl].reshape(ne, nq * 3, -1))           # (e, 3n, 27)
        return out.reshape(ne, 3, n, -1).transpose(2, 0, 1, 3).reshape(n, ne, -1)

    def _apply(self, lin: list, V: np.ndarray, elements: np.ndarray | None = None) -> np.ndarray:
        """Element tangent products ``(n_el, 81, m)`` with the full-dof vectors ``V``
        ``(n_dof, m)`` (only ``elements``, an increasing index array, when given)."""
        g = self.solver.problem.geom
        sel = np.arange(g.edofs.shape[0]) if elements is None else elements
        return self._apply_e(lin, V[g.edofs[sel]], sel)

    def _apply_e(self, lin: list, ue: np.ndarray, sel: np.ndarray | None = None) -> np.ndarray:
        """Element tangent products with element vectors ``ue`` ``(n_sel, 81, m)`` of the
        elements ``sel`` (increasing; None: all)."""
        prob, g = self.solver.problem, self.solver.problem.geom
        out = np.empty(ue.shape)
        for k, (_, _, A, _) in enumerate(lin):
            sl = prob.slices[k]
            if sel is None:
                out[sl] = element_tangent_apply(g.dNT[sl], A, ue[sl])
                continue
            pos = np.flatnonzero((sel >= sl.start) & (sel < sl.stop))
            if pos.size:
                out[pos] = element_tangent_apply(g.dNT[sel[pos]], A[sel[pos] - sl.start], ue[pos])
        return out

    def _reduce(self, fe: np.ndarray) -> np.ndarray:
        """Element vectors ``(n_el, 81, m)`` summed onto the reduced unknowns ``(n_unknowns, m)``."""
        return self._gather @ fe.reshape(-1, fe.shape[-1])

    def _matvec(self, lin: list, q: np.ndarray) -> np.ndarray:
        """The reduced tangent at the converged state times ``q`` ``(n_unknowns, m)``."""
        g = self.solver.problem.geom
        ue = (self._expand @ q).reshape(*g.edofs.shape, q.shape[1])
        out = self._reduce(self._apply_e(lin, ue))
        if self._springs is not None:
            out += self._springs @ q
        return out

    def _solve(self, rhs: np.ndarray, lin: list, states: dict) -> np.ndarray:
        """``K⁻¹ rhs`` with the tangent ``K`` at the converged state.

        ``method="iterative"`` (with a factorisation held, the Newton loop's last): conjugate
        gradients on ``K`` preconditioned by that factorisation, with matrix-free products, to a
        relative error estimate ``tol`` per column — no tangent assembled or factorised, and
        the factorisation stays the Newton loop's for the next increment. It falls back to
        the direct solve when ``K`` is not positive definite or ``max_iter`` is reached.
        ``method="direct"``: assemble and factorise ``K`` (kept for the next increment).
        """
        solver = self.solver
        if self.method == "iterative" and solver.factored:
            x, its = _pcg(lambda q: self._matvec(lin, q), solver.linear.solve, rhs, self.tol, self.max_iter)
            self.stats["iterations"] += its
            if x is not None:
                self.stats["iterative"] += 1
                return x
        prob, g = solver.problem, solver.problem.geom
        Ke = np.empty((g.edofs.shape[0], g.edofs.shape[1], g.edofs.shape[1]))
        for k, (F, S, _, CC) in enumerate(lin):
            sl = prob.slices[k]
            element_tangent(g.dN[sl], g.w[sl], F, S, CC, g.dNT[sl], out=Ke[sl])
        solver.linear.factor(solver.tangent(Ke))
        solver.factored = True
        self.stats["factorisations"] += 1
        return solver.linear.solve(rhs).reshape(rhs.shape)

    def _drive(self, rhs: np.ndarray, t: float, lin: list) -> np.ndarray:
        """Add the drive parameters' part to ``rhs`` ``(n_unknowns, n_par)`` (in place) and
        return the prescribed displacements' derivatives ``(n_dof, n_par)`` [m per unit]."""
        solver, prob = self.solver, self.solver.problem
        dm = solver.dofmap
        dup = np.zeros((prob.n_dof, len(self.pars)))
        moved = []
        for j, p in enumerate(self.pars):
            if p.kind != "drive":
                continue
            dv = np.asarray(dm.bc.rigid.derivative(p.name, t), dtype=float)[dm.rigid_components]
            if dm.force_mode:
                rhs[dm.n_free:, j] -= dv   # r = f_int - f_ext: ∂r/∂p = -∂f_ext/∂p
            else:
                dup[dm.rigid_dofs, j] = dv[None, :]
                moved.append(j)
        if moved:   # the imposed motion's forces on the unknowns: K_fp ∂u_p/∂p
            rhs[:, moved] += self._reduce(self._apply(lin, dup[:, moved]))
        return dup

    def _support(self, rhs: np.ndarray, u: np.ndarray, lin: list, dup: np.ndarray) -> None:
        """Add the support compliance's part to ``rhs`` and, at c = 0, its rim's motion to ``dup``
        (both in place; see the module docstring)."""
        j = next((i for i, p in enumerate(self.pars) if p.kind == "compliance"), None)
        if j is None:
            return
        dm = self.solver.dofmap
        sup = dm.bc.compliance
        if sup.value > 0:
            free = dm.map[sup.dofs] >= 0
            np.add.at(rhs[:, j], dm.map[sup.dofs[free]], -(sup.area[free] / sup.value**2) * u[sup.dofs[free]])
            return
        prob, g = self.solver.problem, self.solver.problem.geom
        f = np.zeros(prob.n_dof)
        for k, (F, S, _, _) in enumerate(lin):
            f += full_vector(g.edofs[prob.slices[k]], self._residuals(k, F, S[None])[0], prob.n_dof)
        dup[sup.dofs, j] = -f[sup.dofs] / sup.area
        rhs[:, [j]] += self._reduce(self._apply(lin, dup[:, [j]]))

    def _springs_moved(self, rhs: np.ndarray, u: np.ndarray) -> None:
        """Add the distributed support's part of the geometry parameters to ``rhs`` (in place):
        ∂(k u)/∂p = (∂k/∂p) u on the springs' dofs."""
        dm = self.solver.dofmap
        for j, dk in self._shape_springs.items():
            if dk is not None and dm.spring_dofs.size:
                np.add.at(rhs[:, j], dm.map[dm.spring_dofs], dk * u[dm.spring_dofs])

    def _update_history(self, u: np.ndarray, du: np.ndarray, dt: float, cache: dict) -> None:
        """Carry the total dSₑ/dp and dh/dp of this step to the next (every parameter at once)."""
        prob, g = self.solver.problem, self.solver.problem.geom
        npar = len(self.pars)
        for k, m in enumerate(prob.materials):
            pr = m.prony()
            if pr is None:
                continue
            sl = prob.slices[k]
            F, C, Ce, Se, CCe = cache[k]
            ne, nq = CCe.shape[:2]
            gg, tau = pr
            e, beta, _ = viscoelastic.step_factors(gg, tau, dt)
            st = prob.state[k]
            # dC = δFᵀF + FᵀδF of every parameter's δu, the parameters riding inside each 3 x 3p
            # block so that each product is one matmul per quadrature point
            ue = du[g.edofs[sl]].reshape(ne, 3, g.dN.shape[2], npar)
            with single_threaded_blas():
                dF = np.einsum("eiaj,eqJa->eqijJ", ue, g.dNT[sl], optimize=True)
                G = np.matmul(np.swapaxes(F, -1, -2), dF.reshape(ne, nq, 3, 3 * npar))
            G = G.reshape(ne, nq, 3, npar, 3)                                              # FᵀδF (I, p, J)
            dC = G.transpose(0, 1, 2, 4, 3) + G.transpose(0, 1, 4, 2, 3)                 # (e, q, I, J, p)
            if m.F0 is not None:
                dCp = np.moveaxis(dC, -1, 0)
                dC = np.moveaxis(np.swapaxes(m.F0, -1, -2) @ dCp @ m.F0, 0, -1)
            # every parameter's ½ CCe : dC at once, as one batched (9 x 9) @ (9 x npar) product
            with single_threaded_blas():
                dSe = 0.5 * (CCe.reshape(ne, nq, 9, 9) @ np.ascontiguousarray(dC).reshape(ne, nq, 9, npar))
            dSe = np.moveaxis(dSe.reshape(ne, nq, 3, 3, npar), -1, 0)                   # (p, e, q, 3, 3)
            for j, ex in self._explicit.get(k, {}).items():
                if self.pars[j].kind != "prony":
                    dSe[j] += ex
            parts = [self._partials(k, p, dt, len(gg)) for p in self.pars]
            de = np.array([q[2] for q in parts])[:, :, None, None, None, None]         # (p, n, 1, 1, 1, 1)
            dbeta = np.array([q[3] for q in parts])[:, :, None, None, None, None]
            self.dh[k] = (_b5(e)[None] * self.dh[k] + _b5(beta)[None] * (dSe - self.dSe[k])[:, None]
                          + de * st.h[None] + dbeta * (Se - st.Se)[None, None])
            self.dSe[k] = dSe


def _full(edofs: np.ndarray, fe: np.ndarray, n_dof: int) -> np.ndarray:
    """Element vectors ``(n_el, 81, m)`` summed onto the full dofs ``(n_dof, m)``."""
    return np.stack([full_vector(edofs, fe[..., j], n_dof) for j in range(fe.shape[-1])], axis=1) \
        if fe.shape[-1] else np.zeros((n_dof, 0))


def _pcg(matvec, precondition, b: np.ndarray, tol: float, max_iter: int):
    """Preconditioned conjugate gradients on the columns of ``b`` ``(n, m)`` at once.

    ``matvec(q)`` and ``precondition(r)`` act on ``(n, m)`` blocks. Starts from the
    preconditioned right-hand side; a column is done when its preconditioned residual (the
    estimate of its remaining error) is at most ``tol`` times its solution. Returns
    ``(x, iterations)``, ``x`` None when a curvature ``pᵀKp`` is not positive or ``max_iter``
    iterations do not reach ``tol``.
    """
    x = precondition(b).reshape(b.shape)
    bnorm = np.linalg.norm(b, axis=0)
    r = b - matvec(x)
    z = precondition(r).reshape(b.shape)
    p = z.copy()
    rz = np.einsum("ij,ij->j", r, z)
    for it in range(max_iter + 1):
        done = (np.linalg.norm(z, axis=0) <= tol * np.linalg.norm(x, axis=0)) | (bnorm == 0)
        if done.all():
            return x + z, it   # with the last correction: free, and smaller than the estimate
        if it == max_iter:
            break
        Kp = matvec(p)
        pKp = np.einsum("ij,ij->j", p, Kp)
        if np.any(pKp[~done] <= 0):
            break
        alpha = np.where(done, 0.0, rz / np.where(done, 1.0, pKp))
        x += alpha * p
        r -= alpha * Kp
        z = precondition(r).reshape(b.shape)
        rz_new = np.einsum("ij,ij->j", r, z)
        beta = np.where(done | (rz == 0), 0.0, rz_new / np.where(rz == 0, 1.0, rz))
        p = z + beta * p
        rz = rz_new
    return None, it


def sensitivities(solver: NewtonSolver, u: np.ndarray, t: float, only: list[str] | None = None,
                  shapes: Mapping[str, shape_mod.DesignVelocity] | None = None) -> Sensitivities:
    """Derivatives of the converged static state ``u`` (at load ``t``).

    Viscous laws respond elastically in a static solve, so their Prony parameters get zero
    derivatives; through a time history use :class:`HistorySensitivity`. Costs one tangent
    assembly and factorisation at ``u`` plus one back-substitution per parameter.
    """
    return HistorySensitivity(solver, only, reactions=True, shapes=shapes).step(u, t, None)


__all__ = ["PRESTRESS_NAMES", "HistorySensitivity", "Sensitivities", "dF0", "parameter_list",
           "parameter_names", "sensitivities"]
