"""The stable API for authors of optimisers (``skinkit.optimisers``).

Everything in ``__all__`` is public and kept stable. An optimiser's ``minimise(fun, x0, lower,
upper, jac=None, options=None)`` minimises ½‖r‖² when ``fun`` returns a residual vector ``(m,)``
(or a scalar objective) within the bounds ``lower``/``upper`` ``(n,)``; ``jac`` gives ``(m, n)``.

- :class:`OptimiseResult` what it returns: ``x`` ``(n,)``, ``fun`` the final objective
  (½‖r‖² for least squares), ``nfev`` evaluations, ``success`` and ``message``.

An optimiser is checked with :func:`skinkit.plugin.conformance.optimisers.check_optimiser`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class OptimiseResult:
    """``x`` ``(n,)`` solution, ``fun`` final objective (½‖r‖² for least squares), ``nfev``
    evaluations, ``success`` and the optimiser's ``message``."""

    x: np.ndarray
    fun: float
    nfev: int
    success: bool
    message: str


__all__ = ["OptimiseResult"]
