"""Camera model, triangulation, cone fit and texture: exact cases and closed forms."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from skinkit.vision import VisionError
from skinkit.vision import camera as C
from skinkit.vision.cone import cone_distance, fit_cone
from skinkit.vision.scene import Cone
from skinkit.vision.texture import SpeckleTexture
from skinkit.vision.triangulation import triangulate


def test_undistort_inverts_projection(true_rig):
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-0.02, 0.02, (200, 2)), rng.uniform(-0.003, 0.003, 200)])
    for cam in true_rig.cameras:
        px = C.project(cam, X)
        xn = C.undistort(cam, px)
        Xc = C.to_camera(cam, X)
        assert np.allclose(xn, Xc[:, :2] / Xc[:, 2:], atol=1e-11)
        o, d = C.rays(cam, px)
        # Each ray passes through its point: distance below 1e-12 m.
        assert np.max(np.linalg.norm(np.cross(X - o, d), axis=1)) < 1e-12


def test_triangulation_from_every_camera_subset(true_rig):
    rng = np.random.default_rng(1)
    X = np.column_stack([rng.uniform(-0.015, 0.015, (50, 2)), rng.uniform(-0.002, 0.002, 50)])
    px = np.stack([C.project(c, X) for c in true_rig.cameras], axis=1)
    for k in (2, 3, 4):
        for subset in itertools.combinations(range(4), k):
            obs = np.full_like(px, np.nan)
            obs[:, subset] = px[:, subset]
            tri = triangulate(true_rig, obs)
            assert tri.valid.all() and np.all(tri.n_views == k)
            assert np.max(np.abs(tri.points - X)) < 1e-10
            assert np.max(tri.reprojection_px) < 1e-6
    one = np.full_like(px, np.nan)
    one[:, 0] = px[:, 0]
    tri = triangulate(true_rig, one)
    assert not tri.valid.any() and np.isnan(tri.points).all()
    # Noise of s px per coordinate: a point's squared 2D errors over 4 views sum to
    # (2*4 - 3) s^2 in expectation (3 fitted coordinates); divided by 4 views -> s*sqrt(5/4).
    s = 0.1
    noisy = px + rng.normal(0, s, px.shape)
    tri = triangulate(true_rig, noisy)
    rms = np.sqrt(np.mean(tri.reprojection_px**2))
    assert abs(rms / (s * np.sqrt(5 / 4)) - 1) < 0.15  # 250 dof: ~5 % sampling error
    with pytest.raises(VisionError, match=r"expected shape \(N, 4, 2\)"):
        triangulate(true_rig, px[:, :3])


def test_cone_fit_recovers_apex_and_tip():
    rng = np.random.default_rng(2)
    cone = Cone(apex=[0.001, -0.002, 0.012], axis=[0.05, 0.02, -1.0])
    P = cone.surface_points(600, rng)
    P = P[P[:, 0] > cone.apex[0] - 0.002]  # a partial view, as the cameras see it
    noise = 10e-6
    P_noisy = P + rng.normal(0, noise, P.shape)
    P_noisy[:5] += 0.001  # gross mismatches, trimmed by the fit
    fit = fit_cone(P_noisy)
    # 10 um noise over ~400 points: the fitted surface is good to ~1 um, the tip 10 mm
    # beyond the apex amplifies axis errors ~2x: 15 um is a generous bound.
    assert np.linalg.norm(fit.tip(cone.tip_length_m) - cone.tip) < 15e-6
    assert abs(np.degrees(fit.half_angle_rad) - cone.half_angle_deg) < 0.2
    assert fit.rms_m == pytest.approx(noise, rel=0.2)
    assert np.max(np.abs(cone_distance(P, cone.apex, cone.axis, np.deg2rad(cone.half_angle_deg)))) < 1e-12
    with pytest.raises(VisionError, match="at least 10"):
        fit_cone(P[:5])


def test_texture_is_deterministic_and_bounded():
    tex = SpeckleTexture(cell=5.0, seed=4)
    x = np.linspace(-50, 50, 301)
    X, Y = np.meshgrid(x, x)
    a = tex(X, Y)
    assert np.array_equal(a, SpeckleTexture(cell=5.0, seed=4)(X, Y))
    assert not np.array_equal(a, SpeckleTexture(cell=5.0, seed=5)(X, Y))
    assert a.min() >= tex.background and a.max() <= tex.background + tex.contrast
    assert a.std() > 0.1  # enough contrast to track
