"""A virtual stereoscope session: rendered board views and a speckled forearm, with the truth.

The thesis's rig (4 cameras on a 125 mm ring at 55°, mild lens distortion) images a 9 x 6
checkerboard of 3 mm squares in 16 poses (the first flat, defining the world frame), then a
speckled forearm (35 mm radius) undeformed and indented: a 0.6 mm Gaussian dimple (σ = 8 mm)
with 1 % / −0.5 % in-plane stretch. The probe is left out of the view so that every step
runs without masks; :mod:`skinkit.vision.scene` renders it when wanted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from skinkit.schemas import CameraRig, ImageSequence

#: mild barrel distortion with a little decentring, as a 6 mm machine-vision lens
DISTORTION = (-0.08, 0.03, 0.0005, -0.0003, 0.0)
BOARD_INNER = (9, 6)
BOARD_SQUARE_M = 0.003
ARM_RADIUS_M = 0.035


def indentation(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Displacement ``(N, 3)`` [m] of material points ``(X, Y)`` [m] in the indented state."""
    r2 = X**2 + Y**2
    return np.column_stack([0.01 * X, -0.005 * Y, -0.0006 * np.exp(-r2 / (2 * 0.008**2))])


@dataclass
class StereoSession:
    """The rendered session and its truth.

    Attributes:
        rig: the true camera rig.
        boards: ``(16, 4, H, W)`` board views, as :class:`ImageSequence` ``"calibration"``.
        skin: ``(2, 4, H, W)`` forearm views (undeformed, indented), sequence ``"indentation"``.
        undeformed, indented: :class:`skinkit.vision.scene.Skin` in each state (the truth).
        board0_R, board0_t: pose of the first (flat) board in the rendering frame; a
            calibration from these views expresses the world in that board's frame.
    """

    rig: CameraRig
    boards: ImageSequence
    skin: ImageSequence
    undeformed: object
    indented: object
    board0_R: np.ndarray
    board0_t: np.ndarray

    def from_calibrated(self, points: np.ndarray) -> np.ndarray:
        """``(N, 3)`` points [m] given in the calibrated (first board's) frame, in the
        rendering frame where the truth is defined."""
        return np.asarray(points) @ self.board0_R.T + self.board0_t

    def true_height_m(self, points: np.ndarray) -> np.ndarray:
        """Height ``(N,)`` [m] of the undeformed surface under ``points`` ``(N, 3)`` (rendering frame)."""
        return self.undeformed.height(points[:, 0], points[:, 1])  # type: ignore[attr-defined]

    def true_indented(self, points: np.ndarray) -> np.ndarray:
        """``(N, 3)`` [m] where the undeformed surface points ``points`` (rendering frame) go
        once indented."""
        return self.indented.position(points[:, 0], points[:, 1])  # type: ignore[attr-defined]


def stereo_session(seed: int = 0) -> StereoSession:
    """Render the session (about 70 views of 640 x 480 px; seconds to a minute)."""
    from skinkit.vision import boards, scene
    from skinkit.vision.rigs import ring_rig
    from skinkit.vision.sensor import Sensor
    from skinkit.vision.texture import SpeckleTexture

    rng = np.random.default_rng(seed)
    rig = ring_rig(distortion=list(DISTORTION))
    sensor = Sensor(noise=0.01, falloff=0.2)
    board = scene.Board(inner=BOARD_INNER, square_m=BOARD_SQUARE_M)
    poses = boards.random_board_poses(16, rng, board, tilt_deg=40, lift_m=(-0.01, 0.01))
    views = boards.board_views(rig, poses, sensor, seed=int(rng.integers(2**31)))
    skin0 = scene.Skin(SpeckleTexture(cell=0.00045, seed=int(rng.integers(2**31))),
                       scene.forearm(ARM_RADIUS_M), (0.025, 0.025))
    skin1 = skin0.deformed(indentation)
    frames = np.stack([[scene.render_view(c, [s], sensor, rng) for c in rig.cameras] for s in (skin0, skin1)])
    return StereoSession(
        rig=rig,
        boards=ImageSequence("calibration", views, rig.names, np.arange(len(views), dtype=float)),
        skin=ImageSequence("indentation", frames, rig.names, [0.0, 1.0]),
        undeformed=skin0, indented=skin1, board0_R=poses[0].R, board0_t=poses[0].t)
