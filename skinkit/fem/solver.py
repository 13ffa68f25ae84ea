"""Newton-Raphson with a line search, load stepping with automatic step cutting.

:func:`solve` runs a load programme over times ``t_1 < t_2 < ...`` (load factors in a static
solve, seconds in a viscoelastic history); each increment is solved by Newton's method
with the consistent tangent and a backtracking line search on the residual norm. An
increment that does not converge (too many iterations, a diverging residual, an inverted
element) is halved and retried, down to ``min_step`` of the original increment; then a
:class:`SolverError` says at which load and why.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.fem import linsolve, threads
from skinkit.fem.assembly import SparsePattern, full_vector
from skinkit.fem.bcs import BoundaryConditions, DofMap
from skinkit.fem.errors import InvertedElementError, SolverError
from skinkit.fem.problem import Problem


def sp_triu(A):
    """The upper triangle of a sparse matrix (the half PARDISO's symmetric mode reads)."""
    import scipy.sparse as sp
    return sp.triu(A, format="csr")


#: a Newton iteration from an extrapolated start must cut the residual at least this much, or
#: the increment starts again from the tangent predictor (quadratic convergence cuts it by
#: orders of magnitude; a damped crawl by a few tens of per cent)
GUESS_PROGRESS = 0.5
#: a residual that stops falling (two Newton iterations without halving it, or none halving it
#: in :data:`STAGNANT_ITERS`) below this fraction of the reference force has reached the
#: round-off floor: a large body carrying large internal stresses (pre-stress, a nearly
#: incompressible layer) against small net reactions cannot balance them to ``rtol`` of those.
#: The floor grows with the mesh: a virtual forearm's truth on 37,479 unknowns (finely graded at
#: the indenter's edge) wanders between 4e-7 and 5e-6 of its reference force without halving,
#: which is four orders below the force sensor's noise
STALL_RTOL = 1e-5
#: Newton gives the increment up when the residual is not below half of what it was this many
#: iterations before: past a limit point or a bifurcation (an indefinite tangent, a wrinkling
#: layer) the line search only wanders at one residual level, and the remaining iterations of
#: ``max_iter`` cost as much as the cut increment that follows them would. A damped crawl that
#: halves the residual within the window goes on
STAGNANT_ITERS = 6
#: below this residual, relative to the increment's reference force, Newton finishes on the
#: tangent it last factorised (frozen-tangent steps: a back-substitution and a residual each,
#: no tangent assembled or factorised). There the iterate is so close to the solution that the
#: factorised tangent differs from the current one by about as little: a frozen step contracts
#: the residual by orders of magnitude, where a new factorisation would cost ~80 % of a Newton
#: iteration on the 10^3-element block (``skinkit bench fem``). Above it (early iterations,
#: large strains) the tangent still changes too much for frozen steps to pay.
FROZEN_RTOL = 1e-4
#: a frozen-tangent step must cut the residual at least this much, or Newton takes a fresh
#: tangent from the iterate before it: one such step (back-substitution + residual, a fifth to
#: a tenth of a factorised iteration) that quarters the residual does more per second than a
#: factorisation; the same test as the extrapolated start's corrections. A factorised step
#: must have cut it as much for its tangent to be used frozen
FROZEN_GAIN = 4.0


@dataclass
class SolverOptions:
    """Newton and stepping controls.

    ``rtol``: residual norm relative to the reference force of the increment (its initial
    unbalance, the external load or the reactions carried, whichever is largest) at
    convergence; ``atol`` [N]: absolute floor; ``max_iter`` per increment; ``max_cuts``:
    successive halvings of an increment before giving up; ``linear``: linear solver name.
    """

    rtol: float = 1e-8
    atol: float = 1e-12
    max_iter: int = 20
    max_cuts: int = 8
    line_search: bool = True
    linear: str = "auto"


@dataclass
class Timings:
    """Accumulated wall time [s]: assembly (residual + tangent), linear solve; counts.

    ``iterations`` counts every Newton step (the tangent predictor's, factorised ones and
    frozen-tangent ones), ``factorisations`` those that factorised a new tangent and
    ``back_substitutions`` the frozen-tangent ones (:data:`FROZEN_RTOL`); the extrapolated
    start's corrections are ``predictor_solves``, not iterations.
    """

    assembly: float = 0.0
    solve: float = 0.0
    iterations: int = 0
    tangent_assemblies: int = 0
    tangent: float = 0.0  # the part of ``assembly`` spent on tangent assemblies
    predictor_solves: int = 0  # back-substitutions with an earlier factorisation (no new tangent)
    factorisations: int = 0  # tangents factorised by the Newton loop (predictor and iterations)
    back_substitutions: int = 0  # Newton steps on a frozen (earlier factorised) tangent


@dataclass
class StepResult:
    """One converged increment."""

    t: float
    iterations: int
    residual: float
    tip_displacement: np.ndarray | None
    tip_force: np.ndarray | None
    reaction: np.ndarray


@dataclass
class Solution:
    """A converged history: ``u`` ``(n_steps, n_dof)`` [m] at ``times``, plus per-step data."""

    times: np.ndarray
    u: np.ndarray
    steps: list[StepResult]
    timings: Timings
    dofmap: DofMap
    factor: Any = None
    extra: dict[str, Any] = field(default_factory=dict)


class NewtonSolver:
    """Solves a :class:`Problem` under :class:`BoundaryConditions`; keeps the pattern."""

    def __init__(self, problem: Problem, bc: BoundaryConditions,
                 options: SolverOptions | None = None) -> None:
        self.problem = problem
        self.dofmap = bc.compile()
        self.options = options or SolverOptions()
        self.linear = linsolve.make(self.options.linear)
        self.pattern = SparsePattern(problem.geom.edofs, self.dofmap.map, self.dofmap.n_unknowns,
                                     upper=self.linear.upper)
        self._springs = self.dofmap.spring_matrix()
        self.timings = Timings()
        self.steps_taken = 0
        #: a factorisation of a recent tangent is held by the linear solver
        self.factored = False
        # after the linear solver has loaded its libraries, so the controller sees them all
        threads.warm()

    def tangent(self, Ke: np.ndarray):
        """The reduced tangent from element tangents ``Ke``, with any elastic supports."""
        K = self.pattern.matrix(Ke)
        if self._springs is not None:
            K = (K + (sp_triu(self._springs) if self.linear.upper else self._springs)).tocsr()
        return K

    def _residual(self, u: np.ndarray, t: float, dt: float | None, with_tangent: bool):
        t0 = time.perf_counter()
        re, Ke = self.problem.evaluate(u, with_tangent, dt)
        self._last_re = re
        r = self.pattern.vector(re) - self.dofmap.external(t) + self.dofmap.spring_forces(u)
        K = self.tangent(Ke) if with_tangent else None
        dt_ = time.perf_counter() - t0
        self.timings.assembly += dt_
        if with_tangent:
            self.timings.tangent_assemblies += 1
            self.timings.tangent += dt_
        return r, K, re

    def increment(self, u: np.ndarray, t: float, dt: float | None, guess: np.ndarray | None = None):
        """Solve one increment to time ``t`` from the converged ``u``.

        Returns ``(u, iterations, |r|)``; raises :class:`SolverError` (not converged) or
        :class:`InvertedElementError`. The residual is checked before a tangent is built, so
        a converged iterate costs no tangent. ``guess``: a first iterate extrapolated from the
        previous increments (its prescribed values are overwritten); without it, the tangent
        predictor spreads the prescribed increment through the body. Below
        :data:`FROZEN_RTOL` of the reference force, Newton steps on the tangent last factorised
        in this increment while each step cuts the residual :data:`FROZEN_GAIN`-fold (counted
        in ``timings.back_substitutions``); the convergence test is the same for every step.
        """
        o = self.options
        self.problem.t = t
        u_old = u
        if guess is not None:
            try:
                u, r, ref = self._extrapolated(u, guess, t, dt)
            except InvertedElementError:
                # the extrapolation overshot a small element (at an indenter's edge): the
                # tangent predictor starts from the converged state instead of cutting the step
                guess = None
        if guess is None:
            u, r, ref = self._predict(u, t, dt)
        norm = float(np.linalg.norm(r))
        tol = max(o.rtol * ref, o.atol)
        last, stalled, ascents = math.inf, 0, 0
        trail: list[float] = []     # the residual after each iteration, for STAGNANT_ITERS
        # frozen-tangent steps only on a tangent factorised in this increment: an extrapolated
        # start has already corrected with the previous increment's until that stopped paying
        frozen = guess is None
        for it in range(o.max_iter + 1):
            if not np.isfinite(norm):
                raise SolverError(f"residual is not finite at t = {t:g} (a layer's stress overflowed or "
                                  "divided by zero: check its law parameters)")
            if norm <= tol or (stalled >= 2 and norm <= STALL_RTOL * ref):
                return u, it, norm
            if it == o.max_iter:
                break
            trail.append(norm)
            if len(trail) > STAGNANT_ITERS and norm > 0.5 * trail[-1 - STAGNANT_ITERS]:
                if norm <= STALL_RTOL * ref:
                    return u, it, norm   # wandering at the round-off floor: converged there
                raise SolverError(f"no progress at t = {t:g}: the residual did not halve in "
                                  f"{STAGNANT_ITERS} Newton iterations (|r| = {norm:.3g} N, reference "
                                  f"{ref:.3g} N, {it} iterations){self._where(r)}{_why(ascents, it)}")
            if guess is not None and norm > GUESS_PROGRESS * last:
                # an extrapolated start outside Newton's basin (it overshot where the drive
                # turns): Newton crawls there under its line search for a dozen iterations or
                # fails; the tangent predictor starts close to the solution
                guess = None
                u, r, ref = self._predict(u_old, t, dt)
                norm, last = float(np.linalg.norm(r)), math.inf
                tol = max(o.rtol * ref, o.atol)
                frozen = True
                trail = [norm]
                if norm <= tol:
                    return u, it, norm
            last = norm
            if frozen and norm <= FROZEN_RTOL * ref:
                step = self._frozen_step(u, r, norm, t, dt)
                if step is not None:
                    u, r, norm = step
                    stalled = 0   # it cut the residual at least FROZEN_GAIN-fold
                    continue
                # not paying: a fresh tangent at the same iterate
            r, K, _ = self._residual(u, t, dt, True)
            t0 = time.perf_counter()
            self.linear.factor(K)
            self.factored = True
            du = -self.linear.solve(r)
            self.timings.solve += time.perf_counter() - t0
            self.timings.iterations += 1
            self.timings.factorisations += 1
            ascents += float(du @ r) >= 0
            r_before = r
            u, r = self._line_search(u, du, r, t, dt)
            if u is None:
                raise SolverError(f"line search failed at t = {t:g} (|r| = {norm:.3g} N): "
                                  "every trial step inverted an element or diverged"
                                  f"{self._where(r_before)}")
            norm = float(np.linalg.norm(r))
            stalled = stalled + 1 if norm > 0.5 * last else 0
            # the new tangent may finish the increment only if its own step paid as a frozen
            # one must: one that did not (at the round-off floor, under a damped line search)
            # predicts too poorly for a frozen step to pay
            frozen = FROZEN_GAIN * norm <= last
        raise SolverError(f"no convergence in {o.max_iter} iterations at t = {t:g} "
                          f"(|r| = {norm:.3g} N, reference {ref:.3g} N){self._where(r)}"
                          f"{_why(ascents, o.max_iter)}")

    def _where(self, r: np.ndarray) -> str:
        """Where an increment failed: the node carrying the largest unbalance of the residual
        ``r`` (reduced unknowns) [N], its reference position [mm] and the regions of the elements
        around it; ``""`` when it cannot be said."""
        try:
            full = np.zeros(self.problem.n_dof)
            idx = np.flatnonzero(self.dofmap.map >= 0)
            full[idx] = r[self.dofmap.map[idx]]
            node = int(np.argmax(np.linalg.norm(full.reshape(-1, 3), axis=1)))
            mesh = self.problem.mesh
            x, y, z = mesh.nodes[node] * 1e3
            around = np.unique(mesh.region[np.any(mesh.elements == node, axis=1)])
            names = ", ".join(mesh.regions[i] for i in around)
            return (f"; largest unbalance {np.linalg.norm(full[3 * node:3 * node + 3]):.3g} N at "
                    f"({x:.3g}, {y:.3g}, {z:.3g}) mm ({names})")
        except Exception:   # the message must not fail where the solve did
            return ""

    def _frozen_step(self, u: np.ndarray, r: np.ndarray, norm: float, t: float, dt: float | None):
        """A Newton step on the tangent last factorised (modified Newton), no line search.

        Returns the new iterate, its residual and norm [N] when the step cuts the residual
        ``norm`` at least :data:`FROZEN_GAIN`-fold, else None (the caller factorises the tangent
        at ``u``; ``u`` and ``r`` are unchanged). Every back-substitution tried is counted in
        ``timings.back_substitutions``, an accepted step also in ``timings.iterations``.
        """
        t0 = time.perf_counter()
        du = -self.linear.solve(r)
        self.timings.solve += time.perf_counter() - t0
        self.timings.back_substitutions += 1
        try:
            cand = self.dofmap.scatter(u, du)
            r2, _, _ = self._residual(cand, t, dt, False)
        except InvertedElementError:
            return None
        n2 = float(np.linalg.norm(r2))
        if not (np.isfinite(n2) and FROZEN_GAIN * n2 <= norm):
            return None
        self.timings.iterations += 1
        return cand, r2, n2

    def _extrapolated(self, u_old: np.ndarray, guess: np.ndarray, t: float, dt: float | None):
        """The predicted first iterate, its residual and the increment's reference force.

        The extrapolated state is corrected once with the tangent already factorised (the
        last one of the previous increment, or the converged one of a sensitivity pass): a
        back-substitution and a residual, no new tangent. The correction is kept only when it
        lowers the residual. Counted in ``timings.predictor_solves``, not as an iteration.
        """
        u = guess.copy()
        self.dofmap.apply_prescribed(u, t)
        r, _, re = self._residual(u, t, dt, False)
        reactions = float(np.linalg.norm(full_vector(self.problem.geom.edofs, re, self.problem.n_dof)))
        # the reference: the load, the reactions carried, or the unbalance of the old state
        ref = max(float(np.linalg.norm(self.dofmap.external(t))), reactions, float(np.linalg.norm(r)) * 1e-3)
        # modified-Newton corrections with the factorised tangent while they pay (each must
        # cut the residual at least four-fold): a residual and a back-substitution each
        norm = float(np.linalg.norm(r))
        current = True   # the last residual evaluated is that of ``u``
        for _ in range(4 if self.factored else 0):
            t0 = time.perf_counter()
            du = -self.linear.solve(r)
            self.timings.solve += time.perf_counter() - t0
            self.timings.predictor_solves += 1
            try:
                cand = self.dofmap.scatter(u, du)
                current = False
                r2, _, _ = self._residual(cand, t, dt, False)
            except InvertedElementError:
                break
            n2 = float(np.linalg.norm(r2))
            if not (np.isfinite(n2) and n2 < norm):
                break
            u, r, gain, current = cand, r2, norm / max(n2, 1e-300), True
            norm = n2
            if gain < FROZEN_GAIN or norm <= max(self.options.rtol * ref, self.options.atol):
                break
        if not current:
            self._residual(u, t, dt, False)   # step results read the last residual evaluated
        return u, r, ref

    def _predict(self, u_old: np.ndarray, t: float, dt: float | None):
        """Tangent predictor: spread the prescribed increment through the body linearly.

        ``K_ff dq = -(r(u_old) + K_fp du_p)`` with the tangent at the converged state, so the
        first Newton iterate is not a mesh whose boundary layer alone has moved. Returns the
        first iterate, its residual, and the reference residual norm of the increment.
        """
        u_new = u_old.copy()
        self.dofmap.apply_prescribed(u_new, t)
        dup = u_new - u_old
        t0 = time.perf_counter()
        re, Ke = self.problem.evaluate(u_old, True, dt)
        re = re + np.einsum("eij,ej->ei", Ke, dup[self.problem.geom.edofs])
        rhs = self.pattern.vector(re) - self.dofmap.external(t) + self.dofmap.spring_forces(u_new)
        K = self.tangent(Ke)
        self.timings.assembly += time.perf_counter() - t0
        self.timings.tangent += time.perf_counter() - t0
        self.timings.tangent_assemblies += 1
        # reference force: the increment's unbalance, the load, or the reactions already
        # carried (a hold step of a relaxing body has a tiny unbalance but real forces)
        reactions = float(np.linalg.norm(full_vector(self.problem.geom.edofs, re - np.einsum(
            "eij,ej->ei", Ke, dup[self.problem.geom.edofs]), self.problem.n_dof)))
        ref = max(float(np.linalg.norm(rhs)), float(np.linalg.norm(self.dofmap.external(t))), reactions)
        t0 = time.perf_counter()
        self.linear.factor(K)
        self.factored = True
        dq = -self.linear.solve(rhs)
        self.timings.solve += time.perf_counter() - t0
        self.timings.iterations += 1
        self.timings.factorisations += 1
        for alpha in (1.0, 0.5, 0.25, 0.125, 0.0):
            cand = self.dofmap.scatter(u_new, dq, alpha)
            try:
                r, _, _ = self._residual(cand, t, dt, False)
            except InvertedElementError:
                if alpha == 0.0:
                    raise
                continue
            return cand, r, ref
        raise AssertionError("unreachable")

    def _line_search(self, u, du, r, t, dt):
        """Energy line search on ``s(α) = du · r(u + α du)``; returns ``(u_new, r_new)``.

        The full step is taken when ``|s(1)| <= 0.5 |s(0)|`` or when the energy still
        decreases at α = 1; otherwise secant steps on s (at most 4). α is halved while a
        trial inverts an element. Without ``line_search`` only the inversion guard acts.
        """
        s0 = float(du @ r)
        alpha, lo, s_lo = 1.0, 0.0, s0
        best = (None, None)
        for _ in range(12):
            try:
                u_try = self.dofmap.scatter(u, du, alpha)
                r_try, _, _ = self._residual(u_try, t, dt, False)
            except InvertedElementError:
                alpha *= 0.5
                continue
            if not np.all(np.isfinite(r_try)):
                alpha *= 0.5
                continue
            s1 = float(du @ r_try)
            if not self.options.line_search or abs(s1) <= 0.5 * abs(s0) or s0 >= 0 or s1 < 0:
                return u_try, r_try
            best = (u_try, r_try)
            a_new = lo + (alpha - lo) * s_lo / (s_lo - s1) if s_lo != s1 else alpha
            lo, s_lo = alpha, s1
            alpha = float(np.clip(a_new, 0.1 * alpha, alpha))
        return best

    def step_result(self, u: np.ndarray, t: float, its: int, norm: float,
                    dt: float | None) -> StepResult:
        """The converged step at load time ``t`` [s]: Newton iterations, residual norm [N], the
        rigid indenter's displacement [m] and force [N], the full residual ``(n_dof,)``."""
        if dt is None or not self.problem.viscous:
            re = self._last_re  # the residual of the converged iterate
        else:
            re = self.problem.evaluate(u, False, dt)[0]
        rf = full_vector(self.problem.geom.edofs, re, self.problem.n_dof)
        return StepResult(t, its, norm, self.dofmap.rigid_displacement(u),
                          self.dofmap.rigid_force(rf), rf)

    def run(self, times: Sequence[float], u0: np.ndarray | None = None, viscous_time: bool = False,
            progress: Callable[[float], None] | None = None, sensitivities: bool | Sequence[str] = False,
            extrapolate: bool = True, sensitivity_method: str = "iterative",
            on_step: Callable[[float, np.ndarray], None] | None = None,
            shapes: Mapping[str, Any] | None = None) -> Solution:
        """Solve at each of ``times`` (increasing); cut increments that fail.

        ``viscous_time``: ``times`` are seconds and viscous histories advance; otherwise
        they are load factors and viscous laws answer elastically. ``sensitivities``: also
        differentiate every output step with respect to every parameter (True) or to the
        named ones (direct differentiation, through the viscous history when there is one);
        the results are in ``solution.extra["sensitivities"]``, one per output time, and how
        their linear systems were solved in ``solution.extra["sensitivity_solves"]``.
        ``sensitivity_method``: ``"iterative"`` (default; no tangent assembled at the converged
        states) or ``"direct"`` — both exact, see :class:`~skinkit.fem.sensitivity.HistorySensitivity`.
        ``extrapolate``: start each increment from a quadratic extrapolation of the last
        converged states (falls back to the tangent predictor after a failure).
        ``on_step(t, u)``: called at each output time with its converged displacement
        ``(n_dof,)`` [m], while the problem's viscous history is the one at ``u`` (what the
        field output, :mod:`skinkit.fem.vtu`, reads the total stress from).
        ``shapes``: geometry parameters to differentiate too, name ->
        :class:`skinkit.fem.shape.DesignVelocity` (named in ``sensitivities`` when that is a list).

        Floating-point warnings (overflow, division by zero, invalid values in a law's stress)
        are silenced here: the solver checks every residual and increment itself, cuts the
        step on a non-finite one and, failing, raises one :class:`SolverError` saying where.
        """
        with np.errstate(all="ignore"):
            return self._run(times, u0, viscous_time, progress, sensitivities, extrapolate,
                             sensitivity_method, on_step, shapes)

    def _run(self, times: Sequence[float], u0: np.ndarray | None, viscous_time: bool,
             progress: Callable[[float], None] | None, sensitivities: bool | Sequence[str],
             extrapolate: bool, sensitivity_method: str = "iterative",
             on_step: Callable[[float, np.ndarray], None] | None = None,
             shapes: Mapping[str, Any] | None = None) -> Solution:
        from skinkit.fem import sensitivity as sens_mod
        only = None if isinstance(sensitivities, bool) else list(sensitivities)
        want_sens = bool(sensitivities) if isinstance(sensitivities, bool) else True
        tracker = sens_mod.HistorySensitivity(self, only, sensitivity_method, shapes=shapes) \
            if want_sens else None
        sens_out = []
        times = [float(x) for x in times]
        if any(b <= a for a, b in zip(times, times[1:], strict=False)):
            raise SolverError("load programme times must increase")
        u = np.zeros(self.problem.n_dof) if u0 is None else np.asarray(u0, dtype=float).copy()
        t_prev = 0.0 if not times or times[0] > 0 else times[0]
        out_u, out_steps = [], []
        hist: list[tuple[float, np.ndarray]] = [(t_prev, u.copy())]
        for t_target in times:
            if t_target <= t_prev and out_steps:
                continue
            base = t_target - t_prev
            h = base
            t_cur = t_prev
            cuts = 0
            while t_cur < t_target - 1e-12 * max(1.0, abs(t_target)):
                t_new = min(t_cur + h, t_target)
                dt = (t_new - t_cur) if viscous_time else None
                saved = self.problem.save_state()
                guess = _extrapolate(hist, t_new) if extrapolate and cuts == 0 else None
                try:
                    u_new, its, norm = self.increment(u, t_new, dt, guess)
                except (SolverError, InvertedElementError) as exc:
                    self.problem.restore_state(saved)
                    cuts += 1
                    if cuts > self.options.max_cuts:
                        raise SolverError(f"gave up at load t = {t_new:g} (from {t_cur:g}) after "
                                          f"{self.options.max_cuts} step cuts: {exc}") from exc
                    h *= 0.5
                    continue
                # a success ends the run of cuts; the increment grows back towards its size
                cuts = 0
                h = min(base, 2 * h)
                self.steps_taken += 1
                if tracker is not None and viscous_time:
                    last_sens = tracker.step(u_new, t_new, t_new - t_cur)
                if viscous_time:
                    self.problem.t = t_new
                    self.problem.commit(u_new, t_new - t_cur)
                u = u_new
                t_cur = t_new
                hist = (hist + [(t_cur, u.copy())])[-3:]
            out_u.append(u.copy())
            out_steps.append(self.step_result(u, t_target, its, norm, None if not viscous_time else 0.0))
            if tracker is not None:
                sens_out.append(last_sens if viscous_time else tracker.step(u, t_target, None))
            if on_step is not None:
                on_step(t_target, u)
            if progress is not None:
                progress(t_target)
            t_prev = t_target
        sol = Solution(np.array(times), np.array(out_u), out_steps, self.timings, self.dofmap,
                       self.linear)
        if tracker is not None:
            sol.extra["sensitivities"] = sens_out
            sol.extra["sensitivity_solves"] = dict(tracker.stats)
        return sol


def _why(ascents: int, iterations: int) -> str:
    """Why Newton failed, when its steps say so: steps that did not descend the energy mean
    the tangent was indefinite at those iterates."""
    if ascents * 4 < iterations:
        return ""
    return (f"; in {ascents} of {iterations} iterations the tangent was indefinite (Newton's step "
            "did not descend the energy): the body is near an instability there (buckling or "
            "wrinkling under compression, a very soft layer sheared far beyond its thickness)")


def _extrapolate(hist: list[tuple[float, np.ndarray]], t: float) -> np.ndarray | None:
    """Lagrange extrapolation of the displacement to ``t`` from the last (up to 3) states."""
    if len(hist) < 2:
        return None
    ts = [a for a, _ in hist]
    out = np.zeros_like(hist[-1][1])
    for i, (ti, ui) in enumerate(hist):
        w = 1.0
        for j, tj in enumerate(ts):
            if j != i:
                w *= (t - tj) / (ti - tj)
        out += w * ui
    return out


def solve(problem: Problem, bc: BoundaryConditions, times: Sequence[float] = (1.0,),
          options: SolverOptions | None = None, viscous_time: bool = False) -> Solution:
    """Convenience wrapper: build a :class:`NewtonSolver` and run ``times``."""
    return NewtonSolver(problem, bc, options).run(times, viscous_time=viscous_time)
