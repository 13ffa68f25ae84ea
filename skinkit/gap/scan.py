"""Find the region: score tests of a region effect over a grid of candidate regions.

An effect confined to a region of the skin plane (a scar: an ``inclusion``) declares the local
names of its centre and size (:attr:`skinkit.plugin.effects.BaseEffect.region`). At its null
(stiffness ratio 1) the position and size leave no signature, so the plain score test
(:mod:`skinkit.gap.score`) holds them at their declared null — the origin and a typical radius
— where a scar elsewhere is nearly invisible. The scan tests the effect's other parameters (the
ratio) at every region of a grid instead:

* **the imaged area** (:func:`imaged_area`): the tracked points' reference positions; its
  extent is their bounding box, its resolution their typical spacing (the median distance from
  a point to its nearest neighbour);
* **the grid** (:func:`scan_grid`): centres on a square grid of ``spacing`` over the extent,
  kept where a tracked point lies within one spacing (no region over a probe's footprint or
  beyond the points), times a few sizes. A spacing below the points' typical spacing, or a
  size below it, asks for detail the points cannot resolve and is refused;
* **one prediction** (:func:`scan`): the model is loaded once with every candidate region as
  an instance of the effect at its null (``"<label>-scan<k>"``), and predicted once with the
  sensitivities to the fitted parameters θ and to every region's tested parameters. A field's
  parameters are differentiated directly (:mod:`skinkit.fem.sensitivity`): each column costs
  one solve with the converged tangent per step, the factorisation reused, not a solve of the
  model; ``cost`` says what the scan took;
* **the statistics**: every region's score test exactly as :func:`skinkit.gap.score.score_test`
  makes one (J_θ projected out, the AR colour's allowance), LM and its raw p;
* **the adjustment for scanning**: the best of R correlated regions is tested, so its raw p is
  far too small. Under "no effect anywhere" the vector t = Aᵀz of the regions' projected unit
  columns A is N(0, AᵀA) (z white, unit variance), so the joint null of every region's
  statistic is known exactly: :data:`N_DRAWS` draws of t give the distribution of the smallest
  p over the scan (the max-statistic adjustment; Westfall & Young 1993), and a region's
  adjusted p is the share of draws whose smallest p is at most its own, bounded by Bonferroni's
  R·p (which stays valid, and resolves p far below 1/N_DRAWS). One-sided constraints are left
  out of the draws, which makes the adjustment conservative.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from skinkit import registry
from skinkit.errors import SkinkitError
from skinkit.gap.score import (
    FLAT,
    Colour,
    EffectColumns,
    ScoreTest,
    colour_of,
    effect_of,
    fitted_basis,
    score_test,
    with_effects,
)
from skinkit.schemas import Observations, Prediction

#: centres across the larger side of the imaged area when no spacing is given
DEFAULT_CELLS = 8
#: sizes scanned when none are given, as multiples of the grid's spacing
DEFAULT_SIZES = (1.0, 2.0)
#: draws of the null score vector for the max-statistic adjustment (and the generator's seed)
N_DRAWS = 20000
SEED = 20260101
#: a second place rivals the best region when its statistic is at least this share of the best's:
#: the score statistic is the likelihood gain of a small effect, and a strong one (a scar many times
#: stiffer) gains differently — a stiffer region's signature saturates where a softer one's keeps
#: growing — so the order of two places within a factor of two is left to their refits
RIVAL_SHARE = 0.5


class ScanError(SkinkitError):
    """A region scan that cannot be made as asked: no tracked points, a grid or a region finer
    than the points resolve, a size outside the effect's bounds, a centre outside the area."""


def region_of(label: str) -> tuple[str, str, str] | None:
    """The ``(x, y, size)`` local names candidate ``label``'s effect declares as its region, or
    None (no region, or not an installed effect)."""
    try:
        plugin = registry.create("skinkit.effects", effect_of(label))
    except SkinkitError:
        return None
    reg = getattr(plugin, "region", None)
    return tuple(reg) if reg else None   # type: ignore[return-value]


# ------------------------------------------------------------------------------- imaged area
@dataclass(frozen=True)
class ImagedArea:
    """Where the session's tracked points are.

    Attributes:
        points: ``(P, 2)`` [m] their distinct reference positions in the skin plane.
        lower, upper: ``(2,)`` [m] the corners of their bounding box (the extent).
        spacing: [m] their typical spacing: the median distance to the nearest neighbour.
    """

    points: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    spacing: float

    def contains(self, xy: Sequence[float]) -> bool:
        """Whether ``xy`` [m] lies within the extent (edges included, to rounding)."""
        tol = 1e-9 * float(np.max(self.upper - self.lower) or 1.0)
        p = np.asarray(xy, float)
        return bool(np.all(p >= self.lower - tol) and np.all(p <= self.upper + tol))

    def describe(self) -> str:
        """The extent in words: ``"x -8.0 to 8.0 mm, y -8.0 to 8.0 mm"``."""
        lo, hi = self.lower * 1e3, self.upper * 1e3
        return f"x {lo[0]:.1f} to {hi[0]:.1f} mm, y {lo[1]:.1f} to {hi[1]:.1f} mm"


def imaged_area(observations: Observations) -> ImagedArea | None:
    """The tracked points of ``observations`` (every protocol's points channels, reference
    positions) as an :class:`ImagedArea`; None when it has no tracked points (or one)."""
    refs = [np.asarray(ch.reference, float)[:, :2] for po in observations for ch in po.channels.values()
            if ch.is_points and ch.reference is not None and len(ch.reference)]
    if not refs:
        return None
    pts = np.unique(np.round(np.concatenate(refs), 12), axis=0)
    if len(pts) < 2:
        return None
    from scipy.spatial import cKDTree

    d, _ = cKDTree(pts).query(pts, k=2)
    return ImagedArea(pts, pts.min(axis=0), pts.max(axis=0), float(np.median(d[:, 1])))


# -------------------------------------------------------------------------------------- grid
@dataclass(frozen=True)
class ScanGrid:
    """The candidate regions: ``centres`` ``(C, 2)`` [m] times ``sizes`` ``(S,)`` [m] on a
    square grid of ``spacing`` [m]."""

    centres: np.ndarray
    sizes: np.ndarray
    spacing: float

    def regions(self) -> np.ndarray:
        """``(C·S, 3)`` [m]: x, y, size of every region, centre by centre (sizes innermost)."""
        c = np.repeat(self.centres, len(self.sizes), axis=0)
        return np.column_stack([c, np.tile(self.sizes, len(self.centres))])


def positive(value: Any, what: str, expected: str = "a positive length") -> float:
    """``value`` as a positive finite float, else a :class:`ScanError` naming ``what`` and the
    ``expected`` kind of value."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ScanError(f"{what}: expected {expected}, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ScanError(f"{what}: expected {expected}, got {value!r}")
    return v


def scan_grid(area: ImagedArea, spacing: float | None = None, sizes: Sequence[float] | None = None, *,
              size_bounds: tuple[float, float] = (0.0, math.inf),
              centre_bounds: tuple[tuple[float, float], tuple[float, float]] | None = None,
              size_name: str = "size") -> ScanGrid:
    """The scan's grid over ``area``: centres ``spacing`` [m] apart (default: the larger side
    over :data:`DEFAULT_CELLS`, at least the points' spacing) kept where a tracked point lies
    within one spacing and inside ``centre_bounds`` ((x_lo, x_hi), (y_lo, y_hi)) [m], and
    ``sizes`` [m] (default :data:`DEFAULT_SIZES` times the spacing, clipped into
    ``size_bounds`` [m] of the effect's parameter ``size_name``).

    Raises :class:`ScanError` for a spacing or a size below the points' typical spacing (finer
    than they resolve), a size outside ``size_bounds``, or no centre left."""
    res = area.spacing
    if spacing is None:
        spacing = max(res, float(np.max(area.upper - area.lower)) / DEFAULT_CELLS)
    spacing = positive(spacing, "--scan-grid")
    if spacing < res * (1 - 1e-6):
        raise ScanError(f"--scan-grid {spacing * 1e3:g} mm is finer than the tracked points resolve: "
                        f"their typical spacing is {res * 1e3:.3g} mm")
    lo_s, hi_s = size_bounds
    if sizes is None:
        sz = np.unique(np.clip(np.array(DEFAULT_SIZES) * spacing, max(lo_s, res), hi_s))
    else:
        sz = np.array([positive(s, "--scan-sizes") for s in sizes])
        if not sz.size:
            raise ScanError("--scan-sizes: no size given")
        for s in sz:
            if s < res * (1 - 1e-6):
                raise ScanError(f"--scan-sizes {s * 1e3:g} mm is smaller than the tracked points resolve: "
                                f"their typical spacing is {res * 1e3:.3g} mm")
            if not lo_s <= s <= hi_s:
                raise ScanError(f"--scan-sizes {s * 1e3:g} mm is outside the admissible range of "
                                f"{size_name} [{lo_s * 1e3:g}, {hi_s * 1e3:g}] mm")
        sz = np.unique(sz)
    mid = 0.5 * (area.lower + area.upper)
    axes = []
    for j in range(2):
        k = int(math.floor(0.5 * (area.upper[j] - area.lower[j]) / spacing + 1e-9))
        axes.append(mid[j] + spacing * np.arange(-k, k + 1))
    X, Y = np.meshgrid(*axes, indexing="ij")
    c = np.column_stack([X.ravel(), Y.ravel()])
    from scipy.spatial import cKDTree

    near, _ = cKDTree(area.points).query(c, k=1)
    keep = near <= spacing * (1 + 1e-9)
    if centre_bounds is not None:
        (xl, xh), (yl, yh) = centre_bounds
        keep &= (c[:, 0] >= xl) & (c[:, 0] <= xh) & (c[:, 1] >= yl) & (c[:, 1] <= yh)
    if not keep.any():
        raise ScanError(f"region scan: no centre of a {spacing * 1e3:g} mm grid lies over the tracked points "
                        f"({area.describe()}) and inside the effect's bounds")
    return ScanGrid(c[keep], sz, spacing)


# -------------------------------------------------------------------------------------- scan
@dataclass
class RegionScan:
    """A scan's result (module docstring).

    Attributes:
        effect: the candidate's label. region: its ``(x, y, size)`` model names
            (``"<label>.<local>"``). tested: the parameters tested at each region.
        grid: the :class:`ScanGrid`; area: the :class:`ImagedArea`.
        tests: one :class:`ScoreTest` per region, in ``grid.regions()`` order.
        p_adjusted, log_p_adjusted: ``(R,)`` each region's p adjusted for the scan.
        min_p: ``(N_DRAWS,)`` sorted smallest raw p of the scan per null draw.
        cost: ``n_forward`` (predictions), ``columns`` (sensitivity columns), ``wall_s`` [s],
            ``forward_equivalents`` (the scan's wall time over a plain prediction's, when known).
    """

    effect: str
    region: tuple[str, str, str]
    tested: list[str]
    grid: ScanGrid
    area: ImagedArea
    tests: list[ScoreTest]
    p_adjusted: np.ndarray
    log_p_adjusted: np.ndarray
    min_p: np.ndarray
    cost: dict[str, Any] = field(default_factory=dict)
    _rivals: dict[float, int | None] = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def best(self) -> int:
        """Index of the best region: the smallest p (then the largest statistic)."""
        return min(range(len(self.tests)), key=lambda i: (self.tests[i].log_p, -self.tests[i].statistic))

    def rival(self, share: float = RIVAL_SHARE) -> int | None:
        """Index of the best region's rival, or None: the highest-scoring region at a place of its
        own — its centre a local maximum of the map (no neighbouring centre, within 1.5 grid
        spacings, scores higher at any size) and outside the best region, the best's centre
        outside it — scoring at least ``share`` of the best's statistic. Computed once per share
        (the report and the diagnosis both ask)."""
        if share not in self._rivals:
            self._rivals[share] = self._find_rival(share)
        return self._rivals[share]

    def _find_rival(self, share: float) -> int | None:
        regs, b = self.grid.regions(), self.best
        st = np.array([t.statistic for t in self.tests], float)
        st = np.where(np.isfinite(st), st, -np.inf)
        xy = regs[:, :2]
        d_best = np.hypot(*(xy - xy[b]).T)
        ok = (d_best > np.maximum(regs[:, 2], regs[b, 2])) & (st >= share * st[b]) & (st > 0)
        for i in np.flatnonzero(ok):
            near = np.hypot(*(xy - xy[i]).T) <= 1.5 * self.grid.spacing
            ok[i] = st[i] >= st[near].max()
        if not ok.any():
            return None
        idx = np.flatnonzero(ok)
        return int(idx[np.argmax(st[idx])])

    def region_values(self, i: int) -> dict[str, float]:
        """Region ``i`` as model values: ``"<label>.<x>"``, ``".<y>"``, ``".<size>"`` [m]."""
        r = self.grid.regions()[i]
        return {n: float(v) for n, v in zip(self.region, r, strict=True)}

    def values(self) -> dict[str, float]:
        """The best region as model values: ``"<label>.<x>"``, ``".<y>"``, ``".<size>"`` [m]."""
        return self.region_values(self.best)

    def adjusted(self, log_p: float) -> tuple[float, float]:
        """``(p, log p)`` of a raw log p adjusted for the scan: the share of null draws whose
        smallest p is at most exp(log_p), bounded by Bonferroni's R·p."""
        n = self.min_p.size
        count = int(np.searchsorted(self.min_p, math.exp(log_p), side="right")) if n else 0
        log_mc = math.log((count + 1) / (n + 1)) if n else 0.0
        # never below the raw p (the draws' noise could put a share a little under it)
        log_adj = max(min(log_p + math.log(len(self.tests)), log_mc, 0.0), log_p)
        return math.exp(log_adj), log_adj

    def critical_p(self, alpha: float = 0.05) -> float:
        """The raw p a region needs for its adjusted p to reach ``alpha``."""
        if not self.min_p.size:
            return alpha / len(self.tests)
        return max(float(np.quantile(self.min_p, alpha)), alpha / len(self.tests))

    def _log10(self, i: int, adjusted: bool = False) -> float:
        """log10 of region ``i``'s raw (or adjusted) p, finite where p underflows: the χ²_q tail's
        leading term, log Q(q/2, LM/2) ≈ (q/2 − 1) log(LM/2) − LM/2 − log Γ(q/2), then Bonferroni's
        R for the adjusted one."""
        t = self.tests[i]
        lp = float(self.log_p_adjusted[i]) if adjusted else t.log_p
        if math.isfinite(lp) or t.dof < 1:
            return lp / math.log(10)
        h = 0.5 * t.dof
        raw = (h - 1) * math.log(0.5 * t.statistic) - 0.5 * t.statistic - math.lgamma(h)
        return (raw + (math.log(len(self.tests)) if adjusted else 0.0)) / math.log(10)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the grid, every region's statistic and p-values, the best region, the cost."""
        regs = self.grid.regions()
        b = self.best
        t = self.tests[b]
        n = range(len(self.tests))
        return {
            "effect": self.effect, "parameters": list(self.region), "tested": self.tested,
            "area": {"lower_m": self.area.lower.tolist(), "upper_m": self.area.upper.tolist(),
                     "point_spacing_m": self.area.spacing, "points": int(len(self.area.points))},
            "grid": {"spacing_m": self.grid.spacing, "centres_m": self.grid.centres.tolist(),
                     "sizes_m": self.grid.sizes.tolist(), "regions": int(len(regs))},
            "regions": {"x_m": regs[:, 0].tolist(), "y_m": regs[:, 1].tolist(), "size_m": regs[:, 2].tolist(),
                        "statistic": [x.statistic for x in self.tests], "dof": [x.dof for x in self.tests],
                        "log10_p": [self._log10(i) for i in n],
                        "log10_p_adjusted": [self._log10(i, True) for i in n]},
            "best": {"x_m": float(regs[b, 0]), "y_m": float(regs[b, 1]), "size_m": float(regs[b, 2]),
                     "statistic": t.statistic, "dof": t.dof, "p_value": t.p_value, "log10_p": self._log10(b),
                     "p_adjusted": float(self.p_adjusted[b]), "log10_p_adjusted": self._log10(b, True),
                     "step": t.step},
            "rival": self._rival_dict(),
            "adjustment": {"method": "max-statistic over the scanned regions (joint Gaussian null of their "
                                     "score vector), bounded by Bonferroni", "draws": int(self.min_p.size),
                           "critical_p_05": self.critical_p(0.05)},
            "cost": dict(self.cost),
        }

    def _rival_dict(self) -> dict[str, Any] | None:
        i = self.rival()
        if i is None:
            return None
        r, t = self.grid.regions()[i], self.tests[i]
        return {"x_m": float(r[0]), "y_m": float(r[1]), "size_m": float(r[2]), "statistic": t.statistic,
                "share_of_best": t.statistic / self.tests[self.best].statistic, "step": t.step}


def instance_tables(effect: str, label: str, region: Sequence[str], regions: np.ndarray,
                    form: str | None = None) -> list[dict[str, Any]]:
    """One ``[[effects]]`` table per row of ``regions`` (its ``region`` parameters' values [SI]):
    the effect at its null as instance ``<label>-scan<k>``, in ``form`` when given."""
    extra = {"form": form} if form else {}
    return [{"name": effect, "instance": f"{label}-scan{k + 1}", **extra,
             **{n: float(v) for n, v in zip(region, row, strict=True)}} for k, row in enumerate(regions)]


def scan(spec: Mapping[str, Any], observations: Observations, values: Mapping[str, float],
         theta: Sequence[str], label: str, *, load: Callable[..., Any], spacing: float | None = None,
         sizes: Sequence[float] | None = None, reference_wall_s: float | None = None,
         progress: Callable[[str], None] | None = None) -> RegionScan:
    """Scan candidate ``label`` (an effect declaring a region) over the tracked points of the
    fitted protocols of ``observations``, on the calibrated model ``spec`` at ``values`` (name
    -> SI) with fitted parameters ``theta``. ``load(spec)`` builds a forward model; ``spacing``
    [m] and ``sizes`` [m]: the grid's (:func:`scan_grid`; None: its defaults);
    ``reference_wall_s`` [s]: a plain prediction's wall time, to state the cost in forward
    equivalents. :class:`ScanError` without tracked points, or for a grid :func:`scan_grid`
    refuses."""

    say = progress or (lambda _m: None)
    effect = effect_of(label)
    plugin = registry.create("skinkit.effects", effect)
    region = tuple(getattr(plugin, "region", None) or ())
    if len(region) != 3:
        raise ScanError(f"region scan: effect {effect!r} declares no region (x, y, size)")
    fitted = observations.fitted()
    area = imaged_area(fitted)
    if area is None:
        raise ScanError(f"region scan of {label}: the session has no tracked points, so no imaged area "
                        "to scan")
    declared = {p.name: p for p in plugin.parameters()}
    xs, ys, ss = (declared[n] for n in region)
    grid = scan_grid(area, spacing, sizes, size_bounds=(ss.lower, ss.upper), size_name=f"{label}.{region[2]}",
                     centre_bounds=((xs.lower, xs.upper), (ys.lower, ys.upper)))
    regs = grid.regions()
    tested = [n for n in declared if n not in region]
    tables = instance_tables(effect, label, region, regs)
    names = list(theta) + [f"{t['instance']}.{n}" for t in tables for n in tested]
    say(f"region scan of {label}: {len(regs)} regions ({len(grid.centres)} centres "
        f"{grid.spacing * 1e3:.3g} mm apart x {len(grid.sizes)} sizes) in one prediction with "
        f"{len(names)} sensitivities")
    tests, A, pred_methods, wall = instance_tests(spec, fitted, values, theta, label, plugin, tables, names,
                                                  load=load)
    min_p = null_min_p(A, [t.dof for t in tests])
    scan_r = RegionScan(label, tuple(f"{label}.{n}" for n in region), [f"{label}.{n}" for n in tested],  # type: ignore[arg-type]
                        grid, area, tests, np.ones(len(tests)), np.zeros(len(tests)), min_p)
    adj = [scan_r.adjusted(t.log_p) for t in tests]
    scan_r.p_adjusted = np.array([a[0] for a in adj])
    scan_r.log_p_adjusted = np.array([a[1] for a in adj])
    methods = sorted({str(pred_methods.get(n, "analytic")) for n in names[len(theta):]})
    scan_r.cost = {"n_forward": 1, "columns": len(names), "region_columns": len(names) - len(theta),
                   "wall_s": wall, "methods": methods,
                   "forward_equivalents": wall / reference_wall_s if reference_wall_s else None}
    b = scan_r.best
    say(f"region scan of {label}: best region x {regs[b, 0] * 1e3:.2f} mm, y {regs[b, 1] * 1e3:.2f} mm, "
        f"size {regs[b, 2] * 1e3:.2f} mm (LM {tests[b].statistic:.4g}, adjusted p "
        f"{scan_r.p_adjusted[b]:.3g}); {wall:.1f} s")
    return scan_r


def instance_tests(spec: Mapping[str, Any], fitted: Observations, values: Mapping[str, float],
                   theta: Sequence[str], label: str, plugin: Any, tables: Sequence[Mapping[str, Any]],
                   names: Sequence[str], *, load: Callable[..., Any]
                   ) -> tuple[list[ScoreTest], list[np.ndarray], dict[str, str], float]:
    """The score test of every instance of ``tables`` (the effect at its null, each a candidate
    region, all in one model ``spec``): one prediction of the ``fitted`` observations at ``values``
    with the sensitivities ``names`` (``theta``, then each instance's tested parameters), the
    whitened residual and :func:`region_tests` with the noise colour. Returns ``(tests, projected
    unit columns, how each column was made, the prediction's wall time [s])``."""
    from skinkit.inverse.objective import Objective

    t0 = time.perf_counter()
    model = load(with_effects(spec, tables))
    try:
        ps = model.parameters()
        ps = ps.with_values({k: v for k, v in values.items() if k in ps.names})
        pred = model.predict(ps, fitted, sensitivities=list(names))
        keep = set(fitted.names)
        pred = Prediction({p: c for p, c in pred.protocols.items() if p in keep}, pred.methods, pred.inputs,
                          pred.info)
        res = Objective(model, fitted, list(names), "noise").residual(pred)
    finally:
        model.close()
    wall = time.perf_counter() - t0
    colour = colour_of(fitted, pred)
    if colour is not None and colour.blocks[-1][0].stop != res.z.size:
        colour = None          # not the residual's layout: test as if the coefficients were known
    tests, A = region_tests(res.z, res.J, len(theta), label, plugin, colour, pred.methods)
    return tests, A, dict(pred.methods), wall


def region_tests(z: np.ndarray, J: np.ndarray, k: int, label: str, plugin: Any, colour: Colour | None = None,
                 methods: Mapping[str, str] | None = None) -> tuple[list[ScoreTest], list[np.ndarray]]:
    """Every region's score test (:func:`skinkit.gap.score.score_test`) from the scan's whitened
    residual ``z`` ``(m,)`` and Jacobian ``J`` ``(m, k + R·q)`` [1 per SI unit]: the k fitted
    parameters first, then each region's q tested parameters (the effect ``plugin``'s parameters
    other than its region, in declared order); and each region's projected unit columns
    ``(m, q_r)`` (for :func:`null_min_p`). ``methods``: model name -> how its column was made."""
    region = tuple(plugin.region)
    declared = {p.name: p for p in plugin.parameters()}
    null = {n: float(v) for n, v in plugin.null().items()}
    tested = [n for n in declared if n not in region]
    methods = methods or {}
    U = fitted_basis(J[:, :k])
    q = len(tested)
    names = [f"{label}.{n}" for n in tested]
    typical = {f"{label}.{n}": float(declared[n].value) for n in declared}
    nul = {f"{label}.{n}": float(null[n]) for n in declared}
    bounds = {f"{label}.{n}": (float(declared[n].lower), float(declared[n].upper)) for n in declared}
    held = {f"{label}.{n}": "scanned: held at each region of the grid" for n in region}
    sides = np.array([1.0 if nul[n] <= bounds[n][0] else -1.0 if nul[n] >= bounds[n][1] else 0.0
                      for n in names])
    tests, cols_out = [], []
    for r in range((J.shape[1] - k) // max(q, 1)):
        Jr = J[:, k + r * q:k + (r + 1) * q]
        size = np.array([abs(typical[n] - nul[n]) or 1.0 for n in names])
        seen = [j for j in range(q) if float(np.linalg.norm(Jr[:, j])) * size[j] > FLAT]
        flat = {names[j]: "no signature at this region" for j in range(q) if j not in seen}
        how = {names[j]: str(methods.get(f"{label}-scan{r + 1}.{tested[j]}", "analytic")) for j in range(q)}
        cols = EffectColumns(label, [names[j] for j in seen], Jr[:, seen], how, sides[seen], nul, typical,
                             {**held, **flat}, bounds)
        tests.append(score_test(z, U, cols, colour))
        Ap = Jr[:, seen] - U @ (U.T @ Jr[:, seen]) if U.shape[1] else Jr[:, seen]
        nrm = np.linalg.norm(Ap, axis=0)
        cols_out.append(Ap[:, nrm > 0] / nrm[nrm > 0])
    return tests, cols_out


def null_min_p(A: Sequence[np.ndarray], dofs: Sequence[int], draws: int = N_DRAWS) -> np.ndarray:
    """Sorted ``(draws,)`` smallest p over the regions under the null, given each region's
    projected unit columns ``A[r]`` ``(m, q_r)`` and its test's dof: t = Aᵀz ~ N(0, G), G = AᵀA,
    each region's LM = t_rᵀ G_rr⁺ t_r referred to χ² with its dof (module docstring)."""
    groups = [a.shape[1] for a in A]
    if not any(groups):
        return np.ones(0)
    Aall = np.hstack([a for a in A if a.shape[1]])
    G = Aall.T @ Aall
    w, V = np.linalg.eigh(G)
    L = V * np.sqrt(np.clip(w, 0.0, None))          # t = L g, g ~ N(0, I)
    inv, start = [], 0
    for n in groups:
        inv.append((start, n, np.linalg.pinv(G[start:start + n, start:start + n]) if n else None))
        start += n
    rng = np.random.default_rng(SEED)
    out = []
    for lo in range(0, draws, 5000):
        g = rng.standard_normal((min(5000, draws - lo), L.shape[1]))
        t = g @ L.T
        lm = np.zeros((t.shape[0], len(groups)))
        for r, (s0, n, Gi) in enumerate(inv):
            if n and dofs[r]:
                tr = t[:, s0:s0 + n]
                lm[:, r] = np.einsum("di,ij,dj->d", tr, Gi, tr)
        q = {int(d) for d, n in zip(dofs, groups, strict=True) if n and d}
        if len(q) == 1:      # one reference distribution: the smallest p is the largest statistic's
            out.append(stats.chi2.sf(lm.max(axis=1), q.pop()))
            continue
        sf = np.ones_like(lm)
        for r, d in enumerate(dofs):
            if d and groups[r]:
                sf[:, r] = stats.chi2.sf(lm[:, r], d)
        out.append(sf.min(axis=1))
    return np.sort(np.concatenate(out))


__all__ = ["DEFAULT_CELLS", "DEFAULT_SIZES", "N_DRAWS", "RIVAL_SHARE", "ImagedArea", "RegionScan",
           "ScanError", "ScanGrid", "imaged_area", "null_min_p", "positive", "region_of", "region_tests",
           "scan", "scan_grid"]
