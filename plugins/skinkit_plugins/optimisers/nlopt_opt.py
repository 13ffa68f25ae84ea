"""Derivative-free bound-constrained minimisation by NLopt's BOBYQA."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import nlopt
import numpy as np

from skinkit_plugins.optimisers.result import OptimiseResult


class NloptBobyqa:
    """NLopt ``LN_BOBYQA``. ``fun`` may return a residual vector (minimises ½‖r‖²) or a scalar.

    ``options``: ``xtol_rel`` (default 1e-8), ``ftol_rel`` (1e-12), ``maxeval`` (2000).
    """

    name = "nlopt-bobyqa"

    def minimise(self, fun: Callable[[np.ndarray], Any], x0: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray, jac: Callable[[np.ndarray], np.ndarray] | None = None,
                 options: Mapping[str, Any] | None = None) -> OptimiseResult:
        """Minimise the objective subject to ``lower <= x <= upper``; ``jac`` is not used."""
        opts = {"xtol_rel": 1e-8, "ftol_rel": 1e-12, "maxeval": 2000, **(options or {})}
        x0 = np.asarray(x0, float)
        nfev = 0

        def objective(x: np.ndarray, grad: np.ndarray) -> float:
            nonlocal nfev
            nfev += 1
            r = np.asarray(fun(x), float)
            return float(0.5 * r @ r) if r.ndim else float(r)

        opt = nlopt.opt(nlopt.LN_BOBYQA, x0.size)
        opt.set_min_objective(objective)
        opt.set_lower_bounds(np.asarray(lower, float))
        opt.set_upper_bounds(np.asarray(upper, float))
        opt.set_xtol_rel(opts["xtol_rel"])
        opt.set_ftol_rel(opts["ftol_rel"])
        opt.set_maxeval(int(opts["maxeval"]))
        try:
            x = opt.optimize(np.clip(x0, lower, upper))
            code = opt.last_optimize_result()
            success = code > 0 and code != nlopt.MAXEVAL_REACHED
            message = {nlopt.SUCCESS: "success", nlopt.FTOL_REACHED: "ftol reached",
                       nlopt.XTOL_REACHED: "xtol reached", nlopt.MAXEVAL_REACHED: "maxeval reached",
                       nlopt.STOPVAL_REACHED: "stopval reached"}.get(code, f"nlopt code {code}")
        except nlopt.RoundoffLimited:
            x, success, message = x0, False, "roundoff limited"
        return OptimiseResult(np.asarray(x), float(opt.last_optimum_value()), nfev, success, message)
