"""Variance accounted for (thesis Eq. 4.8, as a percentage)."""

from __future__ import annotations

import numpy as np


def vaf(y: np.ndarray, y_hat: np.ndarray) -> float:
    """``100 (1 - var(y - y_hat) / var(y))`` [%] of ``(N,)`` arrays; NaN if ``y`` is constant."""
    y = np.asarray(y, float)
    v = float(np.var(y))
    if v == 0:
        return float("nan")
    return float(100.0 * (1.0 - np.var(y - np.asarray(y_hat, float)) / v))
