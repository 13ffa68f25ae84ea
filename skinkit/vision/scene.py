"""What the cameras of a rig see: speckled skin, calibration boards, the speckled conical
indenter and fluorescent marker spheres, rendered with exact ground truth.

Every object answers ``hit(origin, dirs) -> (depth, radiance)`` for world rays (depth is the
ray parameter [m], ``inf`` where the ray misses). :func:`render_view` casts ``s x s`` rays
per pixel through the (distorted) camera model, keeps the nearest hit, averages the samples
over the pixel and exposes the result through a :class:`~skinkit.vision.sensor.Sensor`.
Ground truth is geometric: a material point's image position is the projection of its
3D position (:func:`skinkit.vision.camera.project`).
"""

from __future__ import annotations

import functools
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from skinkit.schemas import CameraModel
from skinkit.vision import VisionError
from skinkit.vision import camera as cam_ops
from skinkit.vision.sensor import Sensor
from skinkit.vision.texture import SolidSpeckle, SpeckleTexture

Height = Callable[[np.ndarray, np.ndarray], np.ndarray]
Displacement = Callable[[np.ndarray, np.ndarray], np.ndarray]

BACKGROUND = 0.05  # radiance where no object is hit [0..1]


def flat(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """The plane z = 0."""
    return np.zeros(np.broadcast(X, Y).shape)


def forearm(radius_m: float = 0.035) -> Height:
    """A forearm-like cylinder of ``radius_m`` [m] along x, crest at z = 0."""
    def h(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        Yc = np.clip(Y, -0.95 * radius_m, 0.95 * radius_m)
        return np.sqrt(radius_m**2 - Yc**2) - radius_m + 0.0 * X
    return h


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of ``(3, N)`` component arrays."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products ``(N,)`` of ``(3, N)`` component arrays."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@dataclass
class Skin:
    """A speckled height-field surface ``z = height(X, Y)`` over material coordinates
    ``(X, Y)`` [m], optionally deformed by ``displacement(X, Y) -> (N, 3)`` [m].

    Speckle covers ``|X| <= half_extent_m[0]``, ``|Y| <= half_extent_m[1]``; beyond is plain.
    """

    texture: SpeckleTexture
    height: Height = flat
    half_extent_m: tuple[float, float] = (0.025, 0.025)
    displacement: Displacement | None = None
    #: the undeformed skin's ray solutions, shared by every deformed copy: a deformed view's
    #: Newton starts there (displacements are small beside the camera distance) and converges
    #: in a few iterations instead of marching in from a plane
    _rest: dict = field(default_factory=dict, repr=False, compare=False)

    def reference(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """``(N, 3)`` undeformed positions of material points [m]."""
        X = np.ravel(X).astype(float)
        Y = np.ravel(Y).astype(float)
        return np.column_stack([X, Y, self.height(X, Y)])

    def position(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """``(N, 3)`` current (deformed) positions of material points [m]."""
        p = self.reference(X, Y)
        if self.displacement is not None:
            p = p + np.asarray(self.displacement(np.ravel(X), np.ravel(Y)), float)
        return p

    def _position_gradient(self, X: np.ndarray, Y: np.ndarray, eps: float
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(N, 3)`` positions and their derivatives along X and Y: the height by differences
        of ``eps`` [m], the displacement by its own ``gradient`` when it has one (one
        evaluation of the field instead of three)."""
        grad = getattr(self.displacement, "gradient", None)
        if self.displacement is not None and grad is None:
            P = self.position(X, Y)
            return P, (self.position(X + eps, Y) - P) / eps, (self.position(X, Y + eps) - P) / eps
        P = self.reference(X, Y)
        dX = (self.reference(X + eps, Y) - P) / eps
        dY = (self.reference(X, Y + eps) - P) / eps
        if grad is not None:
            u, ux, uy = grad(np.ravel(X), np.ravel(Y))
            P, dX, dY = P + u, dX + ux, dY + uy
        return P, dX, dY

    def deformed(self, displacement: Displacement | None) -> Skin:
        """The same skin under another displacement field."""
        return Skin(self.texture, self.height, self.half_extent_m, displacement, self._rest)

    def intersect(self, origin: np.ndarray, dirs: np.ndarray, iterations: int = 20,
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Ray parameter ``(N,)`` [m] (inf if missed) and material coordinates ``(N, 2)`` [m].

        Newton on ``position(X, Y) = origin + s d``, started on the plane z = height(0, 0), or,
        for a deformed skin, at the undeformed skin's solution of the same rays.
        """
        if self.displacement is None:
            u = self._rest_solution(origin, dirs, iterations).copy()
            done = np.isfinite(u).all(axis=1)
        else:
            u, done = self._newton(origin, dirs, iterations, self._rest_solution(origin, dirs, iterations))
        ok = done & (u[:, 2] > 0)
        return np.where(ok, u[:, 2], np.inf), u[:, :2]

    def _rest_solution(self, origin: np.ndarray, dirs: np.ndarray, iterations: int) -> np.ndarray:
        """``(N, 3)`` (X, Y, s) where the undeformed skin meets the rays (NaN where it does not)."""
        key = (np.asarray(origin, float).tobytes(), id(dirs), dirs.shape)
        hit = self._rest.get(key)
        if hit is None or hit[0] is not dirs:   # the rays themselves are kept: their id stays theirs
            rest = Skin(self.texture, self.height, self.half_extent_m)
            u, done = rest._newton(origin, dirs, iterations, None)
            u = u.copy()
            u[~done] = np.nan
            if len(self._rest) >= 8:
                self._rest.pop(next(iter(self._rest)))
            hit = self._rest[key] = (dirs, u)
        return hit[1]

    def _newton(self, origin: np.ndarray, dirs: np.ndarray, iterations: int, start: np.ndarray | None,
                ) -> tuple[np.ndarray, np.ndarray]:
        """``(N, 3)`` (X, Y, s) and ``(N,)`` converged flags of Newton's iterations."""
        n = len(dirs)
        z0 = float(self.height(np.zeros(1), np.zeros(1))[0])
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z0 - origin[2]) / dirs[:, 2]
        p0 = origin + s[:, None] * dirs
        u = np.column_stack([p0[:, 0], p0[:, 1], s])
        active_ok = np.isfinite(s) & (s > 0)
        if start is not None:
            warm = np.isfinite(start).all(axis=1)
            u[warm] = start[warm]
            active_ok |= warm
        eps = 1e-7
        done = np.zeros(n, bool)
        active = np.flatnonzero(active_ok)
        for _ in range(iterations):
            if len(active) == 0:
                break
            ua, da = u[active], dirs[active]
            P, dX, dY = self._position_gradient(ua[:, 0], ua[:, 1], eps)
            F = P - origin - ua[:, 2:3] * da
            conv = np.all(np.abs(F) < 1e-11, axis=1)
            done[active[conv]] = True
            keep = ~conv
            active, ua, da, F = active[keep], ua[keep], da[keep], F[keep]
            if len(active) == 0:
                break
            a, b = dX[keep].T, dY[keep].T
            c, f = -da.T, F.T
            # Cramer's rule for the 3x3 systems [a b c] step = F, one per ray (by components:
            # a view solves some 10^6 of them per iteration)
            bxc = _cross(b, c)
            with np.errstate(all="ignore"):
                inv = 1.0 / _dot(a, bxc)
                step = np.stack([_dot(f, bxc) * inv, _dot(a, _cross(f, c)) * inv,
                                 _dot(a, _cross(b, f)) * inv], axis=1)
            good = np.isfinite(step).all(axis=1)
            u[active[good]] = ua[good] - step[good]
            active = active[good]
        return u, done

    def hit(self, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rays from ``origin`` (3,) along ``dirs`` (R, 3): depth (R,) [m], inf if missed; radiance (R,)."""
        depth, XY = self.intersect(origin, dirs)
        inside = (np.abs(XY[:, 0]) <= self.half_extent_m[0]) & (np.abs(XY[:, 1]) <= self.half_extent_m[1])
        rad = np.full(len(dirs), 0.5 * self.texture.background)
        rad[inside] = self.texture(XY[inside, 0], XY[inside, 1])
        return depth, rad


@dataclass
class Board:
    """A planar checkerboard: ``inner`` = (columns, rows) of inner corners, ``square_m`` [m],
    placed by ``R`` (board -> world rotation) and ``t`` [m] (board origin = first inner corner).
    Board coordinates of inner corner (i, j) are ``(i * square, j * square, 0)``.
    """

    inner: tuple[int, int] = (9, 6)
    square_m: float = 0.004
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    margin_squares: float = 0.7

    def object_points(self) -> np.ndarray:
        """``(cols * rows, 3)`` inner-corner board coordinates [m], row-major (x fastest)."""
        c, r = self.inner
        j, i = np.mgrid[0:r, 0:c]
        return np.column_stack([i.ravel(), j.ravel(), np.zeros(c * r)]) * self.square_m

    def corners_world(self) -> np.ndarray:
        """``(cols * rows, 3)`` inner corners in the world [m]."""
        return self.object_points() @ np.asarray(self.R).T + np.asarray(self.t)

    def hit(self, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rays from ``origin`` (3,) along ``dirs`` (R, 3): depth (R,) [m], inf if missed; radiance (R,)."""
        R = np.asarray(self.R, float)
        nrm = R[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = ((np.asarray(self.t) - origin) @ nrm) / (dirs @ nrm)
        p = origin + s[:, None] * dirs
        q = (p - self.t) @ R  # board coordinates
        a = q[:, 0] / self.square_m
        b = q[:, 1] / self.square_m
        c, r = self.inner
        m = self.margin_squares
        on_board = (a >= -1 - m) & (a <= c + m) & (b >= -1 - m) & (b <= r + m) & (s > 0)
        squares = (a >= -1) & (a < c) & (b >= -1) & (b < r)
        black = (np.floor(a).astype(np.int64) + np.floor(b).astype(np.int64)) % 2 == 0
        rad = np.where(squares & black, 0.08, 0.9)
        return np.where(on_board, s, np.inf), rad


@dataclass
class Cone:
    """The speckled conical indenter head (thesis 5.3), a rigid body.

    ``apex`` [m]; ``axis`` unit vector from the apex into the cone (towards its wide end,
    which faces the skin); ``half_angle_deg``; ``height_m`` along the axis. The probe tip
    lies on the axis ``tip_length_m`` from the apex: ``tip = apex + tip_length_m * axis``.
    """

    apex: np.ndarray
    axis: np.ndarray
    half_angle_deg: float = 40.0
    height_m: float = 0.006
    tip_length_m: float = 0.010
    texture: SolidSpeckle = field(default_factory=lambda: SolidSpeckle(cell=0.0005, seed=7))

    def __post_init__(self) -> None:
        self.apex = np.asarray(self.apex, float)
        self.axis = np.asarray(self.axis, float) / np.linalg.norm(self.axis)

    @property
    def tip(self) -> np.ndarray:
        """``(3,)`` probe tip position [m]."""
        return self.apex + self.tip_length_m * self.axis

    def _body(self, p: np.ndarray) -> np.ndarray:
        # Body coordinates: any fixed frame bound to the cone; speckle moves with it.
        from skinkit.vision.rigs import look_at

        B = look_at(np.zeros(3), self.axis, up=(0.3, 0.5, 0.81))
        return (p - self.apex) @ B.T

    def hit(self, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rays from ``origin`` (3,) along ``dirs`` (R, 3): depth (R,) [m], inf if missed; radiance (R,)."""
        n = self.axis
        c2 = np.cos(np.deg2rad(self.half_angle_deg)) ** 2
        w = origin - self.apex
        dv = dirs @ n
        wv = float(w @ n)
        A = dv**2 - c2
        B = 2 * (dv * wv - c2 * (dirs @ w))
        C = wv**2 - c2 * float(w @ w)
        disc = B**2 - 4 * A * C
        depth = np.full(len(dirs), np.inf)
        with np.errstate(invalid="ignore", divide="ignore"):
            sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
            for s in ((-B - sq) / (2 * A), (-B + sq) / (2 * A)):
                h = wv + s * dv
                good = np.isfinite(s) & (s > 0) & (h >= 0) & (h <= self.height_m) & (s < depth)
                depth = np.where(good, s, depth)
            # The flat top of the cone closes it (plain, dark).
            s_cap = (self.height_m - wv) / dv
            pc = origin + s_cap[:, None] * dirs - self.apex
            rcap = np.linalg.norm(pc - np.outer(pc @ n, n), axis=1)
            cap = np.isfinite(s_cap) & (s_cap > 0) & (rcap <= self.height_m * np.tan(np.deg2rad(
                self.half_angle_deg))) & (s_cap < depth)
        depth = np.where(cap, s_cap, depth)
        rad = np.full(len(dirs), 0.1)
        side = np.isfinite(depth) & ~cap
        p = origin + depth[side, None] * dirs[side]
        rad[side] = self.texture(self._body(p))
        return depth, rad

    def surface_points(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``(n, 3)`` random points on the lateral surface [m] (for tests of the fit)."""
        h = self.height_m * np.sqrt(rng.uniform(0.05, 1, n))
        th = rng.uniform(0, 2 * np.pi, n)
        from skinkit.vision.rigs import look_at

        B = look_at(np.zeros(3), self.axis, up=(0.3, 0.5, 0.81))
        r = h * np.tan(np.deg2rad(self.half_angle_deg))
        local = np.column_stack([r * np.cos(th), r * np.sin(th), h])
        return self.apex + local @ B


@dataclass
class Markers:
    """Small fluorescent spheres of ``radius_m`` [m] centred at ``centres`` ``(M, 3)`` [m]."""

    centres: np.ndarray
    radius_m: float = 0.0003
    brightness: float = 1.0

    def hit(self, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rays from ``origin`` (3,) along ``dirs`` (R, 3): depth (R,) [m], inf if missed; radiance (R,)."""
        depth = np.full(len(dirs), np.inf)
        for c in np.asarray(self.centres, float):
            w = origin - c
            b = dirs @ w
            disc = b**2 - (float(w @ w) - self.radius_m**2)
            with np.errstate(invalid="ignore"):
                s = -b - np.sqrt(np.where(disc >= 0, disc, np.nan))
            good = np.isfinite(s) & (s > 0) & (s < depth)
            depth = np.where(good, s, depth)
        return depth, np.full(len(dirs), self.brightness)


#: a camera's rays cost about half of a rendered view (measured: 0.48 s of 0.57 s for a
#: 480 x 384 view at supersample 2), and a rig renders the same cameras frame after frame: the
#: last few are kept, least recently used first out, within a memory budget
_RAY_CACHE: OrderedDict[tuple, tuple[np.ndarray, np.ndarray]] = OrderedDict()
RAY_CACHE_ENTRIES = 8
RAY_CACHE_BYTES = 256 * 2**20


def _read_only(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)  # shared by every caller: nobody may change it under the others
    return a


def _camera_rays(cam: CameraModel, supersample: int) -> tuple[np.ndarray, np.ndarray]:
    """``(origin (3,), directions (H W s², 3))`` of ``cam``'s pixels, cached read-only."""
    # exact key: the camera's bytes and integers (no float rounding decides a hit)
    key = (cam.name, cam.K.tobytes(), cam.distortion.tobytes(), cam.R.tobytes(), cam.t.tobytes(),
           tuple(int(v) for v in cam.image_size), int(supersample))
    rays = _RAY_CACHE.get(key)
    if rays is not None:
        _RAY_CACHE.move_to_end(key)
        return rays
    origin, dirs = cam_ops.rays(cam, cam_ops.pixel_grid(cam.image_size, supersample))
    rays = (_read_only(np.array(origin, float)), _read_only(np.asarray(dirs, float)))
    _RAY_CACHE[key] = rays
    while len(_RAY_CACHE) > 1 and (len(_RAY_CACHE) > RAY_CACHE_ENTRIES or sum(
            o.nbytes + d.nbytes for o, d in _RAY_CACHE.values()) > RAY_CACHE_BYTES):
        _RAY_CACHE.popitem(last=False)
    return rays


def radiance(cam: CameraModel, objects: Sequence[object], supersample: int = 2) -> np.ndarray:
    """``(H, W)`` radiance [0..1]: nearest object hit along ``supersample**2`` rays per pixel."""
    if supersample < 1:
        raise VisionError(f"supersample must be >= 1, got {supersample}")
    origin, dirs = _camera_rays(cam, supersample)
    depth = np.full(len(dirs), np.inf)
    rad = np.full(len(dirs), BACKGROUND)
    for obj in objects:
        d, r = obj.hit(origin, dirs)  # type: ignore[attr-defined]
        nearer = d < depth
        depth = np.where(nearer, d, depth)
        rad = np.where(nearer, r, rad)
    w, h = cam.image_size
    return rad.reshape(h, w, supersample * supersample).mean(axis=2)


def render_view(cam: CameraModel, objects: Sequence[object], sensor: Sensor,
                rng: np.random.Generator | int | None, supersample: int = 2) -> np.ndarray:
    """The quantised image ``(H, W)`` camera ``cam`` takes of ``objects``."""
    return sensor.expose(radiance(cam, objects, supersample), rng)


def hit_mask(cam: CameraModel, objects: Sequence[object], which: int) -> np.ndarray:
    """``(H, W)`` bool: pixels whose centre ray hits ``objects[which]`` first (e.g. the
    region of interest around the indenter cone)."""
    origin, dirs = _camera_rays(cam, 1)
    depth = np.full(len(dirs), np.inf)
    owner = np.full(len(dirs), -1)
    for k, obj in enumerate(objects):
        d, _ = obj.hit(origin, dirs)  # type: ignore[attr-defined]
        nearer = d < depth
        depth = np.where(nearer, d, depth)
        owner = np.where(nearer, k, owner)
    w, h = cam.image_size
    return (owner == which).reshape(h, w)


def visible(cam: CameraModel, objects: Sequence[object], X: np.ndarray, tol_m: float = 1e-6) -> np.ndarray:
    """``(N,)`` bool: world points ``X`` [m] that are in the image and not hidden by ``objects``."""
    X = np.asarray(X, float)
    px = cam_ops.project(cam, X)
    w, h = cam.image_size
    inside = np.all(np.isfinite(px), axis=1) & (px[:, 0] >= -0.5) & (px[:, 1] >= -0.5) & \
        (px[:, 0] <= w - 0.5) & (px[:, 1] <= h - 0.5)
    d = X - cam.centre
    dist = np.linalg.norm(d, axis=1)
    dirs = d / dist[:, None]
    nearest = np.full(len(X), np.inf)
    for obj in objects:
        nearest = np.minimum(nearest, obj.hit(cam.centre, dirs)[0])  # type: ignore[attr-defined]
    return inside & (nearest >= dist - tol_m)


@dataclass
class CharucoTarget:
    """A ChArUco board (OpenCV ``aruco.CharucoBoard``) placed in the world.

    ``squares``: (columns, rows) of squares; ``square_m``, ``marker_m`` [m]; ``dictionary``:
    an ``cv2.aruco.DICT_*`` name. Board coordinates follow OpenCV: origin at the outer
    top-left corner, x along a row, y down the printed image, z into the board, so the
    printed face is seen from -z. ``R`` (board -> world) and ``t`` [m] place it.
    """

    squares: tuple[int, int] = (8, 6)
    square_m: float = 0.004
    marker_m: float = 0.003
    dictionary: str = "DICT_4X4_50"
    R: np.ndarray = field(default_factory=lambda: np.diag([1.0, -1.0, -1.0]))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    px_per_square: int = 60

    def cv_board(self) -> object:
        """The OpenCV ``aruco.CharucoBoard`` of this target."""
        import cv2

        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(tuple(self.squares), self.square_m, self.marker_m, d)

    def object_points(self) -> np.ndarray:
        """``(P, 3)`` chessboard-corner board coordinates [m], in ChArUco id order."""
        return np.asarray(self.cv_board().getChessboardCorners(), float).reshape(-1, 3)  # type: ignore[attr-defined]

    def corners_world(self) -> np.ndarray:
        """``(P, 3)`` chessboard-corner world coordinates [m], in ChArUco id order."""
        return self.object_points() @ np.asarray(self.R).T + np.asarray(self.t)

    def _image(self) -> np.ndarray:
        """The printed board ``(rows px, columns px)`` in [0, 1], cached read-only."""
        c, r = (int(v) for v in self.squares)
        # exact key: a float length by its exact integer ratio, never by rounding
        return _charuco_image((c, r), float(self.square_m).as_integer_ratio(),
                              float(self.marker_m).as_integer_ratio(), str(self.dictionary),
                              int(self.px_per_square))

    def hit(self, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rays from ``origin`` (3,) along ``dirs`` (R, 3): depth (R,) [m], inf if missed; radiance (R,)."""
        from scipy.ndimage import map_coordinates

        R = np.asarray(self.R, float)
        nrm = R[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = ((np.asarray(self.t) - origin) @ nrm) / (dirs @ nrm)
        q = (origin + s[:, None] * dirs - self.t) @ R
        scale = self.px_per_square / self.square_m
        col = q[:, 0] * scale - 0.5
        row = q[:, 1] * scale - 0.5
        img = self._image()
        h, w = img.shape
        m = 0.5 * self.px_per_square  # white margin of half a square
        on = (s > 0) & (col >= -m) & (col <= w - 1 + m) & (row >= -m) & (row <= h - 1 + m)
        rad = np.full(len(dirs), 0.9)
        inside = on & (col >= 0) & (col <= w - 1) & (row >= 0) & (row <= h - 1)
        rad[inside] = 0.08 + 0.82 * map_coordinates(img, [row[inside], col[inside]], order=1)
        return np.where(on, s, np.inf), rad


@functools.lru_cache(maxsize=4)  # a scene holds one or two boards; each image is ~1 MB
def _charuco_image(squares: tuple[int, int], square: tuple[int, int], marker: tuple[int, int],
                   dictionary: str, px_per_square: int) -> np.ndarray:
    board = CharucoTarget(squares, square[0] / square[1], marker[0] / marker[1], dictionary,
                          px_per_square=px_per_square).cv_board()
    img = board.generateImage((squares[0] * px_per_square, squares[1] * px_per_square),  # type: ignore[attr-defined]
                              marginSize=0, borderBits=1)
    return _read_only(np.asarray(img, float) / 255.0)



@dataclass
class GroundTruth:
    """Exact truth for chosen material points: ``points`` ``(N, 3)`` [m], ``pixels``
    ``(N, C, 2)`` [px] in every camera, ``visible`` ``(N, C)`` (in the image, not hidden)."""

    points: np.ndarray
    pixels: np.ndarray
    visible: np.ndarray


def ground_truth(rig: object, skin: Skin, XY: np.ndarray, objects: Sequence[object] | None = None,
                 ) -> GroundTruth:
    """Where the material points ``XY`` ``(N, 2)`` [m] of ``skin`` (in its current state)
    are in 3D and in each camera of ``rig``; ``objects`` (default: the skin alone) may hide
    them."""
    XY = np.asarray(XY, float).reshape(-1, 2)
    X = skin.position(XY[:, 0], XY[:, 1])
    cams = rig.cameras  # type: ignore[attr-defined]
    px = np.stack([cam_ops.project(c, X) for c in cams], axis=1)
    objs = list(objects) if objects is not None else [skin]
    vis = np.stack([visible(c, objs, X, tol_m=1e-6) for c in cams], axis=1)
    return GroundTruth(X, px, vis)
