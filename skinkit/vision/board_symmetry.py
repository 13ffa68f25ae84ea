"""The half-turn ambiguity of symmetric checkerboards, resolved with the rig's geometry.

A board of ``cols x rows`` inner corners with ``cols + rows`` even (e.g. 12 x 8) looks the same
after half a turn about its normal, so a detector returns its corners either in board order
or reversed. For one camera this does not matter (each view has its own board pose). For a
rig it does: in one frame all cameras must label the same physical corner alike, else the
relative camera poses are wrong by a half turn.

The rig fixes it: camera ``c``'s pose relative to camera ``a``, computed from one frame's two
board poses, is the same for every frame only when both cameras labelled the board alike. With
``T[f, c]`` the board pose found by camera ``c`` in frame ``f`` (per-camera calibration) and
``H`` the board's half turn, the candidates ``T[f, c] H^k H^s[f, a] T[f, a]^-1`` (``k`` = 0 or 1)
cluster at the true relative pose for the right ``k`` and scatter for the wrong one (a half
turn about each view's board normal, which changes from view to view). Cameras are resolved
one after the other, each against an already-resolved camera it shares the most views with.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from skinkit.vision import VisionError

#: candidate relative poses within this rotation [deg] and this fraction of the baseline agree
ROT_TOL_DEG = 2.0
TRANS_TOL = 0.05


def is_symmetric(inner: tuple[int, int]) -> bool:
    """True for a board of (cols, rows) inner corners that a half turn maps onto itself."""
    return (int(inner[0]) + int(inner[1])) % 2 == 0


def half_turn(inner: tuple[int, int], square_m: float) -> np.ndarray:
    """``(4, 4)`` board-frame half turn about the board's centre normal: it maps corner ``k``'s
    board coordinates onto those of corner ``P - 1 - k`` (the reversed order)."""
    c, r = (int(v) for v in inner)
    H = np.diag([-1.0, -1.0, 1.0, 1.0])
    H[:2, 3] = [(c - 1) * square_m, (r - 1) * square_m]
    return H


def _pose(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, float).reshape(3))[0]
    T[:3, 3] = np.asarray(tvec, float).reshape(3)
    return T


def _distance(A: np.ndarray, B: np.ndarray) -> float:
    """Disagreement of two relative poses in tolerance units (<= 1: they agree)."""
    cosang = np.clip((np.trace(A[:3, :3].T @ B[:3, :3]) - 1) / 2, -1, 1)
    ang = np.degrees(np.arccos(cosang))
    base = max(np.linalg.norm(A[:3, 3]), np.linalg.norm(B[:3, 3]), 1e-12)
    return float(max(ang / ROT_TOL_DEG, np.linalg.norm(A[:3, 3] - B[:3, 3]) / (TRANS_TOL * base)))


def board_poses(corners: np.ndarray, found: np.ndarray, obj: np.ndarray, image_size: tuple[int, int],
                names: Sequence[str]) -> np.ndarray:
    """``(F, C, 4, 4)`` board -> camera poses [m] from a calibration of each camera alone
    (NaN where the board was not found); ``corners`` ``(F, C, P, 2)`` [px], ``obj`` ``(P, 3)`` [m]."""
    F, C = found.shape
    T = np.full((F, C, 4, 4), np.nan)
    for c in range(C):
        views = np.flatnonzero(found[:, c])
        if len(views) < 2:
            continue
        try:
            _, _, _, rvecs, tvecs = cv2.calibrateCamera(
                [obj.astype(np.float32)] * len(views), [corners[f, c].astype(np.float32) for f in views],
                image_size, None, None, flags=cv2.CALIB_FIX_K3)
        except cv2.error as exc:
            detail = str(exc).strip().splitlines()[-1]
            raise VisionError(f"calibration of {names[c]} alone failed: {detail}") from None
        for f, rv, tv in zip(views, rvecs, tvecs, strict=True):
            T[f, c] = _pose(rv, tv)
    return T


def resolve_half_turns(corners: np.ndarray, found: np.ndarray, inner: tuple[int, int], square_m: float,
                       image_size: tuple[int, int], names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Reverse the corner order of the views that disagree with the rig; returns the corrected
    ``corners`` ``(F, C, P, 2)`` [px] and ``found`` ``(F, C)`` (views that fit no consistent
    relative pose are dropped).

    Camera 0 (or the first camera that sees the board) labels each frame's board; each other
    camera is matched to it through the views they share. Raises :class:`VisionError` when a
    camera shares fewer than two views with the cameras resolved before it, or when its
    shared views are too alike to tell the two labellings apart.
    """
    corners = np.array(corners, float)
    found = np.array(found, bool)
    F, C = found.shape
    c0, r0 = (int(v) for v in inner)
    j, i = np.mgrid[0:r0, 0:c0]
    obj = np.column_stack([i.ravel(), j.ravel(), np.zeros(c0 * r0)]) * square_m
    T = board_poses(corners, found, obj, image_size, names)
    H = half_turn(inner, square_m)
    flips = np.full((F, C), -1)            # -1: not decided yet
    P: dict[int, np.ndarray] = {}          # resolved camera -> pose relative to the first one
    usable = found & np.isfinite(T[:, :, 0, 0])
    order = [c for c in range(C) if usable[:, c].any()]
    if not order:
        return corners, found
    first = order[0]
    flips[usable[:, first], first] = 0
    P[first] = np.eye(4)
    todo = set(order[1:])
    while todo:
        # the camera sharing the most views with one resolved camera goes next
        shared = {(c, a): int(np.sum(usable[:, c] & usable[:, a])) for c in todo for a in P}
        (c, a), n = max(shared.items(), key=lambda kv: kv[1])
        if n < 2:
            raise VisionError(f"symmetric {c0}x{r0} board: {names[c]} shares {n} view(s) with "
                              f"{', '.join(names[b] for b in P)}; two or more are needed to fix the "
                              "board's half turn")
        both = np.flatnonzero(usable[:, c] & usable[:, a])
        Ta_inv = [np.linalg.inv(T[f, a] @ np.linalg.matrix_power(H, int(flips[f, a]))) for f in both]
        cand = np.array([[T[f, c] @ np.linalg.matrix_power(H, k) @ Ti for k in (0, 1)]
                         for f, Ti in zip(both, Ta_inv, strict=True)])           # (n, 2, 4, 4)
        dist = np.array([[[min(_distance(cand[x, k], cand[y, m]) for m in (0, 1)) for y in range(len(both))]
                          for k in (0, 1)] for x in range(len(both))])           # (n, 2, n)
        support = (dist <= 1).sum(axis=2) - 1
        x, k = np.unravel_index(np.argmax(support - 1e-3 * dist.sum(axis=2)), support.shape)
        ref = cand[x, k]
        d_right = np.array([[_distance(ref, cand[y, m]) for m in (0, 1)] for y in range(len(both))])
        pick = np.argmin(d_right, axis=1)
        agree = d_right[np.arange(len(both)), pick] <= 1
        wrong = cand[np.arange(len(both)), 1 - pick]
        spread = max(_distance(wrong[p], wrong[q]) for p in range(len(both)) for q in range(len(both)))
        if agree.sum() < 2 or spread <= 3:
            raise VisionError(f"symmetric {c0}x{r0} board: the views {names[c]} shares with {names[a]} "
                              "are too alike to fix the board's half turn; vary the board's tilt more")
        for f, kk, ok in zip(both, pick, agree, strict=True):
            if ok:
                flips[f, c] = kk
            else:
                usable[f, c] = False
        P[c] = ref @ P[a]
        # views camera c shares with other resolved cameras, then views no resolved camera saw
        for f in np.flatnonzero(usable[:, c] & (flips[:, c] < 0)):
            seen = [b for b in P if b != c and usable[f, b] and flips[f, b] >= 0]
            if not seen:
                flips[f, c] = 0
                continue
            b = seen[0]
            Tb_inv = np.linalg.inv(T[f, b] @ np.linalg.matrix_power(H, int(flips[f, b])))
            rel = P[c] @ np.linalg.inv(P[b])
            d = [_distance(rel, T[f, c] @ np.linalg.matrix_power(H, m) @ Tb_inv) for m in (0, 1)]
            if min(d) <= 2:  # the chained pose carries the error of two estimates
                flips[f, c] = int(np.argmin(d))
            else:
                usable[f, c] = False
        todo.discard(c)
    rev = flips == 1
    corners[rev] = corners[rev][:, ::-1]
    dropped = found & ~usable
    corners[dropped] = np.nan
    return corners, found & usable
