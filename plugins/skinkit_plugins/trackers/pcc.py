"""``pcc``: NCC integer shift, then the slope of the cross-power-spectrum phase (thesis 2.6.4).

After the integer step the current subset is taken at the integer shift; its residual
subpixel shift ``d`` appears as a linear phase ``omega . d`` of ``F conj(G)``, fitted by
magnitude-weighted least squares over the well-sampled frequencies. A Hann window stops
the subset edges leaking into the spectrum; because the window does not move with the
content it pulls the estimate towards zero, so the fit is repeated on the current image
resampled (cubic B-spline) at the running estimate until the residual shift vanishes.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
from scipy.ndimage import map_coordinates, spline_filter

from skinkit.plugin.trackers import IntegerMatch
from skinkit_plugins.trackers.base import SubsetTracker


def _freq_grid(shape: tuple[int, int], omega_max: float) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """Frequencies used by :func:`phase_slope` (mask ``(ny, nx)``, ``wx``, ``wy``, ``(n, 2)``
    [rad/px]); shared, read-only."""
    # exact key: the float cut-off by its integer ratio (a hit never depends on rounding)
    return _grid(int(shape[0]), int(shape[1]), *float(omega_max).as_integer_ratio())


@functools.lru_cache(maxsize=16)  # one subset size and cut-off per tracker; a few trackers
def _grid(ny: int, nx: int, num: int, den: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    omega_max = num / den
    wy = 2 * np.pi * np.fft.fftfreq(ny)[:, None] * np.ones((1, nx))
    wx = 2 * np.pi * np.fft.fftfreq(nx)[None, :] * np.ones((ny, 1))
    use = (wx**2 + wy**2 <= omega_max**2) & ((wx != 0) | (wy != 0))
    out = (use, wx[use], wy[use], np.column_stack([wx[use], wy[use]]))
    for a in out:
        a.setflags(write=False)  # shared by every call: nobody may change it under the others
    return out


def phase_slope(f: np.ndarray, g: np.ndarray, window: np.ndarray, omega_max: float) -> np.ndarray:
    """Subpixel shift ``(dx, dy)`` [px] with ``g(x) = f(x - d)`` from the phase slope."""
    fw = (f - f.mean()) * window
    gw = (g - g.mean()) * window
    q = np.fft.fft2(fw) * np.conj(np.fft.fft2(gw))
    use, ax, ay, W = _freq_grid(f.shape, omega_max)
    qu = q[use]
    wgt = np.abs(qu)
    phi = np.angle(qu)
    Ww = W * wgt[:, None]
    return np.linalg.solve(Ww.T @ W, Ww.T @ phi)


class PhaseCorrelationTracker(SubsetTracker):
    """NCC integer search then phase-slope subpixel refinement.

    Args:
        search_px: integer search radius [px].
        min_quality: minimum peak NCC [1].
        omega_max: highest radial frequency used in the phase fit [rad/px]; speckle energy
            above it is mostly noise and aliasing.
        iterations: phase-fit passes on the resampled current subset (1 = the thesis's
            single pass).
    """

    name = "pcc"

    def __init__(self, search_px: int = 24, min_quality: float = 0.5, omega_max: float = 0.6 * np.pi,
                 iterations: int = 4) -> None:
        super().__init__(search_px, min_quality)
        self.omega_max = float(omega_max)
        self.iterations = int(iterations)
        self._windows: dict[int, np.ndarray] = {}

    def _window(self, s: int) -> np.ndarray:
        if s not in self._windows:
            h = np.hanning(s + 2)[1:-1]
            self._windows[s] = np.outer(h, h)
        return self._windows[s]

    def prepare(self, ref: np.ndarray, cur: np.ndarray) -> Any:
        """Spline coefficients of ``cur`` for the iterated refinement (None for one iteration)."""
        return spline_filter(cur, order=3, mode="mirror") if self.iterations > 1 else None

    def subpixel(self, state: Any, ref: np.ndarray, cur: np.ndarray, p: np.ndarray,
                 c0: int, r0: int, s: int, match: IntegerMatch,
                 mask: np.ndarray | None) -> tuple[np.ndarray, float, str, dict[str, Any]]:
        """Phase-correlation refinement: (displacement of ``p`` (2,) [px], quality, reason or '', extras)."""
        sx, sy = int(match.shift[0]), int(match.shift[1])
        f = ref[r0:r0 + s, c0:c0 + s]
        g = cur[r0 + sy:r0 + sy + s, c0 + sx:c0 + sx + s]
        use = None
        if mask is not None:
            use = mask[r0:r0 + s, c0:c0 + s] & mask[r0 + sy:r0 + sy + s, c0 + sx:c0 + sx + s]
            f = np.where(use, f, f[use].mean())
        win = self._window(s)
        d = np.zeros(2)
        yy, xx = np.mgrid[r0:r0 + s, c0:c0 + s].astype(float)
        h, w = cur.shape
        for it in range(max(1, self.iterations)):
            if it > 0:
                cx, cy = xx + sx + d[0], yy + sy + d[1]
                if cx.min() < 0 or cy.min() < 0 or cx.max() > w - 1 or cy.max() > h - 1:
                    return np.full(2, np.nan), match.peak, "displaced subset leaves the current image", {}
                g = map_coordinates(state, [cy, cx], order=3, prefilter=False, mode="mirror")
            gg = g if use is None else np.where(use, g, g[use].mean())
            step = phase_slope(f, gg, win, self.omega_max)
            if not np.all(np.isfinite(step)) or np.max(np.abs(step)) > 1.5:
                return np.full(2, np.nan), match.peak, "phase slope fit failed", {}
            d = d + step
            if np.max(np.abs(step)) < 1e-4:
                break
        return match.shift + d, match.peak, "", {}
