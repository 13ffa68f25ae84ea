"""2D renders of a speckle under a known in-plane deformation, with exact ground truth.

Material coordinates are the reference image's pixel coordinates (origin at the centre of
the top-left pixel). A deformation maps material point ``X`` to ``x = X + u(X)``; a pixel of
the deformed image shows the material point ``X(x)`` found by inverting that map. Each
pixel integrates the texture over its area by ``supersample**2`` point samples: the same
sampling in every frame, so the ground-truth displacement of a material point is exactly
``u(X)`` whatever the sampling.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from skinkit.vision import VisionError
from skinkit.vision.texture import SpeckleTexture

#: ``(x, y) -> (X, Y)``: deformed pixel coordinates to material coordinates [px]
InverseMap = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def identity() -> InverseMap:
    """The undeformed state."""
    return lambda x, y: (x, y)


def translation(dx: float, dy: float) -> InverseMap:
    """Rigid translation by ``(dx, dy)`` [px]: ``X = x - d``."""
    return lambda x, y: (x - dx, y - dy)


def affine(A: np.ndarray, d: np.ndarray, centre: np.ndarray) -> InverseMap:
    """``x = centre + A (X - centre) + d`` with ``A`` ``(2, 2)`` [1] and ``d``, ``centre`` ``(2,)`` [px]."""
    A = np.asarray(A, dtype=float)
    Ai = np.linalg.inv(A)
    c = np.asarray(centre, dtype=float)
    d = np.asarray(d, dtype=float)

    def inv(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        px = x - c[0] - d[0]
        py = y - c[1] - d[1]
        return c[0] + Ai[0, 0] * px + Ai[0, 1] * py, c[1] + Ai[1, 0] * px + Ai[1, 1] * py

    return inv


def field(u: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
          iterations: int = 30, tol_px: float = 1e-9) -> InverseMap:
    """A general displacement field ``u(X, Y) -> (ux, uy)`` [px], inverted by fixed-point
    iteration ``X <- x - u(X)`` (converges when the displacement gradient is below 1)."""

    def inv(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        X, Y = x.copy(), y.copy()
        for _ in range(iterations):
            ux, uy = u(X, Y)
            Xn, Yn = x - ux, y - uy
            step = max(float(np.max(np.abs(Xn - X), initial=0)), float(np.max(np.abs(Yn - Y), initial=0)))
            X, Y = Xn, Yn
            if step < tol_px:
                return X, Y
        raise VisionError("displacement field could not be inverted (gradient too large?)")

    return inv


def render(texture: SpeckleTexture, shape_hw: tuple[int, int], inverse: InverseMap | None = None,
           supersample: int = 3) -> np.ndarray:
    """Radiance ``(H, W)`` [0..1] of the texture seen through ``inverse`` (identity if None)."""
    h, w = (int(s) for s in shape_hw)
    if h <= 0 or w <= 0:
        raise VisionError(f"image shape must be positive, got {shape_hw}")
    n = int(supersample)
    offs = (np.arange(n) + 0.5) / n - 0.5
    inv = inverse or identity()
    out = np.zeros((h, w))
    y, x = np.mgrid[0:h, 0:w].astype(float)
    for oy in offs:
        for ox in offs:
            X, Y = inv(x + ox, y + oy)
            out += texture(X, Y)
    return out / (n * n)


def translation_trials(n: int, subset_px: int = 64, margin_px: int = 8, shift_px: float = 2.0,
                       cell_px: float = 5.0, sensor: Any = None, seed: int = 0,
                       ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """``n`` independent speckle translations with exact truth.

    Each trial renders a fresh texture (its own seed) on an image of side
    ``subset_px + 2 * margin_px``, translated by a uniform random ``(dx, dy)`` in
    ``[-shift_px, shift_px]`` [px], both frames through ``sensor`` (default: 0.6 px blur,
    1 % noise, 8 bit) with independent noise. Returns ``(reference, current, point, d)``
    with ``point`` ``(1, 2)`` the image centre and ``d`` ``(2,)`` the true displacement [px].
    """
    from skinkit.vision.sensor import Sensor

    sen = sensor or Sensor(blur_px=0.6, noise=0.01, bits=8)
    rng = np.random.default_rng(seed)
    side = int(subset_px) + 2 * int(margin_px)
    centre = np.array([[(side - 1) / 2, (side - 1) / 2]])
    out = []
    for k in range(int(n)):
        tex = SpeckleTexture(cell=cell_px, seed=int(rng.integers(2**31)) + k)
        d = rng.uniform(-shift_px, shift_px, 2)
        ref = sen.expose(render(tex, (side, side)), rng)
        cur = sen.expose(render(tex, (side, side), translation(*d)), rng)
        out.append((ref, cur, centre, d))
    return out
