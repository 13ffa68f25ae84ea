"""The result record the built-in optimisers return."""

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
