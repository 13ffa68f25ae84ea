"""Each tracked position's standard error, from the cameras' disagreement."""

from __future__ import annotations

import numpy as np

from skinkit.schemas import SurfaceTrack
from skinkit.store import create_experiment, open_experiment
from skinkit.vision import camera as cam_ops
from skinkit.vision.rigs import ring_rig
from skinkit.vision.tracking3d import POOLED_NEIGHBOURS, position_uncertainty
from skinkit.vision.triangulation import triangulate


def _views(rig, X, sigma_px, rng):
    px = np.stack([cam_ops.project(cam, X) for cam in rig.cameras], axis=1)
    return px + sigma_px * rng.standard_normal(px.shape)


def test_triangulation_standard_error_matches_the_pixel_noise():
    """Pixels with white noise σ: s² = Σr²/(2n−3) is unbiased for σ², so the mean of the
    reported variances equals the mean squared error of the points (least squares'
    covariance σ²(JᵀJ)⁻¹), each axis to within its sampling error."""
    rig = ring_rig()
    rng = np.random.default_rng(0)
    N = 6000
    X = np.column_stack([rng.uniform(-5e-3, 5e-3, (N, 2)), rng.uniform(-1e-3, 1e-3, N)])
    tri = triangulate(rig, _views(rig, X, 0.05, rng))
    err2 = np.mean((tri.points - X) ** 2, axis=0)
    rep2 = np.mean(tri.sigma_m ** 2, axis=0)
    # both sides are means of N squared normals (χ² with 5 dof for s²): relative sd √(2/N), √(2/5N)
    tol = 4 * np.sqrt(2 / N + 2 / (5 * N))
    np.testing.assert_allclose(rep2 / err2, 1.0, atol=tol)
    px = _views(rig, X[:5], 0.05, rng)
    px[:, 2:] = np.nan                               # two views: one degree of freedom left
    two = triangulate(rig, px)
    assert np.all(np.isfinite(two.sigma_m)) and np.all(two.valid)
    px[:, 1:] = np.nan
    assert np.all(np.isnan(triangulate(rig, px).sigma_m))


def test_position_uncertainty_pools_neighbours_and_keeps_the_floor():
    """Variances pooled over the nearest points in the same frame; never below the floor;
    NaN where the point was not tracked."""
    rng = np.random.default_rng(1)
    P, F = 200, 3
    pts = np.column_stack([rng.uniform(0, 1e-2, (P, 2)), np.zeros(P)])
    sig = np.full((P, F, 3), 4e-6)
    sig[:, 0] = 0.0                                  # the reference frame, tracked against itself
    valid = np.ones((P, F), bool)
    valid[7, 2] = False
    floor = np.array([1e-6, 1e-6, 2e-6])
    u = position_uncertainty(pts, sig, valid, floor)
    np.testing.assert_allclose(u[:, 0], np.broadcast_to(floor, (P, 3)))
    np.testing.assert_allclose(u[valid][:, 0], np.where(np.arange(P * F).reshape(P, F)[valid] % F == 0,
                                                         1e-6, 4e-6))
    assert np.all(np.isnan(u[7, 2]))
    one = sig.copy()
    one[3, 1] = 30e-6                                # a single outlying estimate is shared out
    u1 = position_uncertainty(pts, one, valid, floor)
    assert 4e-6 < u1[3, 1, 0] < 30e-6
    assert np.isclose(u1[3, 1, 0] ** 2, (29 * 16e-12 / 29 * (POOLED_NEIGHBOURS - 1) + 900e-12)
                      / POOLED_NEIGHBOURS)


def test_track_uncertainty_round_trips_through_the_session_file(tmp_path):
    P, F = 5, 3
    pts = np.zeros((P, F, 3))
    valid = np.ones((P, F), bool)
    unc = np.full((P, F, 3), 2e-6)
    with create_experiment(tmp_path / "s.h5") as exp:
        exp.write_track("a", SurfaceTrack(pts, valid, np.arange(F, dtype=float), uncertainty_m=unc))
        exp.write_track("b", SurfaceTrack(pts, valid, np.arange(F, dtype=float)))
    with open_experiment(tmp_path / "s.h5") as exp:
        np.testing.assert_array_equal(exp.read_track("a").uncertainty_m, unc)
        assert exp.read_track("b").uncertainty_m is None
