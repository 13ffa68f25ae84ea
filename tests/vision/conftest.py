"""Rendered rigs and boards shared by the vision tests (rendered once per session)."""

from __future__ import annotations

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
