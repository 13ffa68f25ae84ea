"""A small synthetic record folder in the two-pad extensometer layout ``skinkit import-extensometer``
reads (that of the real record in ``invivo_extension_dic_healthy``, whose README describes it):
``reactionforce/u_moving_pad.dat``, ``f_moving_pad.dat`` (one value a line, [mm] and [N]) and
``displacement/x0.dat`` ... ``yt_ref_2.dat`` (tracked points and two marks per pad, [px])."""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: pixel scale of the synthetic images [px/mm]: the pads' marks are 24 mm = 240 px apart
PX_PER_MM = 10.0


def _write(path: Path, a: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = np.atleast_2d(a) if a.ndim == 2 else a[:, None]
    path.write_text("".join("\t".join(f"{v:.7e}" for v in row) + "\t\n" for row in rows))


def write_record(root: Path, *, device_mm: float = 4.0, images_mm: float = 3.6, samples: int = 80,
                 frames: int = 12, points: int = 25) -> Path:
    """Write a record folder under ``root``: the device pulls the moving pad from rest to
    ``device_mm`` [mm] over ``samples`` samples (force 0.05 N/mm); the camera's ``frames``
    images (the reference included) see it go out evenly to ``images_mm`` [mm]; ``points``
    skin points between the pads follow it linearly. Returns ``root``."""
    rng = np.random.default_rng(0)
    rest = 5
    u = np.concatenate([np.zeros(rest), np.linspace(0.0, device_mm, samples - rest)]) + 0.01
    _write(root / "reactionforce" / "u_moving_pad.dat", u)
    _write(root / "reactionforce" / "f_moving_pad.dat", 0.05 * (u - 0.01))
    d_px = np.linspace(0.0, images_mm, frames) * PX_PER_MM           # moving pad, per image
    x_fix, x_mov, y_marks = 180.0, 500.0, np.array([200.0, 440.0])
    for k, x in ((1, x_mov + d_px), (2, np.full(frames, x_fix))):    # pad 1 moves
        _write(root / "displacement" / f"x0_ref_{k}.dat", np.full(2, x[0]))
        _write(root / "displacement" / f"y0_ref_{k}.dat", y_marks)
        _write(root / "displacement" / f"xt_ref_{k}.dat", np.tile(x[1:], (2, 1)))
        _write(root / "displacement" / f"yt_ref_{k}.dat", np.tile(y_marks[:, None], (1, frames - 1)))
    side = int(round(np.sqrt(points)))
    gx, gy = np.meshgrid(np.linspace(220.0, 460.0, side), np.linspace(220.0, 420.0, side))
    x0, y0 = gx.ravel(), gy.ravel()
    share = (x0 - x_fix) / (x_mov - x_fix)
    xt = x0[:, None] + share[:, None] * d_px[None, 1:] + 0.05 * rng.standard_normal((x0.size, frames - 1))
    yt = y0[:, None] + 0.05 * rng.standard_normal((x0.size, frames - 1))
    for name, a in (("x0", x0), ("y0", y0), ("xt", xt), ("yt", yt)):
        _write(root / "displacement" / f"{name}.dat", a)
    return root
