"""A noise covariance plus a low-rank one, whitened: (I + V Vᵀ)^(−1/2) as a rank-r update of the
identity (used by the objective for the model error a session carries,
:mod:`skinkit.inverse.approximation`)."""

from __future__ import annotations

import numpy as np


def whitening(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(Q, shrink)`` with (I + V Vᵀ)^(−1/2) = I − Q diag(shrink) Qᵀ for ``V`` ``(m, r)`` (thin SVD;
    directions with no weight dropped)."""
    if V.size == 0:
        return np.zeros((V.shape[0], 0)), np.zeros(0)
    Q, s, _ = np.linalg.svd(V, full_matrices=False)
    keep = s > 1e-12 * max(float(s.max(initial=0.0)), 1e-300)
    Q, s = Q[:, keep], s[keep]
    return Q, 1.0 - 1.0 / np.sqrt(1.0 + s ** 2)


def apply(Q: np.ndarray, shrink: np.ndarray, a: np.ndarray) -> np.ndarray:
    """``(I − Q diag(shrink) Qᵀ) a`` for ``a`` ``(m,)`` or ``(m, n)``."""
    if not shrink.size:
        return a
    if a.ndim == 1:
        return a - Q @ (shrink * (Q.T @ a))
    return a - Q @ (shrink[:, None] * (Q.T @ a))


__all__ = ["apply", "whitening"]
