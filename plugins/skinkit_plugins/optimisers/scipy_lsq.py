"""Bound-constrained nonlinear least squares by SciPy's trust-region reflective method."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from skinkit.plugin.optimisers import OptimiseResult


class ScipyLeastSquares:
    """``scipy.optimize.least_squares`` (method ``trf``), with an analytic Jacobian if given.

    ``options`` are passed to ``least_squares`` (``xtol``, ``ftol``, ``max_nfev``,
    ``x_scale``...).
    """

    name = "scipy-lsq"

    def minimise(self, fun: Callable[[np.ndarray], Any], x0: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray, jac: Callable[[np.ndarray], np.ndarray] | None = None,
                 options: Mapping[str, Any] | None = None) -> OptimiseResult:
        """Minimise ½‖fun(x)‖² subject to ``lower <= x <= upper``."""
        opts = {"x_scale": "jac", **(options or {})}
        res = least_squares(fun, np.asarray(x0, float), jac=jac if jac is not None else "2-point",
                            bounds=(lower, upper), method="trf", **opts)
        return OptimiseResult(res.x, float(res.cost), int(res.nfev), bool(res.success), str(res.message))
