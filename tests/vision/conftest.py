"""Rendered rigs and boards shared by the vision tests (rendered once per session)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from skinkit.vision import boards
from skinkit.vision.rigs import ring_rig
from skinkit.vision.scene import Board
from skinkit.vision.sensor import Sensor

#: mild barrel distortion with a little decentring, as a 6 mm machine-vision lens
DISTORTION = [-0.08, 0.03, 0.0005, -0.0003, 0.0]
BOARD = Board(inner=(9, 6), square_m=0.003)


@pytest.fixture(scope="session")
def board():
    """The 9 x 6 inner-corner board with 3 mm squares."""
    return BOARD


@pytest.fixture(scope="session")
def true_rig():
    """The thesis stereoscope geometry: 4 cameras, 55 deg, 125 mm ring."""
    return ring_rig(distortion=DISTORTION)


@pytest.fixture(scope="session")
def board_set(true_rig):
    """16 board placements (the first flat: the world frame) seen by every camera."""
    poses = boards.random_board_poses(16, np.random.default_rng(3), BOARD, tilt_deg=40,
                                      lift_m=(-0.01, 0.01))
    images = boards.board_views(true_rig, poses, Sensor(noise=0.01, falloff=0.2), seed=1)
    return poses, images


ARM_RADIUS_M = 0.035
MARKER_RADIUS_M = 0.0003
CONE_SHIFT_M = np.array([0.0003, -0.0002, -0.0004])  # indenter motion between the frames [m]


def _indent(X, Y):
    """A 0.6 mm dimple with 1 % / -0.5 % in-plane stretch: the deformed state [m]."""
    r2 = X**2 + Y**2
    return np.column_stack([0.01 * X, -0.005 * Y, -0.0006 * np.exp(-r2 / (2 * 0.008**2))])


def _normal(skin, XY, eps=1e-6):
    """Unit normals ``(N, 3)`` of the (deformed) surface at material points ``XY``."""
    p = skin.position(XY[:, 0], XY[:, 1])
    tx = skin.position(XY[:, 0] + eps, XY[:, 1]) - p
    ty = skin.position(XY[:, 0], XY[:, 1] + eps) - p
    n = np.cross(tx, ty)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


@pytest.fixture(scope="session")
def arm_scene(true_rig):
    """A speckled forearm (35 mm radius) under a speckled conical indenter, rendered by all
    four cameras undeformed (frame 0) and deformed with the indenter moved (frame 1)."""
    from skinkit.schemas import ImageSequence
    from skinkit.vision import scene
    from skinkit.vision.texture import SolidSpeckle, SpeckleTexture

    skin0 = scene.Skin(SpeckleTexture(cell=0.00045, seed=1), scene.forearm(ARM_RADIUS_M), (0.025, 0.025))
    skin1 = skin0.deformed(_indent)
    cone_kw = dict(axis=[0.02, -0.01, -1.0], half_angle_deg=40.0, height_m=0.008, tip_length_m=0.011,
                   texture=SolidSpeckle(cell=0.0006, seed=3))
    cone0 = scene.Cone(apex=np.array([0.0005, -0.0003, 0.012]), **cone_kw)
    cone1 = scene.Cone(apex=cone0.apex + CONE_SHIFT_M, **cone_kw)
    # Fluorescent markers on five material points, 0.3 mm spheres resting on the skin.
    mXY = np.array([[-8, -6], [6, -7], [9, 5], [-5, 8], [0, -10]]) * 1e-3
    centres = [skin.position(mXY[:, 0], mXY[:, 1]) + MARKER_RADIUS_M * _normal(skin, mXY)
               for skin in (skin0, skin1)]
    markers = [scene.Markers(c, MARKER_RADIUS_M, brightness=0.8) for c in centres]
    sensor = Sensor(noise=0.01, falloff=0.2)
    rng = np.random.default_rng(0)
    states = [[skin0, cone0, markers[0]], [skin1, cone1, markers[1]]]
    # Under UV (thesis 5.2.4) only the fluorescent spheres shine; skin and cone are dim.
    dim_tex = SpeckleTexture(cell=0.00045, seed=1, background=0.03, contrast=0.03)
    dim_cone = SolidSpeckle(cell=0.0006, seed=3, background=0.03, contrast=0.03)
    # The dim skins are the lit ones repainted (replace keeps the shared undeformed ray
    # solutions: the texture does not move a surface, so their rays need no new Newton solve).
    uv_states = [[replace(skin, texture=dim_tex),
                  scene.Cone(cone.apex, cone.axis, cone.half_angle_deg, cone.height_m, cone.tip_length_m,
                             dim_cone), mk]
                 for skin, cone, mk in zip((skin0, skin1), (cone0, cone1), markers, strict=True)]
    frames = np.stack([[scene.render_view(c, objs, sensor, rng) for c in true_rig.cameras]
                       for objs in states])
    uv = np.stack([[scene.render_view(c, objs, sensor, rng) for c in true_rig.cameras]
                   for objs in uv_states])
    cone_masks = np.stack([[scene.hit_mask(c, objs, 1) for c in true_rig.cameras] for objs in states])
    seq = ImageSequence("indent", frames, true_rig.names, [0.0, 0.1])
    return {"images": seq, "skin": (skin0, skin1), "cone": (cone0, cone1), "cone_masks": cone_masks,
            "markers": centres, "uv_frames": uv}
