"""A random speckle texture defined analytically on material coordinates.

The texture is an infinite jittered grid of Gaussian dots: cell ``(i, j)`` of side ``cell``
holds one dot at a hashed random position with a hashed random amplitude. Intensity at a
material point is a smooth saturating function of the dot sum, so the texture can be
evaluated exactly at any point (no stored bitmap, no interpolation error): a rendered
image is then exactly consistent with the material points it shows.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)


def _hash(i: np.ndarray, j: np.ndarray, seed: int, salt: int) -> np.ndarray:
    """Uniform [0, 1) numbers hashed from integer cell indices (splitmix64 finaliser)."""
    with np.errstate(over="ignore"):
        z = (i.astype(np.int64).view(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
             ^ j.astype(np.int64).view(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F)
             ^ np.uint64((seed * 1000003 + salt) & 0xFFFFFFFFFFFFFFFF))
        z = (z ^ (z >> np.uint64(30))) * _M1
        z = (z ^ (z >> np.uint64(27))) * _M2
        z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) / float(1 << 53)


@dataclass(frozen=True)
class SpeckleTexture:
    """Gaussian-dot speckle on material coordinates.

    Attributes:
        cell: grid cell side, in the units of the coordinates it is evaluated at (px or m).
        sigma_frac: dot standard deviation as a fraction of ``cell`` [1].
        background: intensity between dots [0..1].
        contrast: intensity range added by the dots [0..1].
        fill: probability that a cell holds a dot [0..1].
        seed: integer seed; the same seed gives the same texture everywhere.
    """

    cell: float
    sigma_frac: float = 0.3
    background: float = 0.15
    contrast: float = 0.75
    fill: float = 0.8
    seed: int = 0

    def __call__(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Intensity [0..1] at material coordinates ``X``, ``Y`` (same shape, any shape)."""
        X = np.asarray(X, dtype=float)
        Y = np.asarray(Y, dtype=float)
        shape = np.broadcast(X, Y).shape
        u = np.broadcast_to(X / self.cell, shape).ravel()
        v = np.broadcast_to(Y / self.cell, shape).ravel()
        i0 = np.floor(u).astype(np.int64)
        j0 = np.floor(v).astype(np.int64)
        fu, fv = u - i0, v - j0          # where in its cell each point is
        s2 = 2.0 * self.sigma_frac**2
        acc = np.zeros(u.shape)
        dots = self._neighbours(i0, j0)
        # Dots beyond two cells contribute < exp(-1.5**2 / s2) ~ 1e-5 of a dot at sigma 0.3.
        for di in (-2, -1, 0, 1, 2):
            for dj in (-2, -1, 0, 1, 2):
                a, ox, oy = dots(di, dj)
                acc += a * np.exp(-((fu - di - ox) ** 2 + (fv - dj - oy) ** 2) / s2)
        return (self.background + self.contrast * (1.0 - np.exp(-1.5 * acc))).reshape(shape)

    def _dots(self, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Amplitude and centre offsets in their cells [cells] of the dots of cells ``(i, j)``."""
        on = _hash(i, j, self.seed, 3) < self.fill
        a = (0.6 + 0.4 * _hash(i, j, self.seed, 4)) * on
        return a, 0.15 + 0.7 * _hash(i, j, self.seed, 1), 0.15 + 0.7 * _hash(i, j, self.seed, 2)

    def _neighbours(self, i0: np.ndarray, j0: np.ndarray
                    ) -> Callable[[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """``dots(di, dj)``: the dots of the cells ``(i0 + di, j0 + dj)``, hashed once per cell into
        a table when the cells are fewer than the points (a rendered view samples each cell
        hundreds of times), else hashed per point. Either way the same numbers."""
        if i0.size == 0:
            return lambda di, dj: self._dots(i0 + di, j0 + dj)
        ilo, jlo = int(i0.min()) - 2, int(j0.min()) - 2
        ni, nj = int(i0.max()) + 3 - ilo, int(j0.max()) + 3 - jlo
        if ni * nj > i0.size:
            return lambda di, dj: self._dots(i0 + di, j0 + dj)
        I, J = np.meshgrid(np.arange(ilo, ilo + ni), np.arange(jlo, jlo + nj), indexing="ij")
        table = [t.ravel() for t in self._dots(I, J)]
        base = (i0 - ilo) * nj + (j0 - jlo)
        return lambda di, dj: tuple(t.take(base + (di * nj + dj)) for t in table)  # type: ignore[return-value]


@dataclass(frozen=True)
class SolidSpeckle:
    """Gaussian-dot speckle filling 3D body coordinates (for curved rigid bodies: the cone).

    A surface cutting the dot field shows dots of random apparent size. Same attributes as
    :class:`SpeckleTexture`; dots beyond one neighbouring cell are below 3e-5 of a dot.
    """

    cell: float
    sigma_frac: float = 0.25
    background: float = 0.15
    contrast: float = 0.75
    fill: float = 0.9
    seed: int = 0

    def __call__(self, P: np.ndarray) -> np.ndarray:
        """Intensity [0..1] at ``(N, 3)`` body coordinates."""
        q = np.asarray(P, dtype=float) / self.cell
        base = np.floor(q).astype(np.int64)
        s2 = 2.0 * self.sigma_frac**2
        acc = np.zeros(len(q))
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                for dk in (-1, 0, 1):
                    i, j, k = base[:, 0] + di, base[:, 1] + dj, base[:, 2] + dk
                    ij = i * 7919 + k
                    on = _hash(ij, j, self.seed, 13) < self.fill
                    a = (0.6 + 0.4 * _hash(ij, j, self.seed, 14)) * on
                    c = np.stack([i + 0.15 + 0.7 * _hash(ij, j, self.seed, 10),
                                  j + 0.15 + 0.7 * _hash(ij, j, self.seed, 11),
                                  k + 0.15 + 0.7 * _hash(ij, j, self.seed, 12)], axis=1)
                    acc += a * np.exp(-np.sum((q - c) ** 2, axis=1) / s2)
        return self.background + self.contrast * (1.0 - np.exp(-1.5 * acc))
