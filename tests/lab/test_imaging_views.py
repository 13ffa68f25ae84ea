"""The virtual cameras' frame loop: what is ray-cast and what is only exposed again."""

from __future__ import annotations

import numpy as np

from skinkit.lab.imaging import Cameras
from skinkit.vision import scene


class _Sensor:
    """Adds the frame's own noise, as a real sensor's exposure does."""

    def expose(self, rad: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return rad + rng.normal(0.0, 0.01, rad.shape)


class _Cam:
    image_size = (4, 3)


class _Rig:
    cameras = [_Cam(), _Cam()]


class _Skin:
    def deformed(self, field):
        return ("deformed", field)


def test_a_still_field_is_ray_cast_once_per_camera_and_exposed_per_frame(monkeypatch):
    cast = []

    def radiance(cam, objects):
        cast.append(objects[0])
        return np.full((3, 4), float(len(cast)))

    monkeypatch.setattr(scene, "radiance", radiance)
    still, moved = (lambda X, Y: 0.0), (lambda X, Y: 1.0)
    cams = Cameras(_Rig(), _Sensor(), _Skin())
    frames = cams.views([still, still, moved, None, None, still], np.random.default_rng(0))
    # still twice in a row: one cast per camera; moved, rest (once for all rest frames), still again
    assert len(cast) == 2 + 2 + 2 + 2
    assert frames.shape == (6, 2, 3, 4)
    same_scene = frames[1] - frames[0]
    assert np.abs(same_scene).max() < 0.1 and np.abs(same_scene).max() > 0   # noise only, fresh per frame
    np.testing.assert_array_equal(frames[3].round(1), frames[4].round(1))
