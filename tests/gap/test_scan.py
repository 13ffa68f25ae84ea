"""The region scan's pieces, from numpy: the imaged area and the grid, the refusals, and the
statistics — every region's score test and the adjustment for the number of regions scanned.

The statistics are checked on a synthetic residual space: 40 points on a line, 12 frames, the
fitted parameters a uniform and a linear stiffness-like column, and one column per region, a
Gaussian bump 3 points wide every 2 points (neighbouring regions correlate at about 0.9, as a
scan's overlapping regions do). A region effect declared here (``Spot``) stands for the
``inclusion`` plugin: the core needs nothing but its declaration.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from skinkit.gap.scan import (
    DEFAULT_CELLS,
    ImagedArea,
    RegionScan,
    ScanError,
    ScanGrid,
    imaged_area,
    null_min_p,
    region_tests,
    scan_grid,
)
from skinkit.gap.scan_step import ScanOptions, check_regions, scan_options
from skinkit.plugin.effects import BaseEffect, declare
from skinkit.schemas import Channel, Observations, ProtocolObservations
from skinkit.schemas.protocol import Protocol


class Spot(BaseEffect):
    """A region effect as an effect author declares one."""

    name = "spot"
    region = ("x", "y", "radius")

    def _declared(self):
        return [declare("ratio", 3.0, 1.0, "1", 0.05, 50.0), declare("x", 3.0, 0.0, "mm", -20.0, 20.0),
                declare("y", 3.0, 0.0, "mm", -20.0, 20.0), declare("radius", 2.0, 2.0, "mm", 0.2, 20.0)]


def grid_points(half_mm: float = 8.0, step_mm: float = 1.0) -> np.ndarray:
    """``(P, 3)`` [m]: a square grid of points ``step_mm`` apart within ``half_mm`` of the origin."""
    g = np.arange(-half_mm, half_mm + 1e-9, step_mm) * 1e-3
    X, Y = np.meshgrid(g, g, indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])


def session(ref: np.ndarray | None) -> Observations:
    """One protocol with a force record and, when ``ref`` is given, points tracked at ``ref``."""
    t = np.linspace(0, 1, 50)
    chans = {"tip_force": Channel("tip_force", t, np.zeros((50, 3)), noise=1e-3, noise_source="declared")}
    if ref is not None:
        fr = np.linspace(0, 1, 5)
        X = np.repeat(ref[:, None, :], fr.size, axis=1)
        chans["points"] = Channel("points", fr, X, noise=1e-5, noise_source="tracker", reference=ref,
                                  reference_frame=0)
    return Observations({"pull": ProtocolObservations(Protocol("pull"), chans)})


# ----------------------------------------------------------------------------- area and grid
def test_the_imaged_area_is_the_points_extent_and_spacing():
    area = imaged_area(session(grid_points()))
    assert area is not None and len(area.points) == 17 * 17
    assert area.lower == pytest.approx([-8e-3, -8e-3]) and area.upper == pytest.approx([8e-3, 8e-3])
    assert area.spacing == pytest.approx(1e-3)
    assert area.contains((8e-3, -8e-3)) and not area.contains((8.5e-3, 0.0))
    assert imaged_area(session(None)) is None


def test_the_default_grid_covers_the_points_at_an_eighth_of_their_extent():
    area = imaged_area(session(grid_points()))
    g = scan_grid(area, size_bounds=(0.2e-3, 20e-3))
    assert g.spacing == pytest.approx(16e-3 / DEFAULT_CELLS)
    assert len(g.centres) == 9 * 9                       # -8..8 mm every 2 mm, every one over points
    assert g.sizes == pytest.approx([2e-3, 4e-3])
    assert g.regions().shape == (9 * 9 * 2, 3)
    # a centre needs a tracked point within one spacing: none over an empty quadrant
    pts = grid_points()
    holed = pts[~((pts[:, 0] > 1e-3) & (pts[:, 1] > 1e-3))]
    g2 = scan_grid(imaged_area(session(holed)), 2e-3)
    assert not np.any((g2.centres[:, 0] > 3.5e-3) & (g2.centres[:, 1] > 3.5e-3))


@pytest.mark.parametrize("spacing, sizes, message", [
    (0.5e-3, None, r"--scan-grid 0.5 mm is finer than the tracked points resolve: their typical spacing "
                   r"is 1 mm"),
    (2e-3, [0.4e-3], r"--scan-sizes 0.4 mm is smaller than the tracked points resolve"),
    (2e-3, [30e-3], r"--scan-sizes 30 mm is outside the admissible range of spot.radius \[0.2, 20\] mm"),
    (-1.0, None, r"--scan-grid: expected a positive length"),
    (2e-3, [], r"--scan-sizes: no size given"),
])
def test_a_grid_the_points_cannot_resolve_is_refused(spacing, sizes, message):
    area = imaged_area(session(grid_points()))
    with pytest.raises(ScanError, match=message):
        scan_grid(area, spacing, sizes, size_bounds=(0.2e-3, 20e-3), size_name="spot.radius")


def test_scan_options_from_the_command_line_are_checked():
    assert scan_options(2.0, ["1", "3"]) == ScanOptions(2e-3, (1e-3, 3e-3))
    assert not scan_options(None, None).explicit
    with pytest.raises(ScanError, match=r"--scan-grid: expected a positive number of mm, got 0"):
        scan_options(0.0, None)
    with pytest.raises(ScanError, match=r"--scan-sizes: expected a positive number of mm, got 'big'"):
        scan_options(None, ["big"])


@pytest.mark.needs_plugins
def test_bad_regions_are_refused_before_anything_runs():
    obs = session(grid_points())
    spec = {"effects": [{"name": "inclusion", "x": "12 mm", "ratio": 3.0}]}
    with pytest.raises(ScanError, match=r"^effects\[0\] \(inclusion\): centre x 12 mm, y 0 mm lies outside "
                                        r"the imaged area: the tracked points span x -8.0 to 8.0 mm, "
                                        r"y -8.0 to 8.0 mm$"):
        check_regions(spec, obs, None)
    check_regions({"effects": [{"name": "inclusion", "x": "3 mm", "y": "-2 mm"}]}, obs, None)   # inside
    with pytest.raises(ScanError, match=r"no tracked points, so no imaged area to scan"):
        check_regions({}, session(None), ScanOptions(2e-3))
    with pytest.raises(ScanError, match=r"finer than the tracked points resolve"):
        check_regions({}, obs, ScanOptions(0.5e-3))
    check_regions({}, session(None), None)    # no options asked: nothing to refuse


# -------------------------------------------------------------------------------- statistics
N_POINTS, N_FRAMES, N_REGIONS = 40, 12, 19


def residual_space() -> tuple[np.ndarray, np.ndarray]:
    """``(J, unit_region_columns)``: J ``(m, 2 + R)`` with the fitted columns first, and each
    region's column alone (to add a signal along it)."""
    x = np.arange(N_POINTS, dtype=float)
    amp = np.sin(np.linspace(0.3, 3.0, N_FRAMES))              # the drive over the frames
    theta = [np.outer(np.ones(N_POINTS), amp).ravel(), np.outer(x / N_POINTS, amp).ravel()]
    centres = 2.0 + 2.0 * np.arange(N_REGIONS)
    bumps = [np.outer(np.exp(-0.5 * ((x - c) / 3.0) ** 2), amp).ravel() for c in centres]
    J = np.column_stack(theta + bumps)
    return J, np.column_stack(bumps)


def scanned(z: np.ndarray, J: np.ndarray, min_p: np.ndarray | None = None) -> RegionScan:
    tests, A = region_tests(z, J, 2, "spot", Spot())
    mp = null_min_p(A, [t.dof for t in tests]) if min_p is None else min_p
    grid = ScanGrid(np.zeros((len(tests), 2)), np.array([1e-3]), 1e-3)
    s = RegionScan("spot", ("spot.x", "spot.y", "spot.radius"), ["spot.ratio"], grid, None, tests,
                   np.ones(len(tests)), np.zeros(len(tests)), mp)
    return s


def test_each_region_is_tested_as_the_score_test_tests_one():
    from skinkit.gap.score import EffectColumns, fitted_basis, score_test

    J, bumps = residual_space()
    z = np.random.default_rng(3).standard_normal(J.shape[0])
    tests, A = region_tests(z, J, 2, "spot", Spot())
    assert len(tests) == N_REGIONS and all(t.dof == 1 and t.tested == ["spot.ratio"] for t in tests)
    assert set(tests[0].held) == {"spot.x", "spot.y", "spot.radius"}
    # region 7 by hand: LM = (aᵀz)² with a its column, J_θ projected out, normalised
    U = fitted_basis(J[:, :2])
    a = bumps[:, 7] - U @ (U.T @ bumps[:, 7])
    a /= np.linalg.norm(a)
    assert tests[7].statistic == pytest.approx(float(a @ z) ** 2, rel=1e-10)
    assert A[7][:, 0] == pytest.approx(a, abs=1e-12)
    cols = EffectColumns("spot", ["spot.ratio"], bumps[:, 7:8], {"spot.ratio": "analytic"}, np.zeros(1),
                         {}, {})
    assert score_test(z, U, cols).p_value == pytest.approx(tests[7].p_value, rel=1e-10)


def test_the_adjusted_p_holds_its_level_on_noise():
    """400 noise residuals: the best region's adjusted p falls below 0.05 in 5 % of them (binomial:
    20 ± 4.4; bounds at about ±3.4σ), the raw p of the best region as often as the simulated null
    says (far more often: the need for the adjustment), and Bonferroni's R·p never more often."""
    J, _ = residual_space()
    rng = np.random.default_rng(11)
    tests, A = region_tests(rng.standard_normal(J.shape[0]), J, 2, "spot", Spot())
    min_p = null_min_p(A, [t.dof for t in tests])
    p_raw_05 = float(np.mean(min_p <= 0.05))     # the simulated null's chance of a raw p below 0.05
    trials, adj, raw, bonf = 400, 0, 0, 0
    for _ in range(trials):
        s = scanned(rng.standard_normal(J.shape[0]), J, min_p)
        best = s.tests[s.best]
        p_adj, _ = s.adjusted(best.log_p)
        adj += p_adj < 0.05
        raw += best.p_value < 0.05
        bonf += best.p_value * N_REGIONS < 0.05
    assert 5 <= adj <= 35, adj
    sd = math.sqrt(trials * p_raw_05 * (1 - p_raw_05))
    assert abs(raw - trials * p_raw_05) < 4 * sd and p_raw_05 > 0.15, (raw, p_raw_05)
    assert bonf <= adj


def test_a_signal_is_found_at_its_region():
    J, bumps = residual_space()
    rng = np.random.default_rng(5)
    u = bumps[:, 9] / np.linalg.norm(bumps[:, 9])
    # 15 noise units along region 9: LM about 15² there against 15² ρ² ≈ 180 at a neighbour
    s = scanned(rng.standard_normal(J.shape[0]) + 15.0 * u, J)
    assert abs(s.best - 9) <= 1
    p_adj, log_p_adj = s.adjusted(s.tests[s.best].log_p)
    assert p_adj < 1e-6
    assert log_p_adj >= s.tests[s.best].log_p        # adjusting never makes a p smaller


def on_a_line(z: np.ndarray, J: np.ndarray) -> RegionScan:
    """The scan of ``z`` with the regions laid out as their bumps are: centres 2 mm apart on x,
    each of radius 1.5 mm."""
    s = scanned(z, J)
    centres = np.column_stack([(2.0 + 2.0 * np.arange(N_REGIONS)) * 1e-3, np.zeros(N_REGIONS)])
    s.grid = ScanGrid(centres, np.array([1.5e-3]), 2e-3)
    s.area = ImagedArea(centres, centres.min(axis=0), centres.max(axis=0), 2e-3)
    return s


def test_a_second_place_of_its_own_is_the_rival_and_a_shoulder_of_the_best_is_not():
    """Two regions carrying signals of similar strength far apart: the weaker is the best's rival
    (a place the refit must also try). One signal mid-line: its neighbours score highly (they
    overlap it) but are no rival, and a second signal a tenth as strong (in LM) is none either.
    A signal near the line's end: with the fitted uniform and linear columns projected out, the
    far end's region carries its opposite-signed lobe and scores more than half as much — the
    shape of a stiff place here read as a soft one there, which the refits must settle."""
    J, bumps = residual_space()
    noise = np.random.default_rng(7).standard_normal(J.shape[0])
    u = [bumps[:, k] / np.linalg.norm(bumps[:, k]) for k in range(N_REGIONS)]
    two = on_a_line(noise + 15.0 * u[4] + 14.0 * u[14], J)
    assert {two.best, two.rival()} == {4, 14}
    d = two.to_dict()["rival"]
    assert d["x_m"] == pytest.approx(two.grid.centres[two.rival(), 0])
    assert 0.5 <= d["share_of_best"] <= 1.0
    one = on_a_line(noise + 15.0 * u[9], J)
    assert one.best == 9 and one.rival() is None and one.to_dict()["rival"] is None
    assert max(one.tests[k].statistic for k in (8, 10)) > 0.5 * one.tests[9].statistic  # a shoulder
    assert on_a_line(noise + 15.0 * u[9] + 4.5 * u[17], J).rival() is None
    edge = on_a_line(noise + 15.0 * u[4], J)
    r = edge.rival()
    assert edge.best == 4 and r == 0
    assert np.sign(edge.tests[r].step["spot.ratio"]) == -np.sign(edge.tests[4].step["spot.ratio"])


@pytest.mark.needs_plugins
def test_a_region_effect_takes_instance_labels():
    """Two scars in one model (what a scan's model holds, one per candidate region)."""
    from skinkit.forward.effects import apply_all, resolve

    second = {"name": "inclusion", "instance": "inclusion-b", "x": "3 mm"}
    eff = resolve([{"name": "inclusion"}, second], "fe")
    assert [(e.name, e.effect) for e in eff] == [("inclusion", "inclusion"), ("inclusion-b", "inclusion")]
    spec = {"layers": [{"name": "skin", "thickness": "1 mm"}]}
    fields = apply_all(spec, eff)["fields"]
    assert [(f["name"], f["x"]) for f in fields] == [("inclusion", 0.0), ("inclusion-b", pytest.approx(3e-3))]


def test_the_diagnosis_tests_a_scanned_candidate_with_the_adjusted_p():
    from skinkit.gap.scan_step import RoundScan
    from skinkit.gap.score import ScoreTest

    J, bumps = residual_space()
    u = bumps[:, 4] / np.linalg.norm(bumps[:, 4])
    s = scanned(np.random.default_rng(2).standard_normal(J.shape[0]) + 4.0 * u, J)
    b = s.tests[s.best]
    other = ScoreTest("other", 9.0, 1, 2.7e-3, math.log(2.7e-3), {}, np.zeros(1), ["other.k"], {}, [], {},
                      False)
    out = RoundScan({"spot": s}).adjust([b, other])
    adj = next(t for t in out if t.effect == "spot")
    p, log_p = s.adjusted(b.log_p)
    assert (adj.p_value, adj.log_p, adj.statistic) == (p, log_p, b.statistic) and p > b.p_value
    assert all("best region" in adj.held[n] for n in ("spot.x", "spot.y", "spot.radius"))
    assert next(t for t in out if t.effect == "other") is other
    order = {"spot": log_p, "other": other.log_p}
    assert [t.effect for t in out] == sorted(order, key=order.get)
