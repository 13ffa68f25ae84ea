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
from skinkit_plugins.trackers.base import SubpixelBatch, SubsetTracker, solve_each, subset_stack

#: subsets refined together: bounds the stacks' memory (512 subsets of 64 px: ~34 MB of spectra)
CHUNK = 512


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
    try:
        return np.linalg.solve(Ww.T @ W, Ww.T @ phi)
    except np.linalg.LinAlgError:  # no usable spectrum (a texture-less subset): no fit
        return np.full(2, np.nan)


@functools.lru_cache(maxsize=16)
def _half_grid(ny: int, nx: int, num: int, den: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frequencies of :func:`_grid` in the half spectrum ``rfft2`` keeps: mask
    ``(ny, nx // 2 + 1)``, and per used bin the terms ``(M, 4)`` (flattened 2x2) and ``(M, 2)``
    it and its dropped conjugate partner add to the normal equations of :func:`phase_slope`."""
    use, _, _, _ = _grid(ny, nx, num, den)
    wy = 2 * np.pi * np.fft.fftfreq(ny)[:, None] * np.ones((1, nx))
    wx = 2 * np.pi * np.fft.fftfreq(nx)[None, :] * np.ones((ny, 1))
    ky, kx = np.nonzero(use[:, :nx // 2 + 1])
    py, px = (-ky) % ny, (-kx) % nx  # the partner bin holds the conjugate value
    W = np.column_stack([wx[ky, kx], wy[ky, kx]])
    Wp = np.column_stack([wx[py, px], wy[py, px]])
    paired = ((kx > 0) & (px != kx))[:, None]  # the partner is not itself in the half spectrum
    # the partner adds the same magnitude weight with the opposite phase
    outer = (W[:, :, None] * W[:, None, :]).reshape(-1, 4)
    G = outer + paired * (Wp[:, :, None] * Wp[:, None, :]).reshape(-1, 4)
    V = W - paired * Wp
    out = (use[:, :nx // 2 + 1].copy(), G, V)
    for arr in out:
        arr.setflags(write=False)
    return out


def windowed_spectra(f: np.ndarray, window: np.ndarray) -> np.ndarray:
    """Half spectra ``(K, S, S // 2 + 1)`` of the zero-mean, windowed subsets ``f`` ``(K, S, S)``."""
    return np.fft.rfft2((f - f.mean(axis=(1, 2), keepdims=True)) * window, axes=(-2, -1))


def phase_slope_many(F: np.ndarray, g: np.ndarray, window: np.ndarray,
                     omega_max: float) -> np.ndarray:
    """:func:`phase_slope` for K subsets at once: the reference half spectra ``F`` (from
    :func:`windowed_spectra`) and current subsets ``g`` ``(K, S, S)``; shifts ``(K, 2)`` [px],
    NaN where the fit is singular. The conjugate-symmetric half of each spectrum is folded
    into the normal equations instead of transformed."""
    q = F * np.conj(windowed_spectra(g, window))
    use, G, V = _half_grid(*g.shape[1:], *float(omega_max).as_integer_ratio())
    qu = q[:, use]  # (K, M) used frequencies
    wgt = np.abs(qu)
    A = (wgt @ G).reshape(-1, 2, 2)
    b = (wgt * np.angle(qu)) @ V
    return solve_each(A, b[:, :, None])[:, :, 0]


def _fill_masked(a: np.ndarray, use: np.ndarray) -> np.ndarray:
    """Stack ``a`` ``(K, S, S)`` with the pixels outside ``use`` set to the mean of those inside."""
    with np.errstate(invalid="ignore", divide="ignore"):  # an empty selection gives NaN, as f[use].mean()
        mean = np.sum(a * use, axis=(1, 2)) / np.count_nonzero(use, axis=(1, 2))
    return np.where(use, a, mean[:, None, None])


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

    def subpixel_many(self, state: Any, ref: np.ndarray, cur: np.ndarray, pts: np.ndarray,
                      origins: np.ndarray, s: int, matches: list[IntegerMatch],
                      mask: np.ndarray | None) -> SubpixelBatch:
        """:meth:`subpixel` for K points at once (stacked FFTs, one interpolation per pass);
        see :meth:`SubsetTracker.subpixel_many` for the arguments and shapes."""
        k = len(pts)
        shifts = np.array([m.shift for m in matches], dtype=int).reshape(k, 2)
        quality = np.array([m.peak for m in matches], dtype=float)
        disp = np.full((k, 2), np.nan)
        reasons = [""] * k
        for a in range(0, k, CHUNK):
            b = min(a + CHUNK, k)
            d, why = self._refine(state, ref, cur, origins[a:b], shifts[a:b], s, mask)
            disp[a:b] = shifts[a:b] + d
            reasons[a:b] = why
        return disp, quality, reasons, {}

    def _refine(self, state: Any, ref: np.ndarray, cur: np.ndarray, origins: np.ndarray,
                shifts: np.ndarray, s: int, mask: np.ndarray | None) -> tuple[np.ndarray, list[str]]:
        """Residual subpixel shifts ``(K, 2)`` [px] (NaN where failed) and K reasons for subsets
        at ``origins`` ``(K, 2)`` (col, row) matched at integer ``shifts`` ``(K, 2)`` [px]."""
        n = len(origins)
        c0, r0 = origins[:, 0], origins[:, 1]
        cs, rs = c0 + shifts[:, 0], r0 + shifts[:, 1]  # first pixel of the displaced subsets
        f = subset_stack(ref, c0, r0, s)
        g = subset_stack(cur, cs, rs, s)
        use = None
        if mask is not None:
            use = subset_stack(mask, c0, r0, s) & subset_stack(mask, cs, rs, s)
            f = _fill_masked(f, use)
        win = self._window(s)
        F = windowed_spectra(f, win)  # the reference side never changes
        d = np.zeros((n, 2))
        why = [""] * n
        act = np.arange(n)  # subsets still iterating
        ar = np.arange(s, dtype=float)
        h, w = cur.shape
        for it in range(max(1, self.iterations)):
            if it > 0:
                # the subset's corners decide, rounded exactly as the per-subset path rounds them
                lo_x, lo_y = cs[act] + d[act, 0], rs[act] + d[act, 1]
                hi_x, hi_y = cs[act] + (s - 1) + d[act, 0], rs[act] + (s - 1) + d[act, 1]
                out = (lo_x < 0) | (lo_y < 0) | (hi_x > w - 1) | (hi_y > h - 1)
                for j in act[out]:
                    why[j] = "displaced subset leaves the current image"
                d[act[out]] = np.nan
                act = act[~out]
                if not len(act):
                    break
                cx = (cs[act, None, None] + ar[None, None, :]) + d[act, 0, None, None]
                cy = (rs[act, None, None] + ar[None, :, None]) + d[act, 1, None, None]
                cx, cy = np.broadcast_arrays(cx, cy)
                gi = map_coordinates(state, [cy.ravel(), cx.ravel()], order=3, prefilter=False,
                                     mode="mirror").reshape(len(act), s, s)
            else:
                gi = g
            gg = gi if use is None else _fill_masked(gi, use[act])
            step = phase_slope_many(F[act], gg, win, self.omega_max)
            big = np.max(np.abs(step), axis=1)
            bad = ~np.all(np.isfinite(step), axis=1) | (big > 1.5)
            for j in act[bad]:
                why[j] = "phase slope fit failed"
            d[act[bad]] = np.nan
            d[act[~bad]] += step[~bad]
            act = act[~bad & ~(big < 1e-4)]  # converged subsets stop
            if not len(act):
                break
        return d, why
