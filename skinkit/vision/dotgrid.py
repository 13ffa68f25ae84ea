"""Dot-grid calibration targets as DIC labs use them, rendered with exact ground truth.

A :class:`DotGrid` is a plate of dark dots on white paper: ``cols x rows`` dots on a square
lattice of ``pitch_m`` (OpenCV's symmetric circle grid) or staggered rows (OpenCV's asymmetric
circle grid, :attr:`DotGrid.asymmetric`). A few dots may be *fiducials* -- hollow rings (the
Correlated Solutions style) or larger dots (the LaVision style) -- placed so that no symmetry
of the lattice maps them onto themselves: they then fix the grid's origin and orientation in
every view, even on a grid that looks the same after half a turn (14 x 10) or a quarter turn
(10 x 10). Without fiducials a symmetric grid's half turn is left to the rig
(:mod:`skinkit.vision.board_symmetry`).

Board coordinates follow :class:`skinkit.vision.scene.Board`: dot ``(i, j)`` (column ``i``,
row ``j``) is at ``(i * pitch, j * pitch, 0)`` (asymmetric: ``((2 i + j % 2) * pitch,
j * pitch, 0)``, OpenCV's convention, so a row's dots are ``2 * pitch`` apart), points are
numbered row by row (``k = j * cols + i``), the printed face is on the +z side; ``R`` (board ->
world) and ``t`` [m] (world position of dot (0, 0)) place the plate.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from skinkit.vision import VisionError

PAPER = 0.9  # radiance of the plate
INK = 0.08   # radiance of a dot
FIDUCIAL_KINDS = ("hollow", "large")

#: the default fiducials: an L of three dots next to dot (0, 0) -- its corner at (1, 1), one arm
#: along +x, one along +y. Three dots in an L fix both the origin and the handedness-free
#: orientation on any lattice of at least 4 x 4 dots.
DEFAULT_FIDUCIALS: tuple[tuple[int, int], ...] = ((1, 1), (2, 1), (1, 2))


@dataclass
class DotGrid:
    """A dot-grid plate.

    Attributes:
        cols, rows: dots per row and per column [1].
        pitch_m: lattice step [m] (asymmetric grid: the row spacing; a row's dots are
            ``2 * pitch_m`` apart, OpenCV's ``squareSize``).
        dot_diameter_m: diameter of an ordinary dot [m].
        fiducials: ``(i, j)`` grid indices of the fiducial dots (empty: a plain grid).
        fiducial_kind: ``"hollow"`` (a ring whose hole is ``hole_ratio`` of its diameter) or
            ``"large"`` (a dot ``large_ratio`` times the ordinary diameter).
        R, t: board -> world rotation and world position [m] of dot (0, 0).
        margin_pitches: white margin around the outer dots [pitches].
    """

    cols: int = 14
    rows: int = 10
    pitch_m: float = 0.002
    dot_diameter_m: float = 0.001
    fiducials: tuple[tuple[int, int], ...] = DEFAULT_FIDUCIALS
    fiducial_kind: str = "hollow"
    hole_ratio: float = 0.5
    large_ratio: float = 1.5
    asymmetric: bool = False
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    margin_pitches: float = 1.0

    def __post_init__(self) -> None:
        self.cols, self.rows = int(self.cols), int(self.rows)
        self.fiducials = tuple((int(i), int(j)) for i, j in self.fiducials)
        check_grid(self)

    @property
    def size(self) -> tuple[int, int]:
        """``(cols, rows)``: OpenCV's ``patternSize``."""
        return self.cols, self.rows

    def object_points(self) -> np.ndarray:
        """``(cols * rows, 3)`` dot centres in board coordinates [m], row by row."""
        j, i = np.mgrid[0:self.rows, 0:self.cols]
        x = 2 * i + j % 2 if self.asymmetric else i
        return np.column_stack([x.ravel(), j.ravel(), np.zeros(i.size)]) * self.pitch_m

    def corners_world(self) -> np.ndarray:
        """``(cols * rows, 3)`` dot centres in the world [m]."""
        return self.object_points() @ np.asarray(self.R, float).T + np.asarray(self.t, float)

    def fiducial_indices(self) -> np.ndarray:
        """Point numbers ``j * cols + i`` of the fiducials, sorted."""
        return np.array(sorted(j * self.cols + i for i, j in self.fiducials), int)

    def ink_ratio(self) -> float:
        """A fiducial's ink (dark area) relative to an ordinary dot's [1]: what tells it apart
        in an image whatever the blur (blur moves ink, it does not create or destroy it)."""
        if self.fiducial_kind == "hollow":
            return 1.0 - self.hole_ratio**2
        return self.large_ratio**2

    def hit(self, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ray parameter ``(N,)`` [m] (inf where the plate is missed) and radiance ``(N,)``."""
        R = np.asarray(self.R, float)
        nrm = R[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = ((np.asarray(self.t, float) - origin) @ nrm) / (dirs @ nrm)
        q = (origin + s[:, None] * dirs - self.t) @ R  # board coordinates [m]
        a, b = q[:, 0] / self.pitch_m, q[:, 1] / self.pitch_m
        j = np.rint(b).astype(np.int64)
        # a dot's radius is below half a pitch, so the nearest row and column hold the dot
        i = np.rint((a - j % 2) / 2).astype(np.int64) if self.asymmetric else np.rint(a).astype(np.int64)
        xc = 2 * i + j % 2 if self.asymmetric else i
        r = np.hypot(a - xc, b - j) * self.pitch_m
        on_lattice = (i >= 0) & (i < self.cols) & (j >= 0) & (j < self.rows)
        fid = np.zeros((self.rows, self.cols), bool)
        for fi, fj in self.fiducials:
            fid[fj, fi] = True
        is_fid = on_lattice & fid[np.clip(j, 0, self.rows - 1), np.clip(i, 0, self.cols - 1)]
        radius = np.full(len(dirs), self.dot_diameter_m / 2)
        hole = np.zeros(len(dirs))
        if self.fiducial_kind == "large":
            radius[is_fid] *= self.large_ratio
        else:
            hole[is_fid] = self.hole_ratio * self.dot_diameter_m / 2
        dark = on_lattice & (r <= radius) & (r >= hole)
        xmax = (2 * self.cols - 1) if self.asymmetric else (self.cols - 1)
        m = self.margin_pitches
        on_plate = (s > 0) & (a >= -m) & (a <= xmax + m) & (b >= -m) & (b <= self.rows - 1 + m)
        rad = np.where(dark, INK, PAPER)
        return np.where(on_plate, s, np.inf), rad


def check_grid(grid: DotGrid) -> None:
    """:class:`VisionError` unless ``grid`` is a detectable, drawable dot grid whose fiducials
    (if any) fix its orientation."""
    c, r = grid.cols, grid.rows
    if c < 3 or r < 3:
        raise VisionError(f"dot grid of {c}x{r} dots is too small (need at least 3x3)")
    if not (grid.pitch_m > 0 and grid.dot_diameter_m > 0):
        raise VisionError(f"dot grid pitch and dot diameter must be positive, got {grid.pitch_m} m "
                          f"and {grid.dot_diameter_m} m")
    if grid.fiducial_kind not in FIDUCIAL_KINDS:
        raise VisionError(f"fiducial kind {grid.fiducial_kind!r}: expected {' or '.join(FIDUCIAL_KINDS)}")
    biggest = grid.dot_diameter_m * (grid.large_ratio if grid.fiducials and grid.fiducial_kind == "large"
                                     else 1.0)
    if biggest >= grid.pitch_m:
        raise VisionError(f"dots of {biggest * 1e3:g} mm overlap at a pitch of {grid.pitch_m * 1e3:g} mm")
    if grid.fiducial_kind == "hollow" and not 0.2 <= grid.hole_ratio <= 0.8:
        raise VisionError(f"hollow fiducials: hole ratio {grid.hole_ratio} outside [0.2, 0.8]")
    if grid.fiducial_kind == "large" and not grid.large_ratio >= 1.2:
        raise VisionError(f"large fiducials: diameter ratio {grid.large_ratio} below 1.2")
    bad = [f for f in grid.fiducials if not (0 <= f[0] < c and 0 <= f[1] < r)]
    if bad:
        raise VisionError(f"fiducial(s) {', '.join(f'{i},{j}' for i, j in bad)} outside the {c}x{r} grid")
    if len(set(grid.fiducials)) != len(grid.fiducials):
        raise VisionError("fiducial positions repeat")
    rots = [p for p, det in symmetries(grid) if det > 0]
    if grid.fiducials:
        fid = set(grid.fiducial_indices().tolist())
        same = [p for p in rots[1:] if {int(p[k]) for k in fid} == fid]
        if same:
            raise VisionError(f"fiducials {' '.join(f'{i},{j}' for i, j in grid.fiducials)} look the same "
                              f"after a turn of the {c}x{r} grid: place them asymmetrically (e.g. an L "
                              "near one corner)")
    elif len(rots) > 2:
        raise VisionError(f"a {c}x{r} dot grid without fiducials looks the same after a quarter turn: "
                          "its orientation is ambiguous; give it fiducials")
    elif len(rots) == 2 and grid.asymmetric:
        raise VisionError(f"an asymmetric {c}x{r} dot grid with an even number of rows looks the same "
                          "after a half turn: use an odd number of rows (e.g. 4x11) or fiducials")


def symmetries(grid: DotGrid) -> list[tuple[np.ndarray, float]]:
    """The lattice's symmetries: ``(perm, det)`` pairs, ``perm`` ``(P,)`` such that point ``k``
    goes to point ``perm[k]``, ``det`` +1 for a turn, -1 for a mirror. The identity comes first."""
    obj = grid.object_points()[:, :2] / grid.pitch_m
    centre = (obj.min(axis=0) + obj.max(axis=0)) / 2
    rel = obj - centre
    key = {tuple(np.rint(2 * p).astype(int)): k for k, p in enumerate(rel)}
    out = []
    for swap in (False, True):
        for sx in (1, -1):
            for sy in (1, -1):
                A = np.array([[0, sy], [sx, 0]]) if swap else np.diag([sx, sy])
                moved = rel @ A.T
                perm = [key.get(tuple(np.rint(2 * p).astype(int))) for p in moved]
                if all(v is not None for v in perm):
                    out.append((np.array(perm, int), float(np.linalg.det(A))))
    return out


def random_grid_poses(n: int, rng: np.random.Generator, grid: DotGrid, tilt_deg: float = 25.0,
                      shift_m: float = 0.006, lift_m: tuple[float, float] = (0.0, 0.012)) -> list[DotGrid]:
    """``n`` placements of ``grid`` as :func:`skinkit.vision.boards.random_board_poses` places a
    checkerboard with the same points (the first flat and centred: the world frame)."""
    from skinkit.vision.boards import random_board_poses
    from skinkit.vision.scene import Board

    # a checkerboard of (2 cols - 1) x rows corners spans the asymmetric grid's points
    width = 2 * grid.cols - 1 if grid.asymmetric else grid.cols
    proxy = Board((width, grid.rows), grid.pitch_m)
    return [replace(grid, R=b.R, t=b.t) for b in random_board_poses(n, rng, proxy, tilt_deg, shift_m, lift_m)]


def parse_fiducials(text: str) -> tuple[str, tuple[tuple[int, int], ...]]:
    """``(kind, positions)`` from a fiducial specification: ``none``; ``hollow`` or ``large``
    (the default L, :data:`DEFAULT_FIDUCIALS`); or ``KIND:I,J;I,J;...`` with the grid indices
    (column ``I``, row ``J``, from 0) of the fiducial dots, e.g. ``hollow:1,1;2,1;1,2``."""
    kind, _, where = text.strip().partition(":")
    kind = kind.strip().lower()
    if kind == "none" and not where:
        return "hollow", ()
    if kind not in FIDUCIAL_KINDS:
        raise VisionError(f"fiducials {text!r}: expected none, {' or '.join(FIDUCIAL_KINDS)}, optionally "
                          "followed by :I,J;I,J;... (grid column, row from 0), e.g. hollow:1,1;2,1;1,2")
    if not where.strip():
        return kind, DEFAULT_FIDUCIALS
    try:
        pos = tuple((int(a), int(b)) for a, b in (p.split(",") for p in where.split(";") if p.strip()))
    except ValueError:
        raise VisionError(f"fiducials {text!r}: positions must be I,J pairs separated by ';', "
                          "e.g. hollow:1,1;2,1;1,2") from None
    if not pos:
        raise VisionError(f"fiducials {text!r}: no positions after ':'")
    return kind, pos
