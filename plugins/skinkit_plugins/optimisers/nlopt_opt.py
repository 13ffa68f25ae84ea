"""Bound-constrained minimisation by NLopt: derivative-free and gradient-based algorithms.

Least-squares residuals ``r(x)`` are minimised as φ = ½‖r‖²; gradient-based algorithms get
∇φ = Jᵀr from the analytic Jacobian ``jac(x)`` (one forward pass with sensitivities gives both,
so a gradient costs no extra solve). An evaluation that cannot be computed (a non-finite
residual: the forward model failed there) is reported to NLopt as φ = +inf, which its
algorithms treat as a rejected point, not as a value to fit.

Plugins (``skinkit.optimisers``): ``nlopt-bobyqa`` (LN_BOBYQA, local derivative-free),
``nlopt-crs2`` (GN_CRS2_LM, global derivative-free, as Lavigne et al.; needs finite bounds),
``nlopt-mma`` (LD_MMA), ``nlopt-slsqp`` (LD_SLSQP) and ``nlopt-lbfgs`` (LD_LBFGS), the last
three gradient-based.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import nlopt
import numpy as np

from skinkit.plugin.optimisers import OptimiseResult

_MESSAGES = {nlopt.SUCCESS: "success", nlopt.FTOL_REACHED: "ftol reached", nlopt.XTOL_REACHED: "xtol reached",
             nlopt.MAXEVAL_REACHED: "maxeval reached", nlopt.STOPVAL_REACHED: "stopval reached",
             nlopt.MAXTIME_REACHED: "maxtime reached"}


class NloptOptimiser:
    """An NLopt algorithm behind skinkit's optimiser interface (``skinkit.interfaces.Optimiser``).

    ``fun`` may return a residual vector (φ = ½‖r‖²) or a scalar. ``options``: ``xtol_rel``
    (default 1e-8), ``ftol_rel`` (1e-12), ``maxeval`` (2000), ``population`` (CRS2 only),
    ``seed`` (0: NLopt's random generator, used by the stochastic algorithms, is seeded so that
    the same fit gives the same answer; ``None`` leaves it seeded from the clock).
    """

    name = "nlopt"
    algorithm: int = nlopt.LN_BOBYQA
    needs_gradient = False
    needs_finite_bounds = False

    def minimise(self, fun: Callable[[np.ndarray], Any], x0: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray, jac: Callable[[np.ndarray], np.ndarray] | None = None,
                 options: Mapping[str, Any] | None = None) -> OptimiseResult:
        """Minimise the objective subject to ``lower <= x <= upper``."""
        opts = {"xtol_rel": 1e-8, "ftol_rel": 1e-12, "maxeval": 2000, **(options or {})}
        x0 = np.asarray(x0, float)
        lower, upper = np.asarray(lower, float), np.asarray(upper, float)
        if self.needs_gradient and jac is None:
            raise ValueError(f"{self.name} is gradient-based and needs the Jacobian")
        if self.needs_finite_bounds and not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
            raise ValueError(f"{self.name} searches a box: every free parameter needs finite bounds")
        nfev = 0
        best = {"x": np.clip(x0, lower, upper), "f": np.inf}
        # quasi-Newton methods start from an identity Hessian: with the objective divided by
        # its value at the start their first steps have a sensible size in scaled coordinates
        scale = {"f0": None}

        def objective(x: np.ndarray, grad: np.ndarray) -> float:
            nonlocal nfev
            nfev += 1
            r = np.asarray(fun(x), float)
            if not np.all(np.isfinite(r)):
                if grad.size:
                    grad[:] = 0.0
                return float("inf")
            f = float(0.5 * r @ r) if r.ndim else float(r)
            if scale["f0"] is None:
                scale["f0"] = abs(f) if f != 0 else 1.0
            if grad.size:
                J = np.asarray(jac(x), float)
                grad[:] = (J.T @ r if r.ndim else J.ravel()) / scale["f0"]
            if f < best["f"]:
                best.update(x=np.array(x, float), f=f)
            return f / scale["f0"]

        opt = nlopt.opt(self.algorithm, x0.size)
        opt.set_min_objective(objective)
        opt.set_lower_bounds(lower)
        opt.set_upper_bounds(upper)
        opt.set_xtol_rel(float(opts["xtol_rel"]))
        opt.set_ftol_rel(float(opts["ftol_rel"]))
        opt.set_maxeval(int(opts["maxeval"]))
        if opts.get("population") is not None:
            opt.set_population(int(opts["population"]))
        if opts.get("seed", 0) is not None:
            nlopt.srand(int(opts.get("seed", 0)))
        try:
            x = opt.optimize(np.clip(x0, lower, upper))
            code = opt.last_optimize_result()
            success = code > 0 and code not in (nlopt.MAXEVAL_REACHED, nlopt.MAXTIME_REACHED)
            message = _MESSAGES.get(code, f"nlopt code {code}")
            fval = float(opt.last_optimum_value()) * (scale["f0"] or 1.0)
        except nlopt.RoundoffLimited:
            # the best point seen is still a result; the fit reports it as not converged
            x, fval, success, message = best["x"], best["f"], False, "roundoff limited"
        except RuntimeError as exc:   # NLopt's generic failure (e.g. SLSQP after rejected points)
            x, fval, success, message = best["x"], best["f"], False, f"nlopt failure: {exc or 'generic'}"
        result = OptimiseResult(np.asarray(x), fval, nfev, success, message)
        return self._polish(result, fun, lower, upper, jac, opts)

    def _polish(self, result: OptimiseResult, fun: Callable[[np.ndarray], Any], lower: np.ndarray,
                upper: np.ndarray, jac: Callable[[np.ndarray], np.ndarray] | None,
                opts: Mapping[str, Any]) -> OptimiseResult:
        """The result as found; a global search refines it locally (see :class:`NloptCrs2`)."""
        return result


class NloptBobyqa(NloptOptimiser):
    """NLopt ``LN_BOBYQA``: local derivative-free, quadratic models in a trust region."""

    name = "nlopt-bobyqa"
    algorithm = nlopt.LN_BOBYQA


class NloptCrs2(NloptOptimiser):
    """NLopt ``GN_CRS2_LM``: global derivative-free controlled random search (Lavigne et al.).

    The search stops when its population has gathered around one basin, which locates the
    minimum only to the population's spread; as NLopt's documentation advises for its global
    algorithms, the best point is then refined by a local search (BOBYQA) with the evaluations
    left of ``maxeval``. ``options["polish"] = False`` returns the global search's point as is.
    """

    name = "nlopt-crs2"
    algorithm = nlopt.GN_CRS2_LM
    needs_finite_bounds = True

    def _polish(self, result: OptimiseResult, fun: Callable[[np.ndarray], Any], lower: np.ndarray,
                upper: np.ndarray, jac: Callable[[np.ndarray], np.ndarray] | None,
                opts: Mapping[str, Any]) -> OptimiseResult:
        left = int(opts["maxeval"]) - result.nfev
        if not opts.get("polish", True) or left < 2 * result.x.size + 2 or not np.all(np.isfinite(result.x)):
            return result
        local = NloptBobyqa().minimise(fun, result.x, lower, upper, jac,
                                       {**opts, "maxeval": left, "population": None, "polish": False})
        nfev = result.nfev + local.nfev
        if not local.fun <= result.fun:
            return OptimiseResult(result.x, result.fun, nfev, result.success, result.message)
        return OptimiseResult(local.x, local.fun, nfev, result.success or local.success,
                              f"{result.message}; refined locally: {local.message}")


class NloptMma(NloptOptimiser):
    """NLopt ``LD_MMA``: gradient-based method of moving asymptotes."""

    name = "nlopt-mma"
    algorithm = nlopt.LD_MMA
    needs_gradient = True


class NloptSlsqp(NloptOptimiser):
    """NLopt ``LD_SLSQP``: gradient-based sequential quadratic programming."""

    name = "nlopt-slsqp"
    algorithm = nlopt.LD_SLSQP
    needs_gradient = True


class NloptLbfgs(NloptOptimiser):
    """NLopt ``LD_LBFGS``: gradient-based limited-memory BFGS with bounds."""

    name = "nlopt-lbfgs"
    algorithm = nlopt.LD_LBFGS
    needs_gradient = True
