"""Module-level caches hand out read-only arrays, stay bounded and hit on exact keys: a caller that
wrote into a cached array would change every later render."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from skinkit.vision import scene
from skinkit.vision.rigs import ring_rig


def _small_camera(name: str = "c0", shift_m: float = 0.0):
    cam = ring_rig(image_size=(48, 40)).cameras[0]
    return dataclasses.replace(cam, name=name, t=cam.t + np.array([shift_m, 0.0, 0.0]))


def test_camera_rays_are_read_only_and_shared():
    cam = _small_camera()
    origin, dirs = scene._camera_rays(cam, 1)
    assert dirs.shape == (48 * 40, 3)
    for a in (origin, dirs):
        with pytest.raises(ValueError, match="read-only"):
            a[0] = 0.0
    again = scene._camera_rays(dataclasses.replace(cam), 1)  # an equal camera: the same arrays
    assert again[1] is dirs


def test_ray_cache_stays_bounded_least_recently_used_out(monkeypatch):
    monkeypatch.setattr(scene, "_RAY_CACHE", type(scene._RAY_CACHE)())
    n = scene.RAY_CACHE_ENTRIES
    cams = [_small_camera(f"c{i}", 1e-3 * i) for i in range(n + 3)]
    first = scene._camera_rays(cams[0], 1)
    for cam in cams[1:]:
        scene._camera_rays(cam, 1)
        scene._camera_rays(cams[0], 1)       # kept in use: never evicted
        assert len(scene._RAY_CACHE) <= n
    assert len(scene._RAY_CACHE) == n
    assert scene._camera_rays(cams[0], 1)[1] is first[1]
    # the least recently used cameras went first: the kept ones are the newest n - 1 and c0
    kept = {key[0] for key in scene._RAY_CACHE}
    assert kept == {"c0"} | {c.name for c in cams[-(n - 1):]}


def test_ray_cache_respects_its_memory_budget(monkeypatch):
    monkeypatch.setattr(scene, "_RAY_CACHE", type(scene._RAY_CACHE)())
    one = sum(a.nbytes for a in scene._camera_rays(_small_camera("a"), 1))
    monkeypatch.setattr(scene, "RAY_CACHE_BYTES", int(2.5 * one))
    for i in range(6):
        scene._camera_rays(_small_camera(f"b{i}", 1e-3 * (i + 1)), 1)
    assert len(scene._RAY_CACHE) == 2


def test_charuco_image_read_only_bounded_exact_key():
    scene._charuco_image.cache_clear()
    board = scene.CharucoTarget(squares=(4, 3), px_per_square=20)
    img = board._image()
    assert img.shape == (60, 80) and 0.0 <= img.min() and img.max() <= 1.0
    with pytest.raises(ValueError, match="read-only"):
        img[0, 0] = 0.5
    assert scene.CharucoTarget(squares=(4, 3), px_per_square=20)._image() is img
    # the key holds the exact lengths: a board 1 ulp larger is another board
    other = scene.CharucoTarget(squares=(4, 3), square_m=np.nextafter(0.004, 1.0), px_per_square=20)
    assert other._image() is not img
    for k in range(10):
        scene.CharucoTarget(squares=(4, 3), marker_m=0.002 + 1e-5 * k, px_per_square=20)._image()
    assert scene._charuco_image.cache_info().currsize <= scene._charuco_image.cache_info().maxsize == 4


@pytest.mark.needs_plugins
def test_pcc_frequency_grid_read_only_bounded_exact_key():
    from skinkit_plugins.trackers import pcc

    pcc._grid.cache_clear()
    use, wx, wy, W = pcc._freq_grid((16, 16), 1.0)
    for a in (use, wx, wy, W):
        with pytest.raises(ValueError, match="read-only"):
            a.flat[0] = 0
    # all frequencies within the cut-off but DC, nothing else
    assert np.all(wx**2 + wy**2 <= 1.0) and not np.any((wx == 0) & (wy == 0))
    assert pcc._freq_grid((16, 16), 1.0)[3] is W
    assert pcc._freq_grid((16, 16), np.nextafter(1.0, 2.0))[3] is not W   # exact, not rounded
    for k in range(40):
        pcc._freq_grid((16, 16), 1.0 + 0.01 * k)
    info = pcc._grid.cache_info()
    assert info.currsize <= info.maxsize == 16
