"""``skinkit bench vision``: subpixel tracking error and speed, skinkit against peers.

Every method sees the same rendered subsets (speckle translated by random subpixel amounts,
1 % Gaussian noise, 8-bit): skinkit's ``pcc`` and ``gn`` trackers (from the plugin registry),
``cv2.phaseCorrelate`` (with the Hann window its documentation recommends),
``cv2.phaseCorrelateIterative`` (when this OpenCV has it) and
``skimage.registration.phase_cross_correlation`` (upsample factor 100; as documented, and
windowed without spectral normalisation, its better setting on noisy speckle). Error is split into
bias (mean error) and noise (standard deviation); speed is subsets per second in this
process.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from skinkit.vision.planar import translation_trials

Method = Callable[[np.ndarray, np.ndarray, np.ndarray, int], np.ndarray]


def _skinkit(name: str) -> Method:
    from skinkit import registry

    tracker = registry.create("skinkit.trackers", name)

    def run(ref: np.ndarray, cur: np.ndarray, p: np.ndarray, s: int) -> np.ndarray:
        return tracker.track(ref, cur, p, s).displacement_px[0]

    return run


def _centre_subsets(ref: np.ndarray, cur: np.ndarray, s: int) -> tuple[np.ndarray, np.ndarray]:
    h, w = ref.shape
    r0, c0 = (h - s) // 2, (w - s) // 2
    return (ref[r0:r0 + s, c0:c0 + s].astype(np.float64), cur[r0:r0 + s, c0:c0 + s].astype(np.float64))


def peers() -> dict[str, Method]:
    """Peer methods available in this environment, by display name."""
    import cv2

    out: dict[str, Method] = {}
    windows: dict[int, np.ndarray] = {}

    def cv_pc(ref: np.ndarray, cur: np.ndarray, p: np.ndarray, s: int) -> np.ndarray:
        a, b = _centre_subsets(ref, cur, s)
        win = windows.setdefault(s, cv2.createHanningWindow((s, s), cv2.CV_64F))
        return np.array(cv2.phaseCorrelate(a, b, win)[0])

    out["cv2.phaseCorrelate (Hann)"] = cv_pc
    if hasattr(cv2, "phaseCorrelateIterative"):
        def cv_pci(ref: np.ndarray, cur: np.ndarray, p: np.ndarray, s: int) -> np.ndarray:
            a, b = _centre_subsets(ref, cur, s)
            return np.array(cv2.phaseCorrelateIterative(a, b))

        out["cv2.phaseCorrelateIterative"] = cv_pci
    try:
        from skimage.registration import phase_cross_correlation
    except ImportError:  # pragma: no cover - scikit-image is optional for the bench
        return out

    def sk(ref: np.ndarray, cur: np.ndarray, p: np.ndarray, s: int) -> np.ndarray:
        a, b = _centre_subsets(ref, cur, s)
        # skimage returns the (row, col) shift that registers `moving` onto `reference`.
        return -np.asarray(phase_cross_correlation(a, b, upsample_factor=100)[0])[::-1]

    out["skimage phase_cross_correlation (x100)"] = sk

    def sk_win(ref: np.ndarray, cur: np.ndarray, p: np.ndarray, s: int) -> np.ndarray:
        a, b = _centre_subsets(ref, cur, s)
        win = windows.setdefault(s, cv2.createHanningWindow((s, s), cv2.CV_64F))
        a, b = (a - a.mean()) * win, (b - b.mean()) * win
        shift = phase_cross_correlation(a, b, upsample_factor=100, normalization=None)[0]
        return -np.asarray(shift)[::-1]

    out["skimage phase_cross_correlation (x100, Hann, unnormalised)"] = sk_win
    return out


def compare(n_trials: int = 100, subset_px: int = 64, seed: int = 0,
            methods: dict[str, Method] | None = None) -> list[dict[str, float | str]]:
    """Run every method on the same ``n_trials`` translations; one row per method.

    Row keys: ``method``, ``rms_px``, ``bias_x_px``, ``bias_y_px``, ``noise_px`` (RMS of the
    per-axis standard deviations), ``max_px``, ``subsets_per_s``, ``failed``.
    """
    trials = translation_trials(n_trials, subset_px, seed=seed)
    if methods is None:
        methods = {"skinkit pcc": _skinkit("pcc"), "skinkit gn": _skinkit("gn"),
                   "skinkit gn-translation": _skinkit("gn-translation"), **peers()}
    rows: list[dict[str, float | str]] = []
    for name, fn in methods.items():
        errs = []
        t0 = time.perf_counter()
        for ref, cur, p, d in trials:
            errs.append(np.asarray(fn(ref, cur, p, subset_px), dtype=float) - d)
        dt = time.perf_counter() - t0
        e = np.array(errs)
        ok = np.all(np.isfinite(e), axis=1)
        e = e[ok]
        rows.append({
            "method": name,
            "rms_px": float(np.sqrt(np.mean(np.sum(e**2, axis=1)) / 2)) if len(e) else float("nan"),
            "bias_x_px": float(e[:, 0].mean()) if len(e) else float("nan"),
            "bias_y_px": float(e[:, 1].mean()) if len(e) else float("nan"),
            "noise_px": float(np.sqrt(np.mean(e.std(axis=0) ** 2))) if len(e) else float("nan"),
            "max_px": float(np.max(np.abs(e))) if len(e) else float("nan"),
            "subsets_per_s": len(trials) / dt if dt > 0 else float("inf"),
            "failed": float(np.count_nonzero(~ok)),
        })
    return rows


#: column titles of :func:`table_rows`
COLUMNS = ("method", "RMS [px]", "bias x [px]", "bias y [px]", "noise [px]", "max [px]", "subsets/s",
           "failed")


def table_rows(rows: list[dict[str, float | str]]) -> list[list[str]]:
    """One row of text per method of :func:`compare`'s rows, under :data:`COLUMNS`."""
    return [[str(r["method"]), f"{r['rms_px']:.4f}", f"{r['bias_x_px']:+.4f}", f"{r['bias_y_px']:+.4f}",
             f"{r['noise_px']:.4f}", f"{r['max_px']:.4f}", f"{r['subsets_per_s']:.0f}", f"{r['failed']:.0f}"]
            for r in rows]


def ratio_lines(rows: list[dict[str, float | str]]) -> list[str]:
    """Each method's RMS error and speed relative to skinkit's ``pcc`` (the first row without it)."""
    ref = next((r for r in rows if r["method"] == "skinkit pcc"), rows[0])
    return [f"{r['method']}: RMS error {float(r['rms_px']) / float(ref['rms_px']):.2f}x pcc's, "
            f"speed {float(r['subsets_per_s']) / float(ref['subsets_per_s']):.2f}x pcc's"
            for r in rows if r is not ref]
