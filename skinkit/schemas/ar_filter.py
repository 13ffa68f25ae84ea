"""Autoregressive prewhitening of a channel's noise-normalised samples, and its inverse.

The maths of :meth:`skinkit.schemas.Channel.whiten` for a tip channel with coloured noise; the
noise model itself is estimated in :mod:`skinkit.forward.noise_model`.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter, lfiltic


def whiten_series(z: np.ndarray, valid: np.ndarray, ar: np.ndarray, ratio: float,
                  scale: np.ndarray | None = None) -> np.ndarray:
    """Prewhiten ``z`` ``(T,)`` or ``(T, m)`` (noise-normalised residuals or their derivatives)
    along axis 0 by A(q) = 1 − Σ φᵢ q⁻ⁱ, scaled by ``ratio`` = σ/σ_e (module docstring).

    ``valid`` ``(T,)``: samples that carry data; the others are bridged by linear interpolation
    before filtering (the filter needs a value there) and returned as 0. ``scale`` ``(T,)``: the
    innovation's standard deviation at each sample relative to the model's (heteroscedastic
    noise), dividing the filtered samples. Complex-safe."""
    ar = np.asarray(ar, dtype=float)
    if not ar.size:
        return z
    z = np.asarray(z)
    valid = np.asarray(valid, dtype=bool)
    p = ar.size
    out = np.array(z, copy=True)
    if valid.sum() >= 2 and not valid.all():
        idx = np.flatnonzero(valid)
        t = np.arange(z.shape[0])
        flat = out.reshape(z.shape[0], -1)
        for j in range(flat.shape[1]):
            col = flat[:, j]
            re = np.interp(t, idx, col[idx].real)
            flat[:, j] = re + 1j * np.interp(t, idx, col[idx].imag) if np.iscomplexobj(col) else re
        out = flat.reshape(z.shape)
    filt = lfilter(np.concatenate([[1.0], -ar]), [1.0], out, axis=0) * ratio
    filt[:p] = out[:p]
    if scale is not None:
        filt = filt / np.asarray(scale, dtype=float).reshape((-1,) + (1,) * (z.ndim - 1))
    valid_b = valid.reshape(valid.shape + (1,) * (z.ndim - 1))
    return np.where(valid_b, filt, 0.0)


def colour_series(e: np.ndarray, valid: np.ndarray, ar: np.ndarray, ratio: float,
                  scale: np.ndarray | None = None) -> np.ndarray:
    """The inverse of :func:`whiten_series`: white samples ``e`` ``(T,)`` or ``(T, m)`` into
    noise-normalised coloured ones (the first p samples as they are, then 1/A(q) of e/ratio)."""
    ar = np.asarray(ar, dtype=float)
    if not ar.size:
        return e
    if scale is not None:
        e = np.asarray(e) * np.asarray(scale, dtype=float).reshape((-1,) + (1,) * (np.ndim(e) - 1))
    e = np.where(np.asarray(valid, bool).reshape(valid.shape + (1,) * (np.ndim(e) - 1)), e, 0.0)
    p = ar.size
    a = np.asarray(e) / ratio
    den = np.concatenate([[1.0], -ar])
    flat_e = np.asarray(e).reshape(len(a), -1)
    flat_a = a.reshape(len(a), -1)
    out = np.array(flat_e, copy=True)
    for j in range(flat_a.shape[1]):
        # the recursion starts from the first p samples, which are kept as they are
        zi = lfiltic([1.0], den, flat_e[:p, j][::-1])
        out[p:, j] = lfilter([1.0], den, flat_a[p:, j], zi=zi)[0]
    return out.reshape(np.shape(e))


__all__ = ["colour_series", "whiten_series"]
