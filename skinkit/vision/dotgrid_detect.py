"""Finding a dot grid in an image: dots, their order, and the fiducials that fix it.

1. **Dots** (:func:`find_dots`): dark blobs under a local (adaptive) threshold, holes filled
   (a hollow fiducial becomes a disc), kept when their shape is an ellipse. Each centre is the
   centroid of the *ink* -- the local white level (median of a ring of paper around the dot)
   minus the grey value -- over the dot grown by the blur's reach: sub-pixel, unbiased by the
   noise, and the same for a ring as for a disc (both are centrally symmetric). The ink sum
   measures the dot's size whatever the blur.
   The centroid of a circle's image is not exactly the image of its centre (perspective makes
   the near half larger). For a dot of radius ``r`` at distance ``Z`` seen at angle ``theta``
   the shift is about ``f (r / Z)^2 sin(theta) cos(theta)`` px: 0.01 px for 1 mm dots at
   110 mm with f = 1100 px -- well below the detection noise, so it is not corrected.
2. **Order**: OpenCV's ``findCirclesGrid`` arranges the dot centres (passed as points, not
   as an image) into the ``cols x rows`` lattice, in one of the lattice's symmetric orders.
3. **Orientation**: of the lattice's symmetries, those that keep the printed face towards the
   camera (the board's x, y and the camera-facing normal right-handed) remain; the fiducials,
   dots whose ink differs from their neighbours' by the fiducial's ratio, pick the one that
   puts them where the grid has them. A symmetric grid without fiducials keeps its
   half-turn ambiguity (resolved across the rig by :mod:`skinkit.vision.board_symmetry`).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import cv2
import numpy as np
from scipy.ndimage import binary_dilation, binary_fill_holes

from skinkit.vision import VisionError
from skinkit.vision.board_symmetry import resolve_half_turns
from skinkit.vision.boards import FRONT_HANDEDNESS
from skinkit.vision.calibration import Calibration, Detections, calibrate_detections
from skinkit.vision.dotgrid import DotGrid, symmetries

MIN_AREA_PX = 6  # a dot must cover this many pixels (smaller: noise, or too steep a view)


def _to_uint8(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 2:
        raise VisionError(f"dot detection needs a grey image, got shape {img.shape}")
    f = img.astype(np.float32)
    lo, hi = np.percentile(f, [0.5, 99.5])
    return np.clip((f - lo) * (255.0 / max(hi - lo, 1e-9)), 0, 255).astype(np.uint8)


def find_dots(image: np.ndarray) -> np.ndarray:
    """Centres ``(N, 2)`` [px] (x right, y down, origin at the centre of the top-left pixel) of
    the dark elliptical blobs in a grey ``(H, W)`` image, to about a pixel: the candidates that
    :func:`detect_dotgrid` orders and then measures precisely.

    A hollow dot seen at an angle is a thin ring that the threshold may cut into arcs: pieces
    that are not ellipses themselves are joined with pieces within 2 px and kept when the
    union, holes filled, is an ellipse. Solid dots are never joined, so neighbouring dots
    cannot merge."""
    u8 = _to_uint8(image)
    H, W = u8.shape
    # dark: a quarter of the image's contrast below the local paper level (the brightest pixel
    # within a few dot pitches), low enough to keep the thin, blurred parts of a ring seen at an
    # angle and high enough to keep the paper between two dots seen at an angle
    block = 2 * (min(H, W) // 32) + 1
    smooth = cv2.blur(u8, (3, 3))  # the noise's maxima would raise the paper level
    paper = cv2.dilate(smooth, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (block, block)))
    lo, hi = np.percentile(smooth, [1, 99])
    mask = ((paper.astype(np.float32) - u8) > 0.25 * (hi - lo)).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    centres = []
    pieces = np.zeros((H, W), np.uint8)
    for k in range(1, n):
        x0, y0, w, h, area = (int(v) for v in stats[k])
        if area > H * W // 50 or w > W // 4 or h > H // 4 or x0 == 0 or y0 == 0 \
                or x0 + w == W or y0 + h == H:
            continue  # the scene around the plate, or cut by the image border
        sl = (slice(y0, y0 + h), slice(x0, x0 + w))
        filled = binary_fill_holes(labels[sl] == k)
        if _elliptical(filled):
            centres.append(_centroid(filled, x0, y0))
        elif area >= 2:
            pieces[sl][labels[sl] == k] = 1
    grown = cv2.dilate(pieces, np.ones((3, 3), np.uint8))
    m, groups, gstats, _ = cv2.connectedComponentsWithStats(grown, connectivity=8)
    for k in range(1, m):
        x0, y0, w, h, _ = (int(v) for v in gstats[k])
        sl = (slice(y0, y0 + h), slice(x0, x0 + w))
        region = (groups[sl] == k) & (pieces[sl] > 0)
        region = binary_fill_holes(binary_dilation(region) & (groups[sl] == k))
        if _elliptical(region):
            centres.append(_centroid(region, x0, y0))
    return np.array(centres, float).reshape(-1, 2)


def _centroid(region: np.ndarray, x0: int, y0: int) -> list[float]:
    ys, xs = np.nonzero(region)
    return [float(xs.mean()) + x0, float(ys.mean()) + y0]


def _elliptical(region: np.ndarray) -> bool:
    """True for a filled region whose area matches the ellipse of its second moments (a dot
    seen at an angle), not a blob of another shape."""
    ys, xs = np.nonzero(region)
    if len(xs) < MIN_AREA_PX:
        return False
    cov = np.cov(np.vstack([xs, ys])) + np.eye(2) / 12.0  # + a pixel's own spread
    ev = np.linalg.eigvalsh(cov)
    if ev[0] <= 0 or ev[1] / ev[0] > 36:  # flatter than 1:6 -- more than 80 deg off the normal
        return False
    ellipse_area = 4 * np.pi * np.sqrt(ev[0] * ev[1])
    return 0.6 < len(xs) / ellipse_area < 1.4  # a small blob's pixels approximate it coarsely


def _grid_order(centres: np.ndarray, grid: DotGrid) -> np.ndarray | None:
    """``(P,)`` indices into ``centres`` in one of the lattice's orders, or None."""
    if len(centres) < grid.cols * grid.rows:
        return None
    pts = centres.astype(np.float32).reshape(-1, 1, 2)
    kind = cv2.CALIB_CB_ASYMMETRIC_GRID if grid.asymmetric else cv2.CALIB_CB_SYMMETRIC_GRID
    params = cv2.CirclesGridFinderParameters()
    for flags in (kind, kind | cv2.CALIB_CB_CLUSTERING):
        try:
            ok, found = cv2.findCirclesGrid(image=pts, patternSize=grid.size, flags=flags,
                                            blobDetector=None, parameters=params)
        except cv2.error:
            continue
        if ok and found is not None:
            got = found.reshape(-1, 2).astype(float)
            d = np.linalg.norm(centres[None, :, :] - got[:, None, :], axis=2)
            idx = np.argmin(d, axis=1)
            if np.all(d[np.arange(len(got)), idx] < 1e-3) and len(set(idx.tolist())) == len(idx):
                return idx
    return None


def _local_maps(pts: np.ndarray, grid: DotGrid) -> np.ndarray:
    """``(P, 2, 2)`` local affine maps board xy [m] -> image [px] at each lattice point, fitted
    to the point and its lattice neighbours (the dot's image shape: perspective is locally
    affine over a dot)."""
    obj = grid.object_points()[:, :2]
    d = np.linalg.norm(obj[:, None] - obj[None], axis=2)
    step = np.min(d[d > 0])
    out = np.empty((len(pts), 2, 2))
    for k in range(len(pts)):
        nb = np.flatnonzero(d[k] < 1.5 * step)  # the point itself and its 3 to 8 neighbours
        A = np.column_stack([obj[nb] - obj[k], np.ones(len(nb))])
        coef, *_ = np.linalg.lstsq(A, pts[nb], rcond=None)
        out[k] = coef[:2].T
    return out


def _remeasure(image: np.ndarray, pts: np.ndarray, grid: DotGrid) -> tuple[np.ndarray, np.ndarray]:
    """Ink centroids ``(P, 2)`` [px] and inks ``(P,)`` of the dots at lattice points ``pts``
    (NaN ink where a dot's window leaves the image).

    Each dot is measured over the window its lattice predicts (the local affine map ``u`` from
    pixels to board coordinates): the points nearer to it than half a lattice step, ``|u| <=
    step / 2`` -- the whole dot and its blur, and as far from the neighbours' ink as from its
    own, so their tails cancel. The paper level is the median of the pixels within one step
    that lie outside every dot's window. Nothing depends on how the threshold cut the dot (a
    thin ring seen at an angle may break)."""
    img = np.asarray(image, float)
    H, W = img.shape
    maps = _local_maps(pts, grid)
    obj = grid.object_points()[:, :2]
    d = np.linalg.norm(obj[:, None] - obj[None], axis=2)
    step = float(np.min(d[d > 0]))
    r_w = step / 2
    centres = pts.astype(float).copy()
    inks = np.full(len(pts), np.nan)
    for k in range(len(pts)):
        J = maps[k]
        Jinv = np.linalg.inv(J)
        nb = obj[(d[k] > 0) & (d[k] < 1.5 * step)] - obj[k]  # neighbours' offsets [m]
        scale = float(np.linalg.norm(J, 2))                   # [px/m], least foreshortened
        half = step * scale + 1
        for _ in range(2):  # re-centre once on the measured centroid
            c = centres[k]
            if min(c[0], c[1]) - r_w * scale < 0 or c[0] + r_w * scale > W - 1 or c[1] + r_w * scale > H - 1:
                break  # the dot's window leaves the image: keep the detector's centre, ink unknown
            x0, x1 = max(int(np.floor(c[0] - half)), 0), min(int(np.ceil(c[0] + half)) + 1, W)
            y0, y1 = max(int(np.floor(c[1] - half)), 0), min(int(np.ceil(c[1] + half)) + 1, H)
            yy, xx = np.mgrid[y0:y1, x0:x1]
            u = np.stack([xx - c[0], yy - c[1]], axis=-1) @ Jinv.T
            r = np.linalg.norm(u, axis=-1)
            inside = r <= r_w
            paper = (r > r_w) & (r <= step)
            for off in nb:
                paper &= np.linalg.norm(u - off, axis=-1) > r_w
            patch = img[y0:y1, x0:x1]
            if paper.sum() < 6:
                break
            wgt = np.where(inside, float(np.median(patch[paper])) - patch, 0.0)
            ink = float(wgt.sum())
            if not ink > 0:
                break
            centres[k] = [float((wgt * xx).sum()) / ink, float((wgt * yy).sum()) / ink]
            inks[k] = ink
    return centres, inks


def _handedness(obj: np.ndarray, img: np.ndarray) -> float:
    """Sign of the determinant of the least-squares affine map board xy -> image."""
    A = np.column_stack([obj[:, :2], np.ones(len(obj))])
    coef, *_ = np.linalg.lstsq(A, img, rcond=None)
    return float(np.sign(np.linalg.det(coef[:2].T)))


def _relative_ink(ink: np.ndarray, grid: DotGrid) -> np.ndarray:
    """``(P,)`` log of each dot's ink over the median of its lattice neighbours' (up to two
    steps away: the same foreshortening, and a fiducial L never outvotes them); NaN unknown."""
    obj = grid.object_points()[:, :2]
    d = np.linalg.norm(obj[:, None] - obj[None], axis=2)
    step = np.min(d[d > 0])
    near = (d > 0) & (d < 2.1 * step)
    with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all neighbours unknown: NaN
        med = np.array([np.nanmedian(np.where(near[k], ink, np.nan)) for k in range(len(ink))])
        return np.log(ink / med)


def _pick_by_fiducials(rel: np.ndarray, cands: list[np.ndarray], grid: DotGrid) -> int | None:
    """Index of the candidate order that puts the fiducials' ink where the grid has them.

    Score of an order: mean relative log-ink of the dots it calls fiducials minus the median of
    the others; the right order scores about ``log(ink_ratio)``, a wrong one about 0 (its
    "fiducials" are mostly ordinary dots). Accepted when the best scores beyond half of that
    and every other order stays within half of it."""
    want = grid.fiducial_indices()
    expect = float(np.log(grid.ink_ratio()))
    scores = []
    for perm in cands:
        r = rel[perm]
        if not np.all(np.isfinite(r[want])):
            scores.append(np.nan)  # a fiducial of this order is cut by the image border
            continue
        others = np.delete(r, want)
        scores.append((float(np.mean(r[want])) - float(np.nanmedian(others))) / expect)
    sc = np.array(scores)
    if not np.any(np.isfinite(sc)):
        return None
    best = int(np.nanargmax(sc))
    rest = np.delete(sc, best)
    if sc[best] < 0.5 or np.any(rest[np.isfinite(rest)] > 0.5):
        return None
    return best


def detect_dotgrid(image: np.ndarray, grid: DotGrid) -> tuple[np.ndarray | None, str]:
    """``(P, 2)`` dot centres [px] in board order (None when not found) and, when not found,
    why (``""`` otherwise). A symmetric grid without fiducials is returned in one of its two
    half-turn orders."""
    centres = find_dots(image)
    order = _grid_order(centres, grid)
    if order is None:
        P = grid.cols * grid.rows
        if len(centres) < P:
            return None, f"{len(centres)} dots seen, the grid has {P}"
        return None, f"{len(centres)} dots seen, not arranged as {grid.cols}x{grid.rows}"
    pts, ink = _remeasure(image, centres[order], grid)
    obj = grid.object_points()
    cands = [perm for perm, _ in symmetries(grid)
             if _handedness(obj, pts[perm]) == FRONT_HANDEDNESS]
    if not grid.fiducials:
        return pts[cands[0]], ""
    pick = _pick_by_fiducials(_relative_ink(ink, grid), cands, grid)
    if pick is None:
        return None, f"grid found but not its {len(grid.fiducials)} {grid.fiducial_kind} fiducial dots"
    return pts[cands[pick]], ""


def detect_all_dotgrid(images: np.ndarray, grid: DotGrid,
                       camera_names: Sequence[str] | None = None) -> Detections:
    """Detect ``grid`` in ``(F, C, H, W)`` images; ``Detections`` with its object points.

    Raises :class:`VisionError` naming the cameras, frames and reasons when some camera finds
    the grid in no view at all."""
    return _detect_all(images, grid, camera_names)[0]


def _detect_all(images: np.ndarray, grid: DotGrid, camera_names: Sequence[str] | None,
                ) -> tuple[Detections, dict[int, list[tuple[int, str]]]]:
    """:func:`detect_all_dotgrid` and, per camera, the ``(frame, reason)`` of each miss."""
    imgs = np.asarray(images)
    if imgs.ndim != 4:
        raise VisionError(f"calibration images: expected (frames, cameras, H, W), got shape {imgs.shape}")
    F, C, H, W = imgs.shape
    names = list(camera_names) if camera_names is not None else [f"camera {c}" for c in range(C)]
    if len(names) != C:
        raise VisionError(f"{len(names)} camera names for {C} cameras in the images")
    P = grid.cols * grid.rows
    corners = np.full((F, C, P, 2), np.nan)
    found = np.zeros((F, C), bool)
    why: dict[int, list[tuple[int, str]]] = {c: [] for c in range(C)}
    for f in range(F):
        for c in range(C):
            pts, reason = detect_dotgrid(imgs[f, c], grid)
            if pts is None:
                why[c].append((f, reason))
            else:
                corners[f, c], found[f, c] = pts, True
    blind = [c for c in range(C) if not found[:, c].any()]
    if blind:
        raise VisionError(f"{grid.cols}x{grid.rows} dot grid not found in any view of "
                          + "; ".join(f"{names[c]} ({_misses(why[c])})" for c in blind))
    return Detections(corners, found, (W, H), grid.object_points()), why


def _misses(misses: list[tuple[int, str]]) -> str:
    """``frames 0, 3, 7: <first reason>`` (the frames without the grid, one reason); a camera
    that found the grid in every frame (too few frames in all) says so."""
    if not misses:
        return "found in every frame: take more views"
    frames = ", ".join(str(f) for f, _ in misses[:8]) + (", ..." if len(misses) > 8 else "")
    return f"frame{'s' if len(misses) > 1 else ''} {frames}: {misses[0][1]}"


def calibrate_dotgrid(images: np.ndarray, grid: DotGrid, camera_names: Sequence[str] | None = None,
                      min_views: int = 4, world_view: int | None = None, fix_k3: bool = True,
                      ) -> Calibration:
    """Calibrate the cameras that took ``images`` ``(F, C, H, W)`` of the dot grid ``grid``
    (:func:`skinkit.vision.calibration.calibrate` for dot grids).

    The world frame is the grid of view ``world_view`` (default: the first camera 0 saw), dot
    (0, 0) at its origin, x along its rows. A symmetric grid without fiducials is labelled
    alike across the cameras by the rig's geometry (:mod:`skinkit.vision.board_symmetry`).
    Raises :class:`VisionError` naming the camera, frames and reason when a camera finds the
    grid in fewer than ``min_views`` views.
    """
    det, why = _detect_all(images, grid, camera_names)
    F, C = det.found.shape
    names = list(camera_names) if camera_names is not None else [f"cam{c}" for c in range(C)]
    few = [c for c in range(C) if det.found[:, c].sum() < min_views]
    if few:
        raise VisionError("too few views of the dot grid (each camera needs " + str(min_views) + "): "
                          + "; ".join(f"{names[c]} found it in {int(det.found[:, c].sum())} of {F} "
                                      f"({_misses(why[c])})" for c in few))
    if not grid.fiducials and len([p for p, det_ in symmetries(grid) if det_ > 0]) == 2:
        corners, found = resolve_half_turns(det.corners, det.found, grid.size, grid.pitch_m,
                                            det.image_size, names)
        det = Detections(corners, found, det.image_size, det.object_points)
    return calibrate_detections(det, None, grid.pitch_m, names, min_views, world_view, fix_k3)
