"""Parameter sensitivities by direct differentiation with the converged tangent.

At a converged state the reduced residual vanishes, ``r(u(p), p) = 0``, so
``K du/dp = -∂r/∂p`` with ``K`` the tangent at that state: one factorisation (the
converged tangent) and one back-substitution per parameter give every derivative, instead
of one nonlinear solve per parameter as finite differences need. ``∂r/∂p`` is assembled
from ``∂S/∂p`` at fixed deformation (complex step for complex-safe laws, central
differences otherwise; pre-stretch parameters by central differences of the stress).

Outputs differentiated: the full displacement ``du/dp`` (hence embedded points), the
indenter's reference-point motion (force control) and its reaction force (displacement
control), and the reactions on any node set.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from skinkit.fem import lawkit
from skinkit.fem.assembly import element_residual, full_vector
from skinkit.fem.problem import Problem, prestretch
from skinkit.fem.solver import NewtonSolver
from skinkit.fem.tensors import push_with


def _b5(a) -> np.ndarray:
    """Per-term factors ``(n,)`` shaped to broadcast over ``(n, e, q, 3, 3)`` histories."""
    return np.asarray(a)[:, None, None, None, None]


#: Prony parameters of a QLV law (relative moduli and relaxation times)
_PRONY = re.compile(r"^(g|tau)[0-9]+$")

#: pre-stretch parameters of a material with ``prestress = (l1, l2, angle)``
PRESTRESS_NAMES = ("prestretch.l1", "prestretch.l2", "prestretch.angle")


@dataclass
class Sensitivities:
    """Derivatives at one converged state.

    Attributes:
        names: ``"<region>.<parameter>"`` for each parameter, in column order.
        du: ``(n_dof, n_par)`` displacement derivatives [m per parameter unit].
        tip_displacement: ``(3, n_par)`` reference-point motion derivatives (force control).
        tip_force: ``(3, n_par)`` indenter force derivatives [N per parameter unit].
        reaction: ``(n_dof, n_par)`` nodal internal-force derivatives.
    """

    names: list[str]
    du: np.ndarray
    tip_displacement: np.ndarray | None
    tip_force: np.ndarray | None
    reaction: np.ndarray


def parameter_list(problem: Problem) -> list[tuple[int, str]]:
    """``(material index, parameter name)`` of every law and pre-stretch parameter."""
    out = []
    for k, m in enumerate(problem.materials):
        for n in lawkit.parameter_names(m.law):
            out.append((k, n))
        if m.prestress is not None:
            out.extend((k, n) for n in PRESTRESS_NAMES)
    return out


def _dS(problem: Problem, k: int, name: str, F: np.ndarray) -> np.ndarray:
    """∂S/∂p at fixed F for material ``k`` (PK2 w.r.t. the mesh configuration)."""
    m = problem.materials[k]
    C = np.swapaxes(F, -1, -2) @ F
    if name in PRESTRESS_NAMES:
        i = PRESTRESS_NAMES.index(name)
        base = list(m.prestress)
        h = 1e-6 * max(abs(base[i]), 1.0)

        def S_at(v):
            q = list(base)
            q[i] = v
            F0 = prestretch(*q)
            Ce = np.swapaxes(F0, -1, -2) @ C @ F0
            return push_with(F0, lawkit.stress(m.law, Ce, m.params))[0]
        return (S_at(base[i] + h) - S_at(base[i] - h)) / (2 * h)
    Ce = C if m.F0 is None else np.swapaxes(m.F0, -1, -2) @ C @ m.F0
    dS = lawkit.stress_parameter_derivative(m.law, Ce, m.params, name)
    if m.F0 is not None:
        dS = push_with(m.F0, dS)[0]
    return dS


def sensitivities(solver: NewtonSolver, u: np.ndarray, t: float) -> Sensitivities:
    """Derivatives of the converged state ``u`` (at load ``t``) of a static problem.

    Viscous laws respond elastically in a static solve, so their Prony parameters get zero
    derivatives here; through a time history use :class:`HistorySensitivity`. Costs one
    tangent assembly and factorisation at ``u`` plus one back-substitution per parameter
    (all right-hand sides at once).
    """
    prob = solver.problem
    g = prob.geom
    pars = parameter_list(prob)
    re, Ke = prob.evaluate(u, True)
    K = solver.pattern.matrix(Ke)
    solver.linear.factor(K)
    n_el = g.edofs.shape[0]
    dre_all = np.zeros((len(pars), n_el, g.edofs.shape[1]))
    for j, (k, name) in enumerate(pars):
        sl = prob.slices[k]
        F = prob._F(u, k)
        dS = _dS(prob, k, name, F)
        dre_all[j, sl] = element_residual(g.dN[sl], g.w[sl], F, dS)
    rhs = np.stack([solver.pattern.vector(dre_all[j]) for j in range(len(pars))], axis=1)
    dq = -solver.linear.solve(rhs) if rhs.size else np.zeros((solver.dofmap.n_unknowns, 0))
    dq = dq.reshape(solver.dofmap.n_unknowns, -1)
    mp = solver.dofmap.map
    du = np.zeros((prob.n_dof, len(pars)))
    du[mp >= 0] = dq[mp[mp >= 0]]
    # total derivative of the internal forces: explicit part + tangent times du/dp
    react = np.zeros((prob.n_dof, len(pars)))
    for j in range(len(pars)):
        dre = dre_all[j] + np.einsum("eij,ej->ei", Ke, du[g.edofs, j])
        react[:, j] = full_vector(g.edofs, dre, prob.n_dof)
    dm = solver.dofmap
    tip_u = tip_f = None
    if dm.rigid_dofs is not None:
        tip_u = np.full((3, len(pars)), np.nan)
        tip_u[dm.rigid_components] = du[dm.rigid_dofs[0]]
        tip_f = react.reshape(-1, 3, len(pars))[dm.bc.rigid.nodes].sum(axis=0)
    names = [f"{prob.materials[k].region}.{n}" for k, n in pars]
    return Sensitivities(names, du, tip_u, tip_f, react)


class HistorySensitivity:
    """Direct differentiation through a viscoelastic time history.

    Call :meth:`step` after each converged time step and before the problem commits it
    (``NewtonSolver.run(..., sensitivities=True)`` does so). With the Prony recurrence
    hⁿ = e hⁿ⁻¹ + β (Sₑⁿ - Sₑⁿ⁻¹), S = g∞ Sₑ + Σ g h, the derivative of the stress at fixed
    displacement carries the derivatives of the history (dhⁿ⁻¹/dp, dSₑⁿ⁻¹/dp, and those of
    e, β, g for the Prony parameters); the converged algorithmic tangent then gives duⁿ/dp,
    from which the total dSₑⁿ/dp and dhⁿ/dp are updated for the next step. Pre-stretch
    parameters are not differentiated through histories (law parameters are).
    """

    def __init__(self, solver: NewtonSolver) -> None:
        self.solver = solver
        prob = solver.problem
        self.pars = [(k, n) for k, n in parameter_list(prob) if n not in PRESTRESS_NAMES]
        self.names = [f"{prob.materials[k].region}.{n}" for k, n in self.pars]
        nq = prob.geom.w.shape[1]
        npar = len(self.pars)
        self.dSe: dict[int, np.ndarray] = {}
        self.dh: dict[int, np.ndarray] = {}
        for k, st in prob.state.items():
            ne = prob.materials[k].elements.size
            self.dSe[k] = np.zeros((npar, ne, nq, 3, 3))
            self.dh[k] = np.zeros((npar, st.h.shape[0], ne, nq, 3, 3))

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

    def _partials_of(self, k: int, kk: int, name: str, dt: float, gg: np.ndarray):
        """Prony partials when parameter ``(kk, name)`` belongs to material ``k``, else zeros."""
        if kk == k:
            return self._prony_partials(k, name, dt)
        return 0.0, 0 * gg, 0 * gg, 0 * gg

    def step(self, u: np.ndarray, t: float, dt: float) -> Sensitivities:
        """Sensitivities at the converged ``u`` of the step of length ``dt`` [s] ending at ``t``."""
        from skinkit.fem import viscoelastic
        solver, prob, g = self.solver, self.solver.problem, self.solver.problem.geom
        npar = len(self.pars)
        re, Ke = prob.evaluate(u, True, dt)
        K = solver.pattern.matrix(Ke)
        solver.linear.factor(K)
        n_el = g.edofs.shape[0]
        dre = np.zeros((npar, n_el, g.edofs.shape[1]))
        cache = {}
        for k, m in enumerate(prob.materials):
            sl = prob.slices[k]
            F = prob._F(u, k)
            C = np.swapaxes(F, -1, -2) @ F
            Ce = C if m.F0 is None else np.swapaxes(m.F0, -1, -2) @ C @ m.F0
            Se, CCe = lawkit.response(m.law, Ce, m.params, True)
            cache[k] = (F, Se, CCe)
            pr = m.prony()
            for j, (kk, name) in enumerate(self.pars):
                is_prony = pr is not None and _PRONY.match(name) is not None
                if kk == k and not is_prony:
                    dSe_p = lawkit.stress_parameter_derivative(m.law, Ce, m.params, name)
                else:
                    dSe_p = np.zeros_like(Se)
                if pr is None:
                    dS = dSe_p if kk == k else None
                else:
                    gg, tau = pr
                    e, beta, _ = viscoelastic.step_factors(gg, tau, dt)
                    st = prob.state[k]
                    h_new = _b5(e) * st.h + _b5(beta) * (Se - st.Se)[None]
                    dginf, dg, de, dbeta = self._partials_of(k, kk, name, dt, gg)
                    dh = (_b5(e) * self.dh[k][j] + _b5(beta) * (dSe_p - self.dSe[k][j])[None]
                          + _b5(de) * st.h + _b5(dbeta) * (Se - st.Se)[None])
                    dS = (dginf * Se + (1 - gg.sum()) * dSe_p
                          + np.tensordot(np.asarray(dg), h_new, axes=(0, 0))
                          + np.tensordot(gg, dh, axes=(0, 0)))
                if dS is None:
                    continue
                if m.F0 is not None:
                    dS = push_with(m.F0, dS)[0]
                dre[j, sl] = element_residual(g.dN[sl], g.w[sl], F, dS)
        rhs = np.stack([solver.pattern.vector(dre[j]) for j in range(npar)], axis=1)
        dq = -solver.linear.solve(rhs).reshape(solver.dofmap.n_unknowns, -1)
        mp = solver.dofmap.map
        du = np.zeros((prob.n_dof, npar))
        du[mp >= 0] = dq[mp[mp >= 0]]
        react = np.zeros((prob.n_dof, npar))
        for j in range(npar):
            dre_tot = dre[j] + np.einsum("eij,ej->ei", Ke, du[g.edofs, j])
            react[:, j] = full_vector(g.edofs, dre_tot, prob.n_dof)
        # update the history derivatives with the total dSe/dp of this step
        for k, m in enumerate(prob.materials):
            pr = m.prony()
            if pr is None:
                continue
            sl = prob.slices[k]
            F, Se, CCe = cache[k]
            gg, tau = pr
            e, beta, _ = viscoelastic.step_factors(gg, tau, dt)
            st = prob.state[k]
            ue = du[g.edofs[sl]].reshape(-1, 3, g.dN.shape[2], npar)
            dF = np.einsum("eiaj,eqaJ->jeqiJ", ue, g.dN[sl])
            dC = np.swapaxes(dF, -1, -2) @ F + np.swapaxes(F, -1, -2) @ dF
            if m.F0 is not None:
                dC = np.swapaxes(m.F0, -1, -2) @ dC @ m.F0
            for j, (kk, name) in enumerate(self.pars):
                is_prony = _PRONY.match(name) is not None
                dSe_tot = 0.5 * np.einsum("eqIJKL,eqKL->eqIJ", CCe, dC[j])
                if kk == k and not is_prony:
                    Ce = np.swapaxes(F, -1, -2) @ F
                    if m.F0 is not None:
                        Ce = np.swapaxes(m.F0, -1, -2) @ Ce @ m.F0
                    dSe_tot = dSe_tot + lawkit.stress_parameter_derivative(m.law, Ce, m.params, name)
                _, _, de, dbeta = self._partials_of(k, kk, name, dt, gg)
                self.dh[k][j] = (_b5(e) * self.dh[k][j] + _b5(beta) * (dSe_tot - self.dSe[k][j])[None]
                                 + _b5(de) * st.h + _b5(dbeta) * (Se - st.Se)[None])
                self.dSe[k][j] = dSe_tot
        dm = solver.dofmap
        tip_u = tip_f = None
        if dm.rigid_dofs is not None:
            tip_u = np.full((3, npar), np.nan)
            tip_u[dm.rigid_components] = du[dm.rigid_dofs[0]]
            tip_f = react.reshape(-1, 3, npar)[dm.bc.rigid.nodes].sum(axis=0)
        return Sensitivities(list(self.names), du, tip_u, tip_f, react)
