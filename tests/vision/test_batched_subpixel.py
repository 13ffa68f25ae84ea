"""The batched subpixel step of the subset trackers gives the per-point results.

``SubsetTracker.subpixel_many`` by default calls ``subpixel`` point by point; ``pcc`` and ``gn``
override it with stacked FFTs, stacked solves and one interpolation per iteration. On a speckle
scene with a known affine motion, texture-less and striped patches, a mask and points at the
image edge, and on a blank current image (so that every failure reason occurs), the batched
results equal the per-point ones.
"""

from __future__ import annotations

import types

import numpy as np
import pytest
from scipy.ndimage import affine_transform, gaussian_filter
from skinkit_plugins.trackers import gauss_newton, pcc
from skinkit_plugins.trackers.base import SubsetTracker

from skinkit import registry
from skinkit.plugin.trackers import IntegerMatch, TrackResult

pytestmark = pytest.mark.needs_plugins

SIZE = 240  # image side [px]
SUBSET = 31  # subset side [px]
TOL = 1e-9  # displacement [px] and quality [1]


@pytest.fixture(scope="module")
def scene():
    """``(ref, cur, points, guesses, mask)``: ``(SIZE, SIZE)`` images, ``(N, 2)`` points [px],
    ``(N, 2)`` initial guesses [px] and a ``(SIZE, SIZE)`` bool mask."""
    rng = np.random.default_rng(7)
    ref = gaussian_filter(rng.normal(size=(SIZE, SIZE)), 1.5)
    ref = 128 + 40 * ref / ref.std()
    # content moves by a 1 % stretch, a little shear and (0.7, -0.4) px; (row, col) order
    A = np.array([[0.99, 0.015], [-0.01, 1.01]])
    cur = affine_transform(ref, A, offset=(0.4, -0.7), order=3, mode="mirror")
    ref = ref + rng.normal(0, 0.5, ref.shape)
    cur = cur + rng.normal(0, 0.5, cur.shape)
    # texture-less (no texture, no phase fit) and striped (constant along y: no y gradient)
    # patches, apart by more than a subset: one straddling both would be ill-conditioned, its
    # result decided by rounding
    ref[130:, 170:] = cur[130:, 170:] = 100.0
    cur[150:230, 20:100] += rng.normal(0, 90, (80, 80))  # noisy: correlation below 0.5
    ref[:90, 170:] = cur[:90, 170:] = 100 + 30 * np.sin(0.7 * np.arange(170, SIZE))
    pts = np.vstack([
        rng.uniform(-2, SIZE + 2, (260, 2)),  # anywhere, edges and outside included
        [[200.0, 18.0], [205.0, 20.0]],  # stripes: degenerate gradient
        [[200.0, 190.0], [100.0, 60.0], [101.0, 61.0]],  # texture-less; two guessed below
    ])
    guesses = np.zeros_like(pts)
    guesses[-2] = np.nan
    guesses[-1] = (5000.0, 0.0)
    mask = np.ones(ref.shape, bool)
    mask[110:150, 30:160] = False
    mask[rng.uniform(size=mask.shape) < 0.03] = False  # scattered holes: partly used subsets
    return ref, cur, pts, guesses, mask


def _per_point(tracker: SubsetTracker) -> SubsetTracker:
    """``tracker`` with the default, point-by-point subpixel step."""
    tracker.subpixel_many = types.MethodType(SubsetTracker.subpixel_many, tracker)
    return tracker


def _assert_same(a: TrackResult, b: TrackResult) -> None:
    assert a.reason == b.reason
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_allclose(a.displacement_px, b.displacement_px, rtol=0, atol=TOL)
    np.testing.assert_allclose(a.quality, b.quality, rtol=0, atol=TOL)
    np.testing.assert_array_equal(a.isu_px, b.isu_px)
    assert a.extra.keys() == b.extra.keys()
    for key in a.extra:
        np.testing.assert_allclose(a.extra[key], b.extra[key], rtol=0, atol=TOL)


CASES = [("pcc", {}), ("pcc", {"iterations": 1}), ("gn", {}), ("gn", {"order": 5}),
         ("gn-translation", {})]


@pytest.mark.parametrize("name, kwargs", CASES)
@pytest.mark.parametrize("masked", [False, True])
def test_batched_equals_per_point(scene, name, kwargs, masked):
    ref, cur, pts, guesses, mask = scene
    m = mask if masked else None
    batched = registry.create("skinkit.trackers", name, **kwargs).track(
        ref, cur, pts, SUBSET, mask=m, guess_px=guesses)
    single = _per_point(registry.create("skinkit.trackers", name, **kwargs)).track(
        ref, cur, pts, SUBSET, mask=m, guess_px=guesses)
    _assert_same(batched, single)
    assert batched.valid.sum() > 100  # the comparison covers many tracked points
    reasons = {r.split(" (")[0].split(" in ")[0].split(" 0.")[0] for r in batched.reason}
    expected = {"", "point", "initial guess is not finite", "search window lies outside the current image",
                "NCC peak on the border of the +-24-px search window", "correlation"}
    expected |= {"subset is less than 75% usable under the mask"} if masked else set()
    if kwargs.get("iterations", 2) > 1:  # the subpixel step resamples the current image
        expected |= {"displaced subset leaves the current image"}
    if name.startswith("gn"):
        expected |= {"reference subset has no texture", "reference subset gradient is degenerate"}
    else:
        expected |= {"phase slope fit failed"}
    assert expected <= reasons, sorted(expected - reasons)
    if name == "gn":
        assert "Gauss-Newton did not converge" in reasons
        assert "gradient" in batched.extra


@pytest.mark.parametrize("name", ["pcc", "gn", "gn-translation"])
def test_chunks_do_not_change_the_result(scene, name, monkeypatch):
    """Subsets are processed in chunks; a chunk boundary anywhere gives the same result."""
    ref, cur, pts, guesses, mask = scene
    whole = registry.create("skinkit.trackers", name).track(ref, cur, pts, SUBSET, mask=mask)
    monkeypatch.setattr(pcc, "CHUNK", 17)
    monkeypatch.setattr(gauss_newton, "CHUNK", 17)
    chunked = registry.create("skinkit.trackers", name).track(ref, cur, pts, SUBSET, mask=mask)
    _assert_same(chunked, whole)


@pytest.mark.parametrize("name", ["pcc", "gn", "gn-translation"])
def test_blank_current_image(scene, name):
    """A blank current image: the NCC search, clipped at the corner, keeps its first shift and
    the current subset has no texture."""
    ref = scene[0]
    cur = np.zeros_like(ref)  # exactly blank after the spline prefilter too
    pts = np.array([[20.0, 20.0], [22.0, 21.0], [120.0, 120.0]])
    batched = registry.create("skinkit.trackers", name).track(ref, cur, pts, SUBSET)
    single = _per_point(registry.create("skinkit.trackers", name)).track(ref, cur, pts, SUBSET)
    _assert_same(batched, single)
    why = "phase slope fit failed" if name == "pcc" else "current subset has no texture"
    assert batched.reason[:2] == [why, why]


class _ShiftOnly(SubsetTracker):
    """A third-party tracker implementing only the per-point ``subpixel``."""

    name = "shift-only"

    def subpixel(self, state, ref, cur, p, c0, r0, s, match: IntegerMatch, mask):
        extra = {"corner": np.array([c0, r0], float)} if c0 % 2 else {}
        return match.shift.astype(float), match.peak, "", extra


def test_a_tracker_with_only_subpixel_still_works(scene):
    ref, cur, pts, _, _ = scene
    res = _ShiftOnly().track(ref, cur, pts, SUBSET)
    assert res.valid.sum() > 100
    np.testing.assert_array_equal(res.displacement_px[res.valid], np.rint(res.displacement_px[res.valid]))
    corner = res.extra["corner"]
    odd = np.array([int(np.rint(p[0])) - SUBSET // 2 for p in pts]) % 2 == 1
    has = ~np.isnan(corner[:, 0])
    assert has.any() and np.all(odd[has])


def test_texture_less_pcc_subset_is_invalid_not_an_error():
    """A flat subset has no spectrum to fit: the point is invalid with a reason."""
    rng = np.random.default_rng(1)
    ref = 128 + 40 * gaussian_filter(rng.normal(size=(96, 96)), 1.5)
    ref[:, 48:] = 100.0
    pts = np.array([[24.0, 48.0], [72.0, 48.0]])
    for trk in (registry.create("skinkit.trackers", "pcc"),
                _per_point(registry.create("skinkit.trackers", "pcc"))):
        res = trk.track(ref, ref, pts, SUBSET)
        assert res.valid.tolist() == [True, False]
        assert res.reason[1] == "phase slope fit failed"
