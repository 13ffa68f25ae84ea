"""Reading grey images and point lists from files, with clear errors."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np

from skinkit.vision import VisionError


def read_gray(path: str | Path) -> np.ndarray:
    """A ``(H, W)`` grey image (uint8/uint16/float32) from an image file; colour is converted."""
    p = Path(path)
    if not p.exists():
        raise VisionError(f"{p}: no such image file")
    if p.is_dir():
        raise VisionError(f"{p}: is a directory, not an image")
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise VisionError(f"{p}: cannot be read as an image (unknown format or corrupt file)")
    if img.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        img = cv2.cvtColor(img, code)
    return img


def read_points_csv(path: str | Path) -> np.ndarray:
    """``(N, 2)`` points from a CSV file with header ``x_px,y_px`` [px]."""
    p = Path(path)
    if not p.exists():
        raise VisionError(f"{p}: no such points file")
    with p.open(newline="") as fh:
        reader = csv.reader(fh)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise VisionError(f"{p}: is empty (expected a header x_px,y_px)") from None
        if "x_px" not in header or "y_px" not in header:
            raise VisionError(f"{p}:1: header {','.join(header)!r} lacks the columns x_px,y_px")
        ix, iy = header.index("x_px"), header.index("y_px")
        rows = []
        for lineno, row in enumerate(reader, start=2):
            if not row or all(not c.strip() for c in row):
                continue
            try:
                rows.append((float(row[ix]), float(row[iy])))
            except (ValueError, IndexError):
                raise VisionError(f"{p}:{lineno}: expected numbers in x_px,y_px, got {row!r}") from None
    if not rows:
        raise VisionError(f"{p}: holds no points")
    return np.array(rows, dtype=float)
