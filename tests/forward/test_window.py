"""A subset tracker's point is its subset's mean motion: the windowed observation operator."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit.errors import SchemaError
from skinkit.forward.fe import window_mean, window_offsets
from skinkit.schemas import Channel


def _field(X: np.ndarray, Y: np.ndarray, t: float) -> np.ndarray:
    """A displacement quartic in x and y (the 3-point Gauss rule integrates up to fifth order)."""
    return t * np.stack([1e-3 + 2.0 * X**2 - 3.0 * X * Y + 40.0 * Y**4,
                         5.0 * X * Y**2 + 0.1 * Y,
                         -7.0 * X**2 * Y**2 + 30.0 * X**3], axis=-1)


def _exact_mean(x0: float, y0: float, w: float, t: float, n: int = 801) -> np.ndarray:
    """Mean of the field over the window by a fine midpoint rule (error ~ w²/n²)."""
    s = (np.arange(n) + 0.5) / n * w - w / 2
    X, Y = np.meshgrid(x0 + s, y0 + s, indexing="ij")
    return _field(X, Y, t).reshape(-1, 3).mean(axis=0)


def test_window_mean_is_the_subsets_mean_displacement():
    w = 2.7e-3
    centres = np.array([[3e-3, 0.0, 0.0], [-5e-3, 4e-3, -1e-5]])
    q = (centres[:, None, :] + window_offsets(w)[None]).reshape(-1, 3)
    times = (0.0, 0.5, 1.0)
    pos = np.stack([q + _field(q[:, 0], q[:, 1], t) for t in times])          # (n, 9P, 3)
    d = np.stack([_field(q[:, 0], q[:, 1], 1.0)[..., None] for _ in times])    # d/dt, one parameter
    d[0] = 0.0
    mean, dmean = window_mean(pos, d)
    for k, t in enumerate(times):
        for p, c in enumerate(centres):
            want = c + _exact_mean(c[0], c[1], w, t)
            # the midpoint rule's own error bounds the comparison: ~1e-6 of the field's scale
            assert np.allclose(mean[k, p], want, rtol=0, atol=1e-11)
    assert np.allclose(dmean[2, 0, :, 0], _exact_mean(3e-3, 0.0, w, 1.0), rtol=0, atol=1e-11)
    assert np.all(dmean[0] == 0)


def test_window_offsets_centre_first_and_symmetric():
    off = window_offsets(2e-3)
    assert np.array_equal(off[0], np.zeros(3))
    assert np.allclose(off.sum(axis=0), 0.0, atol=1e-18)
    assert np.isclose(np.abs(off[:, :2]).max(), 1e-3 * np.sqrt(0.6))


@pytest.mark.parametrize("bad", [0.0, -1e-3, float("nan"), float("inf")])
def test_channel_refuses_a_bad_window(bad):
    ref = np.zeros((2, 3))
    with pytest.raises(SchemaError, match="window_m"):
        Channel("points", [0.0, 1.0], np.zeros((2, 2, 3)), noise=1e-6, reference=ref, window_m=bad)
