"""A deformed skin's rays start their Newton at the undeformed skin's solution: the same
intersections as a cold start from the plane, to the iteration's own tolerance."""

from __future__ import annotations

import numpy as np

from skinkit.lab.imaging import Cameras, displacement_field, followed_grid
from skinkit.vision import scene


def test_warm_started_rays_meet_the_skin_where_cold_started_rays_do():
    cams = Cameras.make(scene.forearm(0.035), seed=7)
    grid, points = followed_grid(0.01, lambda xy: np.zeros(len(xy)))
    bump = np.exp(-np.sum(points[:, :2] ** 2, axis=1) / 1e-5)
    u = np.column_stack([3e-4 * bump, 0.0 * bump, -5e-4 * bump])   # 0.3 mm slide, 0.5 mm dent
    skin = cams.skin.deformed(displacement_field(grid, points, u))
    origin, dirs = scene._camera_rays(cams.rig.cameras[0], 1)
    depth, xy = skin.intersect(origin, dirs)
    cold, done = skin._newton(origin, dirs, 20, None)
    hit, cold_hit = np.isfinite(depth), done & (cold[:, 2] > 0)
    assert cold_hit.sum() > 0.5 * len(dirs) and not (cold_hit & ~hit).any()
    # a few grazing rays on the arm's flank, where the cold start runs out of iterations, are
    # found from the warm start: all of them beyond the speckled patch
    extra = hit & ~cold_hit
    assert extra.sum() < 1e-3 * len(dirs)
    assert (np.abs(xy[extra]) > 0.025).any(axis=1).all()
    hit = cold_hit
    # Newton stops once the residual is below 1e-11 m; two stops of one root differ by about that
    assert np.abs(xy[hit] - cold[hit, :2]).max() < 1e-10
    assert np.abs(depth[hit] - cold[hit, 2]).max() < 1e-10
    # the undeformed solution is kept with the skin and shared by its deformed copies
    assert skin._rest is cams.skin._rest and len(skin._rest) == 1
