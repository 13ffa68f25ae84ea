"""Newton-Raphson with a line search, load stepping with automatic step cutting.

:func:`solve` runs a load programme over times ``t_1 < t_2 < ...`` (load factors in a static
solve, seconds in a viscoelastic history); each increment is solved by Newton's method
with the consistent tangent and a backtracking line search on the residual norm. An
increment that does not converge (too many iterations, a diverging residual, an inverted
element) is halved and retried, down to ``min_step`` of the original increment; then a
:class:`SolverError` says at which load and why.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.fem import linsolve
from skinkit.fem.assembly import SparsePattern, full_vector
from skinkit.fem.bcs import BoundaryConditions, DofMap
from skinkit.fem.errors import InvertedElementError, SolverError
from skinkit.fem.problem import Problem


@dataclass
class SolverOptions:
    """Newton and stepping controls.

    ``rtol``: residual norm relative to the first residual of the increment (or to the
    external load) at convergence; ``atol`` [N]: absolute floor; ``max_iter`` per increment;
    ``max_cuts``: halvings of an increment before giving up; ``linear``: linear solver name.
    """

    rtol: float = 1e-8
    atol: float = 1e-12
    max_iter: int = 20
    max_cuts: int = 8
    line_search: bool = True
    linear: str = "auto"


@dataclass
class Timings:
    """Accumulated wall time [s]: assembly (residual + tangent), linear solve, iterations."""

    assembly: float = 0.0
    solve: float = 0.0
    iterations: int = 0
    tangent_assemblies: int = 0


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
        linsolve.resolve(self.options.linear)
        self.pattern = SparsePattern(problem.geom.edofs, self.dofmap.map, self.dofmap.n_unknowns)
        self.timings = Timings()
        self.last_factor = None

    def _residual(self, u: np.ndarray, t: float, dt: float | None, with_tangent: bool):
        t0 = time.perf_counter()
        re, Ke = self.problem.evaluate(u, with_tangent, dt)
        r = self.pattern.vector(re) - self.dofmap.external(t)
        K = self.pattern.matrix(Ke) if with_tangent else None
        self.timings.assembly += time.perf_counter() - t0
        if with_tangent:
            self.timings.tangent_assemblies += 1
        return r, K, re

    def increment(self, u: np.ndarray, t: float, dt: float | None, u_guess: np.ndarray | None = None):
        """Solve one increment to time ``t`` from ``u``. Returns ``(u, iterations, |r|)``.

        Raises :class:`SolverError` (not converged) or :class:`InvertedElementError`.
        """
        o = self.options
        u = (u if u_guess is None else u_guess).copy()
        self.dofmap.apply_prescribed(u, t)
        f_scale = float(np.linalg.norm(self.dofmap.external(t)))
        r, K, _ = self._residual(u, t, dt, True)
        ref = max(float(np.linalg.norm(r)), f_scale)
        norm = float(np.linalg.norm(r))
        for it in range(1, o.max_iter + 1):
            if not np.isfinite(norm):
                raise SolverError(f"residual is not finite at t = {t:g}")
            if norm <= max(o.rtol * ref, o.atol):
                return u, it - 1, norm
            t0 = time.perf_counter()
            fac = linsolve.factorize(o.linear, K)
            du = -fac.solve(r)
            self.timings.solve += time.perf_counter() - t0
            self.timings.iterations += 1
            self.last_factor = fac
            u_try, alpha = self._line_search(u, du, r, t, dt)
            if u_try is None:
                raise SolverError(f"line search failed at t = {t:g} (|r| = {norm:.3g} N): "
                                  "every trial step inverted an element or diverged")
            u = u_try
            r, K, _ = self._residual(u, t, dt, True)
            norm = float(np.linalg.norm(r))
        if norm <= max(o.rtol * ref, o.atol):
            return u, o.max_iter, norm
        raise SolverError(f"no convergence in {o.max_iter} iterations at t = {t:g} "
                          f"(|r| = {norm:.3g} N, reference {ref:.3g} N)")

    def _line_search(self, u, du, r, t, dt):
        """Energy line search: find alpha with |du . r(u + alpha du)| <= 0.5 |du . r(u)|.

        Alpha is halved while a trial inverts an element; otherwise secant steps on the
        directional derivative (at most 4). Without ``line_search`` the full step is taken.
        """
        s0 = float(du @ r)
        alpha, lo, s_lo = 1.0, 0.0, s0
        best = None
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
            if not self.options.line_search:
                return u_try, alpha
            s1 = float(du @ r_try)
            if best is None:
                best = (u_try, alpha)
            if abs(s1) <= 0.5 * abs(s0) or s0 >= 0:
                return u_try, alpha
            # secant on s(alpha) between the last two points, kept within [0.1, 1] of alpha
            a_new = lo + (alpha - lo) * s_lo / (s_lo - s1) if s_lo != s1 else alpha
            lo, s_lo = alpha, s1
            if s1 < 0:  # still descending at alpha: the full step was short, keep it
                return u_try, alpha
            alpha = float(np.clip(a_new, 0.1 * alpha, alpha))
            best = (u_try, alpha)
        return best if best is not None else (None, 0.0)

    def step_result(self, u: np.ndarray, t: float, its: int, norm: float, dt: float | None) -> StepResult:
        re, _ = self.problem.evaluate(u, False, dt)
        rf = full_vector(self.problem.geom.edofs, re, self.problem.n_dof)
        return StepResult(t, its, norm, self.dofmap.rigid_displacement(u),
                          self.dofmap.rigid_force(rf), rf)

    def run(self, times: Sequence[float], u0: np.ndarray | None = None, viscous_time: bool = False,
            progress: Callable[[float], None] | None = None) -> Solution:
        """Solve at each of ``times`` (increasing); cut increments that fail.

        ``viscous_time``: ``times`` are seconds and viscous histories advance; otherwise
        they are load factors and viscous laws answer elastically.
        """
        times = [float(x) for x in times]
        if any(b <= a for a, b in zip(times, times[1:])):
            raise SolverError("load programme times must increase")
        u = np.zeros(self.problem.n_dof) if u0 is None else np.asarray(u0, dtype=float).copy()
        t_prev = 0.0 if not times or times[0] > 0 else times[0]
        out_u, out_steps = [], []
        u_prev_inc = np.zeros_like(u)
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
                # extrapolate the last increment as the first guess (keeps elements upright)
                guess = self.dofmap.scatter(u, np.zeros(self.dofmap.n_unknowns))
                scale = (t_new - t_cur) / max(self._last_h, 1e-300) if hasattr(self, "_last_h") else 0.0
                guess = guess + scale * u_prev_inc
                try:
                    try:
                        u_new, its, norm = self.increment(u, t_new, dt, guess)
                    except (SolverError, InvertedElementError):
                        if scale == 0.0:
                            raise
                        u_new, its, norm = self.increment(u, t_new, dt, None)
                except (SolverError, InvertedElementError) as exc:
                    self.problem.restore_state(saved)
                    cuts += 1
                    if cuts > self.options.max_cuts:
                        raise SolverError(f"gave up at load t = {t_new:g} (from {t_cur:g}) after "
                                          f"{self.options.max_cuts} step cuts: {exc}") from exc
                    h *= 0.5
                    continue
                if viscous_time:
                    self.problem.commit(u_new, t_new - t_cur)
                u_prev_inc = u_new - u
                self._last_h = t_new - t_cur
                u = u_new
                t_cur = t_new
            out_u.append(u.copy())
            out_steps.append(self.step_result(u, t_target, its, norm, None if not viscous_time else 0.0))
            if progress is not None:
                progress(t_target)
            t_prev = t_target
        return Solution(np.array(times), np.array(out_u), out_steps, self.timings, self.dofmap,
                        self.last_factor)


def solve(problem: Problem, bc: BoundaryConditions, times: Sequence[float] = (1.0,),
          options: SolverOptions | None = None, viscous_time: bool = False) -> Solution:
    """Convenience wrapper: build a :class:`NewtonSolver` and run ``times``."""
    return NewtonSolver(problem, bc, options).run(times, viscous_time=viscous_time)
