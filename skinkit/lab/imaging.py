"""The virtual lab's cameras: what four synchronised cameras take of a truth's speckled skin.

The truth follows a square grid of material points of its top surface (1 mm apart over its
whole disc); at every camera trigger the surface's displacement between those points is
interpolated by bicubic splines (zero beyond the disc: its rim is fixed), the speckled surface
is deformed by it and rendered by each camera of the rig (:mod:`skinkit.vision.scene`: exact
ray casting through the distorted camera model, 2 x 2 rays per pixel, sensor noise and
quantisation). Calibration is imaged as a lab does it: a 9 x 6 checkerboard of 3 mm squares in
16 placements, the first lying flat and centred on the probe's axis — it defines the world frame
the calibration reports, ``BOARD_ORIGIN_M`` from the skin frame's origin. The probe is left out
of the views (the tracked points stay 1 mm clear of it).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from skinkit.schemas import CameraRig, ImageSequence

#: mild barrel distortion with a little decentring, as a 6 mm machine-vision lens
DISTORTION = (-0.08, 0.03, 0.0005, -0.0003, 0.0)
BOARD_INNER = (9, 6)
BOARD_SQUARE_M = 0.003
#: the flat first board's origin (its first inner corner) in the skin frame: centred on the probe
BOARD_ORIGIN_M = np.array([-(BOARD_INNER[0] - 1) / 2 * BOARD_SQUARE_M,
                           -(BOARD_INNER[1] - 1) / 2 * BOARD_SQUARE_M, 0.0])
#: speckle: 0.45 mm cells over 50 mm x 50 mm of skin
SPECKLE_CELL_M = 0.00045
SPECKLE_HALF_M = (0.025, 0.025)
GRID_SPACING_M = 1e-3
#: spacing [m] of the table the interpolated displacement is read from while ray casting
TABLE_SPACING_M = 1e-4
#: the sensor: 1 % noise, 20 % vignetting
SENSOR_NOISE = 0.01
SENSOR_FALLOFF = 0.2


def followed_grid(radius_m: float, height: Callable[[np.ndarray], np.ndarray],
                  spacing_m: float = GRID_SPACING_M) -> tuple[np.ndarray, np.ndarray]:
    """The square grid ``(n,)`` [m] of both axes and the material points ``(P, 3)`` [m] of it
    strictly inside the disc of ``radius_m``, lifted on the surface by ``height(xy (P, 2))``."""
    k = int(np.floor(radius_m / spacing_m + 1e-9))
    g = np.arange(-k, k + 1) * spacing_m
    X, Y = np.meshgrid(g, g, indexing="ij")
    xy = np.column_stack([X.ravel(), Y.ravel()])
    xy = xy[np.hypot(xy[:, 0], xy[:, 1]) < radius_m - 1e-9]
    return g, np.column_stack([xy, height(xy)])


def displacement_field(grid: np.ndarray, points: np.ndarray, displacement: np.ndarray,
                       table_spacing_m: float = TABLE_SPACING_M
                       ) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``u(X, Y) -> (N, 3)`` [m]: bicubic interpolation of ``displacement`` ``(P, 3)`` [m] at the
    grid's ``points`` ``(P, 3)``; zero at grid nodes outside the disc and beyond the grid.

    The spline is tabulated once every ``table_spacing_m`` and read bilinearly: ray casting
    evaluates the field some 10^7 times per view, and the table's error (h²/8 times the
    field's curvature, below 10 nm here) is far below anything a camera resolves.
    """
    from scipy.interpolate import RectBivariateSpline

    n = grid.size
    idx = np.rint((points[:, :2] - grid[0]) / (grid[1] - grid[0])).astype(int)
    lo, hi = float(grid[0]), float(grid[-1])
    m = int(np.ceil((hi - lo) / table_spacing_m)) + 1
    fine = np.linspace(lo, hi, m)
    h = fine[1] - fine[0]
    table = np.zeros((m, m, 3))
    for c in range(3):
        full = np.zeros((n, n))
        full[idx[:, 0], idx[:, 1]] = displacement[:, c]
        table[:, :, c] = RectBivariateSpline(grid, grid, full, kx=3, ky=3)(fine, fine)
    flat = table.reshape(m * m, 3)

    def cells(X: np.ndarray, Y: np.ndarray):
        X = np.ravel(X)
        Y = np.ravel(Y)
        inside = (X >= lo) & (X <= hi) & (Y >= lo) & (Y <= hi)
        fx = (X[inside] - lo) / h
        fy = (Y[inside] - lo) / h
        i = np.minimum(fx.astype(int), m - 2)
        j = np.minimum(fy.astype(int), m - 2)
        k = i * m + j                  # flat gathers: a view samples the table ~10^6 times
        corners = (flat.take(k, axis=0), flat.take(k + 1, axis=0), flat.take(k + m, axis=0),
                   flat.take(k + m + 1, axis=0))
        return X.size, inside, (fx - i)[:, None], (fy - j)[:, None], corners

    def u(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        n, inside, a, b, (f00, f01, f10, f11) = cells(X, Y)
        out = np.zeros((n, 3))
        out[inside] = (1 - a) * ((1 - b) * f00 + b * f01) + a * ((1 - b) * f10 + b * f11)
        return out

    def gradient(X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """u and its derivatives along X and Y, each ``(N, 3)``, from one set of gathers."""
        n, inside, a, b, (f00, f01, f10, f11) = cells(X, Y)
        out, dx, dy = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
        lo_b, hi_b = f00 + b * (f01 - f00), f10 + b * (f11 - f10)
        out[inside] = lo_b + a * (hi_b - lo_b)
        dx[inside] = (hi_b - lo_b) / h
        dy[inside] = ((1 - a) * (f01 - f00) + a * (f11 - f10)) / h
        return out, dx, dy

    u.gradient = gradient  # type: ignore[attr-defined]
    return u


@dataclass
class Cameras:
    """The rig, its sensor and the undeformed speckled skin (truth; the chain never reads it)."""

    rig: CameraRig
    sensor: object
    skin: object

    @classmethod
    def make(cls, height: Callable[[np.ndarray, np.ndarray], np.ndarray], seed: int) -> Cameras:
        """The thesis's ring of four cameras over skin of ``height(X, Y)`` [m] speckled with seed ``seed``."""
        from skinkit.vision import scene
        from skinkit.vision.rigs import ring_rig
        from skinkit.vision.sensor import Sensor
        from skinkit.vision.texture import SpeckleTexture

        skin = scene.Skin(SpeckleTexture(cell=SPECKLE_CELL_M, seed=seed), height, SPECKLE_HALF_M)
        return cls(ring_rig(distortion=list(DISTORTION)), Sensor(noise=SENSOR_NOISE, falloff=SENSOR_FALLOFF),
                   skin)

    def boards(self, seed: int, n: int = 16) -> ImageSequence:
        """``n`` checkerboard placements (the first flat, centred on the probe's axis)."""
        from skinkit.vision import boards, scene

        rng = np.random.default_rng(seed)
        board = scene.Board(inner=BOARD_INNER, square_m=BOARD_SQUARE_M)
        poses = boards.random_board_poses(n, rng, board, tilt_deg=40, lift_m=(-0.01, 0.01))
        views = boards.board_views(self.rig, poses, self.sensor, seed=int(rng.integers(2**31)))
        return ImageSequence("calibration", views, self.rig.names, np.arange(len(views), dtype=float))

    def cast(self, field: Callable[[np.ndarray, np.ndarray], np.ndarray] | None) -> np.ndarray:
        """``(C, H, W)`` radiance of the skin under the displacement ``field`` (``None``: at rest)
        in each camera: the ray casting, the costly part of a view (seconds per camera)."""
        from skinkit.vision import scene

        skin = self.skin if field is None else self.skin.deformed(field)  # type: ignore[attr-defined]
        return np.stack([scene.radiance(cam, [skin]) for cam in self.rig.cameras])

    def expose(self, radiances: Sequence[np.ndarray], rng: np.random.Generator) -> np.ndarray:
        """``(F, C, H, W)`` images: each frame's radiance ``(C, H, W)`` exposed by the sensor,
        frame by frame and camera by camera from ``rng`` (a fresh noise draw per exposure)."""
        out = None
        for f, rad in enumerate(radiances):
            for c in range(len(rad)):
                img = self.sensor.expose(rad[c], rng)  # type: ignore[attr-defined]
                if out is None:
                    out = np.zeros((len(radiances), *rad.shape[:1], *img.shape), img.dtype)
                out[f, c] = img
        assert out is not None
        return out

    def views(self, fields: Sequence[Callable[[np.ndarray, np.ndarray], np.ndarray] | None],
              rng: np.random.Generator, progress: Callable[[float], None] | None = None) -> np.ndarray:
        """``(F, C, H, W)`` images of the skin under each displacement field (``None``: at rest);
        the rest state, and a field repeated in consecutive frames, are ray-cast once and
        exposed afresh per frame."""
        rest: np.ndarray | None = None
        # a field repeated in the next frame (a still skin, seen twice) is ray-cast once; only
        # the sensor's noise differs between the two exposures
        last: tuple[object, np.ndarray | None] = (object(), None)
        rads = []
        for f, field in enumerate(fields):
            if field is None:
                if rest is None:
                    rest = self.cast(None)
                rads.append(rest)
            else:
                if field is not last[0]:
                    last = (field, self.cast(field))
                rads.append(last[1])
            if progress:
                progress((f + 1) / len(fields))
        return self.expose(rads, rng)


def displacements(followed: np.ndarray, points: np.ndarray) -> list[np.ndarray | None]:
    """The displacement ``(P, 3)`` [m] of the grid's ``points`` ``(P, 3)`` in each frame of
    ``followed`` ``(P, F, 3)``; ``None`` where nothing has moved (an exact rest view)."""
    out: list[np.ndarray | None] = []
    for f in range(followed.shape[1]):
        u = followed[:, f] - points
        out.append(None if np.abs(u).max() < 1e-12 else u)
    return out


def protocol_images(cams: Cameras, name: str, times: np.ndarray, grid: np.ndarray, points: np.ndarray,
                    followed: np.ndarray, rng: np.random.Generator,
                    progress: Callable[[float], None] | None = None) -> ImageSequence:
    """The image sequence ``name`` of one protocol: a frame per trigger time ``times`` ``(F,)`` [s],
    the skin displaced by ``followed - points`` (``followed``: ``(P, F, 3)`` [m] positions of the
    grid's ``points`` ``(P, 3)``); frames where nothing has moved are exact rest views."""
    fields = [None if u is None else displacement_field(grid, points, u)
              for u in displacements(followed, points)]
    frames = cams.views(fields, rng, progress)
    return ImageSequence(name, frames, cams.rig.names, np.asarray(times, float))


def noise_pair(cams: Cameras, rng: np.random.Generator, grid: np.ndarray | None = None,
               points: np.ndarray | None = None, rest: np.ndarray | None = None) -> ImageSequence:
    """Two frames of the skin at rest (``"noise-floor"``): what the tracker reads as motion
    between them is its noise, the level a lab measures before a session. ``rest`` ``(P, 3)``
    [m]: where the grid's ``points`` are at rest (a pre-stressed skin is not in its reference
    state); default the reference state."""
    field = None
    if rest is not None and np.abs(rest - points).max() > 0:
        field = displacement_field(grid, points, rest - points)
    return ImageSequence("noise-floor", cams.views([field, field], rng), cams.rig.names, [0.0, 1.0])


__all__ = ["BOARD_INNER", "BOARD_ORIGIN_M", "BOARD_SQUARE_M", "Cameras", "displacement_field",
           "displacements", "followed_grid", "noise_pair", "protocol_images"]
