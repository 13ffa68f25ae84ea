"""The small model the solve-cache and cluster tests share: a two-layer disc (neo-Hookean skin
over subdermal tissue) indented through a bonded 4 mm probe, and one protocol's channels."""

from __future__ import annotations

import numpy as np

from skinkit.schemas import Channel

SPEC = {
    "model": {"name": "bilayer"},
    "geometry": {"kind": "disc", "diameter": "20 mm", "indenter_diameter": "4 mm", "n_inner": 2,
                 "n_ring": 2},
    "layers": [{"name": "skin", "thickness": "1.5 mm", "elements": 1, "law": "neo-hookean-enu",
                "parameters": {"E": "40 kPa", "nu": 0.45}},
               {"name": "subdermal", "thickness": "3.5 mm", "elements": 1, "law": "neo-hookean-enu",
                "parameters": {"E": "10 kPa", "nu": 0.45}}],
    "indenter": {"mode": "displacement"},
    "drive": {"max_step": "1 s"},
}
#: noise of one sample: force [N], tip position [m], tracked point [m]
NOISE_F, NOISE_X, NOISE_P = 1e-4, 1e-6, 5e-6
#: sample times of the tip [s] and of the tracked frames [s]
T = np.arange(0, 2.0001, 0.01)
FRAMES = np.array([0.0, 1.0, 2.0])
#: two tracked points' reference positions [m]
POINTS = np.array([[3e-3, 0, 0], [0, 4e-3, 0]])


def channels(direction: tuple[float, float, float] = (0, 0, -1)) -> dict[str, Channel]:
    """One protocol's channels, the probe moved at 0.2 mm/s along ``direction`` for 2 s: the
    drive, a zero force and points at rest (the values a test fills in)."""
    X = 2e-4 * T[:, None] * np.asarray(direction, float)
    return {"tip_force": Channel("tip_force", T, 0 * X, noise=NOISE_F),
            "tip_position": Channel("tip_position", T, X, noise=NOISE_X),
            "points": Channel("points", FRAMES, np.repeat(POINTS[:, None], FRAMES.size, 1), noise=NOISE_P,
                              reference=POINTS)}
