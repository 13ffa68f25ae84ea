"""The conformance kit for 2D subset trackers (``skinkit.trackers``): the stable API a tracker
author checks a tracker with.

:func:`check_tracker` ``(tracker)`` -> :class:`~skinkit.plugin.conformance.report.Report`, on a
seeded, smoothed random speckle (128 x 128 px) shifted by a known sub-pixel translation:

- ``interface``: the members of :class:`skinkit.interfaces.Tracker` and a name;
- ``result``: ``displacement_px`` ``(N, 2)``, ``quality`` ``(N,)``, ``valid`` ``(N,)`` and one
  ``reason`` per point (empty where valid);
- ``shift``: every interior point valid and within ``tolerance_px`` (default 0.05 px) of the
  translation ``(x, y)`` = (1.3, -0.6) px;
- ``zero shift``: identical images give displacements within 0.01 px of zero;
- ``edge``: a point whose subset leaves the image is invalid with a reason;
- ``bad input``: images of different sizes are refused with a :class:`~skinkit.plugin.trackers.VisionError`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from skinkit import registry
from skinkit.interfaces import Tracker, missing_members
from skinkit.plugin.conformance.report import Report
from skinkit.vision import VisionError

#: the known translation (x, y) [px] of the shifted speckle
SHIFT = (1.3, -0.6)


def speckle(shape: tuple[int, int] = (128, 128), shift: tuple[float, float] = (0.0, 0.0),
            seed: int = 0) -> np.ndarray:
    """A ``(H, W)`` smooth random speckle in [0, 255], its content moved by ``shift`` (x, y) [px]
    (exactly: the pattern is a sum of sinusoids evaluated at the shifted coordinates)."""
    rng = np.random.default_rng(seed)
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(float)
    x -= shift[0]
    y -= shift[1]
    img = np.zeros(shape)
    for _ in range(60):
        kx, ky = rng.uniform(-0.9, 0.9, 2)
        img += rng.uniform(0.5, 1.0) * np.cos(kx * x + ky * y + rng.uniform(0, 2 * np.pi))
    img -= img.min()
    return 255.0 * img / img.max()


def _result_shape(res: Any, n: int) -> str:
    try:
        d = np.asarray(res.displacement_px)
        q = np.asarray(res.quality)
        v = np.asarray(res.valid)
        r = list(res.reason)
    except (AttributeError, TypeError) as exc:
        return f"{type(exc).__name__}: {exc}"
    problems = []
    if d.shape != (n, 2):
        problems.append(f"displacement_px {d.shape}, expected {(n, 2)}")
    if q.shape != (n,) or v.shape != (n,):
        problems.append(f"quality {q.shape} / valid {v.shape}, expected {(n,)}")
    if len(r) != n or any(bool(v[i]) == bool(r[i]) for i in range(min(n, len(r), v.size))):
        problems.append("one reason per point, empty exactly where valid")
    return "; ".join(problems)


def check_tracker(tracker: Any, tolerance_px: float = 0.05, subset_px: int = 31) -> Report:
    """Check ``tracker`` (a plugin object or the name of an installed one); see the module."""
    trk = registry.create("skinkit.trackers", tracker) if isinstance(tracker, str) else tracker
    if isinstance(trk, type):
        trk = trk()
    report = Report("tracker", str(getattr(trk, "name", "?")))
    missing = missing_members(trk, Tracker)
    if not report.add("interface", not missing, f"missing {', '.join(missing)}" if missing else ""):
        return report
    ref, cur = speckle(), speckle(shift=SHIFT)
    pts = np.array([[40.0, 40.0], [64.0, 64.0], [88.0, 50.0], [50.0, 88.0], [2.0, 64.0]])
    try:
        res = trk.track(ref, cur, pts, subset_px)
        zero = trk.track(ref, ref, pts[:4], subset_px)
    except Exception as exc:  # a third-party tracker may raise anything
        report.add("track", False, f"{type(exc).__name__}: {exc}")
        return report
    problem = _result_shape(res, len(pts))
    if not report.add("result", not problem, problem):
        return report
    d, v = np.asarray(res.displacement_px, dtype=float), np.asarray(res.valid, dtype=bool)
    err = np.abs(d[:4] - np.array(SHIFT)).max()
    report.add("shift", bool(v[:4].all()) and err <= tolerance_px,
               f"worst error {err:.3f} px (tolerance {tolerance_px} px), valid {v[:4].tolist()}")
    z = np.abs(np.asarray(zero.displacement_px, dtype=float)).max()
    report.add("zero shift", z <= 0.01, f"largest displacement {z:.1e} px")
    report.add("edge", not bool(v[4]) and bool(res.reason[4]), f"reason {res.reason[4]!r}")
    try:
        trk.track(ref, cur[:-1], pts[:1], subset_px)
    except VisionError:
        report.add("bad input", True)
    except Exception as exc:  # anything but VisionError is the wrong refusal
        report.add("bad input", False, f"raised {type(exc).__name__} instead of VisionError")
    else:
        report.add("bad input", False, "images of different sizes were accepted")
    return report


__all__ = ["SHIFT", "check_tracker", "speckle"]
