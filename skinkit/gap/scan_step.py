"""The diagnosis's region step: scan each candidate that declares a region, then test and refit it
at its best region.

For every remaining candidate whose effect declares a region (``region = (x, y, size)``) and a
session with tracked points, each round first scans candidate regions over the imaged area
(:func:`skinkit.gap.scan.scan`, one prediction). The candidate's score test is then made with
its position and size held at the best region (instead of the declared null position), and its
p-value is replaced by the one adjusted for the number of regions scanned — the best of many
regions is tested, and its raw p would open the gate on pure noise. Its refit starts at the best
region with the position and size freed, so that it estimates centre, size and strength with
their intervals. Each scan goes to the report's ``region_scan``.

Bad input is refused before the calibration: a region effect the model file places (start or
fixed values) with its centre outside the tracked points' extent, and scan options
(``--scan-grid``, ``--scan-sizes``) given for a session without tracked points or finer than its
points resolve.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from skinkit import registry
from skinkit.errors import SkinkitError
from skinkit.forward.stages import stage
from skinkit.gap.candidates import AIC_MARGIN
from skinkit.gap.scan import RegionScan, ScanError, imaged_area, positive, region_of, scan, scan_grid
from skinkit.gap.score import ScoreTest, effect_of
from skinkit.gap.shape_scan import ShapeScan, shape_scan
from skinkit.schemas import Observations


@dataclass(frozen=True)
class ScanOptions:
    """How the diagnosis scans region effects: ``spacing`` [m] of the grid of centres and
    ``sizes`` [m] (None: :func:`skinkit.gap.scan.scan_grid`'s defaults); ``enabled`` False: no
    scan (a region effect is tested at its declared null position)."""

    spacing: float | None = None
    sizes: tuple[float, ...] | None = None
    enabled: bool = True

    @property
    def explicit(self) -> bool:
        """Whether the grid was asked for (a spacing or sizes given)."""
        return self.spacing is not None or self.sizes is not None


@dataclass(frozen=True)
class Rival:
    """A second place of a region scan (:meth:`skinkit.gap.scan.RegionScan.rival`) to refit from:
    ``values`` its region (model names -> SI), ``form`` and ``form_values`` the elliptical form and
    start its shape scan chose (None, {} without one), ``step`` its score test's step (which way
    the region differs: stiffer or softer) and ``entry`` the scan's entry of the report it belongs
    to."""

    values: dict[str, float]
    form: str | None
    form_values: dict[str, float]
    step: dict[str, float]
    entry: dict[str, Any]


@dataclass
class RoundScan:
    """One round's scans: candidate label -> its :class:`RegionScan` (empty: nothing scanned),
    its :class:`ShapeScan` and its :class:`Rival`."""

    scans: dict[str, RegionScan] = field(default_factory=dict)
    shapes: dict[str, ShapeScan] = field(default_factory=dict)
    rivals: dict[str, Rival] = field(default_factory=dict)

    def refit_forms(self) -> dict[str, tuple[str, dict[str, float]]]:
        """Candidate label -> the form it is refitted in and that form's start values (model
        names -> SI), for every scanned candidate whose shape was scanned."""
        return {k: (v.form, v.values()) for k, v in self.shapes.items()}

    def values(self) -> dict[str, float]:
        """Every scanned candidate's best region as model values ``"<label>.<local>"`` [m]."""
        return {k: v for s in self.scans.values() for k, v in s.values().items()}

    def adjust(self, tests: Sequence[ScoreTest]) -> list[ScoreTest]:
        """``tests`` with each scanned candidate's p-value adjusted for its scan (its position and
        size held at the best region, said in ``held``), most significant first again."""
        out = []
        for t in tests:
            s = self.scans.get(t.effect)
            if s is None:
                out.append(t)
                continue
            p, log_p = s.adjusted(t.log_p)
            where = _where(s)
            held = {**t.held, **{n: f"held at the region scan's best region ({where}); p adjusted for the "
                                 f"{len(s.tests)} regions scanned" for n in s.region}}
            out.append(dataclasses.replace(t, p_value=p, log_p=log_p, held=held))
        return sorted(out, key=lambda t: (t.log_p, -t.statistic))


def _where(s: RegionScan) -> str:
    """The scan's best region in words: its centre and size in mm."""
    return _at(s.values(), 3)


def check_regions(spec: Mapping[str, Any], observations: Observations, options: ScanOptions | None) -> None:
    """Refuse, as one :class:`ScanError` line: an ``[[effects]]`` table of ``spec`` whose effect
    declares a region and whose centre (given, or the null where only one coordinate is)
    lies outside the tracked points' extent; scan ``options`` asked of a session without
    tracked points, or finer than its points resolve."""
    area = imaged_area(observations)
    for i, t in enumerate(spec.get("effects") or []):
        if not isinstance(t, Mapping):
            continue
        try:
            plugin = registry.create("skinkit.effects", str(t.get("name")))
        except SkinkitError:
            continue            # the model's reader names an unknown effect
        reg = getattr(plugin, "region", None)
        if not reg or area is None or not (reg[0] in t or reg[1] in t):
            continue
        v = plugin.values({k: t[k] for k in reg[:2] if k in t})
        if not area.contains((v[reg[0]], v[reg[1]])):
            what = t.get("instance", t.get("name"))
            raise ScanError(f"effects[{i}] ({what}): centre x {v[reg[0]] * 1e3:.3g} mm, "
                            f"y {v[reg[1]] * 1e3:.3g} mm lies outside the imaged area: the tracked points "
                            f"span {area.describe()}")
    if options is None or not options.enabled or not options.explicit:
        return
    if area is None:
        raise ScanError("--scan-grid/--scan-sizes: the session has no tracked points, so no imaged area to "
                        "scan for a region")
    scan_grid(area, options.spacing, options.sizes)


def check_centres(effects: Sequence[Any], values: Mapping[str, float], observations: Observations,
                  given: Sequence[str] = ()) -> None:
    """Refuse, as one :class:`ScanError` line naming the parameters, a region effect of a loaded
    model whose centre lies outside the tracked points' extent: ``effects`` the model's applied
    effects (each with ``name``, its label, and ``plugin``), ``values`` model name -> SI (the
    start or fixed values), ``given`` the names the user gave (``--start``: said so). Nothing
    to check without tracked points."""
    area = imaged_area(observations)
    if area is None:
        return
    for e in effects:
        reg = getattr(getattr(e, "plugin", None), "region", None)
        nx, ny = (f"{e.name}.{reg[0]}", f"{e.name}.{reg[1]}") if reg else ("", "")
        if nx in values and ny in values and not area.contains((values[nx], values[ny])):
            how = "--start " if nx in given or ny in given else ""
            x, y = values[nx] * 1e3, values[ny] * 1e3
            raise ScanError(f"{how}{nx}, {ny}: centre x {x:.3g} mm, y {y:.3g} mm "
                            f"lies outside the imaged area: the tracked points span {area.describe()}")


def scan_round(run: Any, spec_r: Mapping[str, Any], values: Mapping[str, float], rnd: int) -> RoundScan:
    """Scan every remaining candidate of the diagnosis ``run`` that declares a region (module
    docstring) on the current model ``spec_r`` at ``values``; each scan is said, counted in
    ``run.n_forward``, appended to ``run.scans`` and its best region kept in
    ``run.held_regions`` (the first found); a candidate whose effect has an elliptical form gets
    its shape scanned at the best region (:mod:`skinkit.gap.shape_scan`), kept in
    ``run.held_forms``. Empty without tracked points or when disabled."""
    opts = run.scan or ScanOptions()
    labels = [c for c in run.remaining if region_of(c)]
    out = RoundScan()
    if not labels or not opts.enabled:
        return out
    if imaged_area(run.observations.fitted()) is None:
        run.say(f"no tracked points: {', '.join(labels)} tested at the declared null position")
        return out
    wall = dict(run.current["prediction"].info or {}).get("wall_s")
    for label in labels:
        with stage("region scan"):
            try:
                s = scan(spec_r, run.observations, values, run.theta_r, label, load=run.loader,
                         spacing=opts.spacing, sizes=opts.sizes, reference_wall_s=wall, progress=run.say)
            except ScanError as exc:
                if opts.explicit:
                    raise
                run.say(f"region scan of {label} not made: {exc}")
                continue
        run.n_forward += int(s.cost["n_forward"])
        out.scans[label] = s
        entry = {"round": rnd + 1, **s.to_dict()}
        with stage("region scan"):
            shape = shape_scan(spec_r, run.observations, values, run.theta_r, label,
                               s.grid.regions()[s.best], s.tests[s.best].statistic, load=run.loader,
                               progress=run.say)
        if shape is not None:
            run.n_forward += int(shape.cost["n_forward"])
            out.shapes[label] = shape
            entry["shape"] = shape.to_dict()
            run.held_forms.setdefault(label, (shape.form, shape.values()))
        rival = _rival(run, spec_r, values, s, label, entry)
        if rival is not None:
            out.rivals[label] = rival
        run.scans.append(entry)
        for k, v in s.values().items():
            run.held_regions.setdefault(k, v)
    return out


def _rival(run: Any, spec_r: Mapping[str, Any], values: Mapping[str, float], s: RegionScan, label: str,
           entry: dict[str, Any]) -> Rival | None:
    """The scan's rival region (None without one), its shape scanned as the best's was."""
    i = s.rival()
    if i is None:
        return None
    row, t = s.grid.regions()[i], s.tests[i]
    run.say(f"region scan of {label}: a second place at x {row[0] * 1e3:.3g} mm, y {row[1] * 1e3:.3g} mm "
            f"scores {t.statistic / s.tests[s.best].statistic:.0%} of the best: both are refitted")
    with stage("region scan"):
        shape = shape_scan(spec_r, run.observations, values, run.theta_r, label, row, t.statistic,
                           load=run.loader, progress=run.say, where="the second place")
    form, form_values = None, {}
    if shape is not None:
        run.n_forward += int(shape.cost["n_forward"])
        entry["rival"]["shape"] = shape.to_dict()
        form, form_values = shape.form, shape.values()
    return Rival(s.region_values(i), form, form_values, dict(t.step), entry)


def rival_refit(run: Any, test: ScoreTest, state: dict[str, Any] | None, rival: Rival, entry: dict[str, Any],
                refit: Callable[[Mapping[str, float], tuple[str, Mapping[str, float]] | None, ScoreTest],
                                dict[str, Any]]) -> dict[str, Any] | None:
    """Refit candidate ``test.effect`` from its scan's ``rival`` region too and keep the better of
    that and ``state`` (the refit from the best region; None when it failed): the lower χ², both
    having the same parameters. ``refit(values, form, test)`` refits from those start values. Both
    are recorded in ``entry["rivals"]`` and on the scan's entry; when their χ² differ by no more
    than :data:`~skinkit.gap.candidates.AIC_MARGIN` the data cannot tell the two places apart,
    which a ``region-not-separable`` warning says. A rival refit that fails keeps ``state``."""
    label = test.effect
    run.say(f"refit with {label} from the second place ({_at(rival.values)})")
    try:
        with stage(f"refit {label}"):
            other = refit(rival.values, (rival.form, rival.form_values) if rival.form else None,
                          dataclasses.replace(test, step=rival.step))
        run.n_forward += other["result"].n_forward + 1
    except SkinkitError as exc:
        run.say(f"refit with {label} from the second place failed: {exc}")
        entry.setdefault("refit_failures", {})[f"{label} (second place)"] = str(exc)
        return state
    d = None if state is None else float(other["chi2"] - state["chi2"])
    kept = other if d is None or d < 0 else state
    rec = {"best": None if state is None else _summary(state), "rival": _summary(other), "delta_chi2": d,
           "kept": "rival" if kept is other else "best",
           "separable": None if d is None else abs(d) > AIC_MARGIN}
    entry.setdefault("rivals", {})[label] = rec
    rival.entry["rival"]["refits"] = rec
    if kept is other:       # a later refit of this effect alone starts where it fitted better
        run.held_regions.update(rival.values)
        if rival.form:
            run.held_forms[label] = (rival.form, rival.form_values)
    place = "second" if kept is other else "best"
    run.say(f"{label}: the refit from the {place} place is carried"
            + ("" if d is None else f" (its χ² {abs(d):.4g} lower than the other's)"))
    if rec["separable"] is False and state is not None:
        run.warnings.append({"kind": "region-not-separable", "where": label, "message": (
            f"{label}: two places fit the data alike — {_words(label, state)} and {_words(label, other)} "
            f"(χ² differ by {abs(d):.3g}, within the AIC margin of {AIC_MARGIN:g}): the data cannot tell "
            f"them apart; the report carries the {rec['kept']} one")})
    return kept


def _at(values: Mapping[str, float], n: int = 2) -> str:
    """The first ``n`` of a region's ``values`` (its centre; with its size at 3) in words, in mm."""
    return ", ".join(f"{k.partition('.')[2]} {v * 1e3:.3g} mm" for k, v in list(values.items())[:n])


def _summary(state: Mapping[str, Any]) -> dict[str, Any]:
    values = {k: v for k, v in state["table"].items() if isinstance(v, float)}
    return {"values": values, "chi2": state["chi2"]}


def _words(label: str, state: Mapping[str, Any]) -> str:
    """A refitted region effect's values in words: the region's lengths in mm, an ellipse's angle
    in degrees (the names its plugin declares as region and elliptical form), the rest as numbers."""
    plugin = registry.create("skinkit.effects", effect_of(label))
    el = getattr(plugin, "region_ellipse", None)
    lengths = set(getattr(plugin, "region", None) or ()) | set(el[1][:4] if el else ())
    angle = el[1][4] if el else None

    def one(k: str, v: float) -> str:
        return f"{k} {v * 1e3:.3g} mm" if k in lengths else f"{k} {math.degrees(v):.3g} deg" if k == angle \
            else f"{k} {v:.3g}"
    return ", ".join(one(k, v) for k, v in state["table"].items() if isinstance(v, float))


def scan_options(spacing_mm: float | None, sizes_mm: Sequence[float] | None, enabled: bool = True
                 ) -> ScanOptions:
    """:class:`ScanOptions` from the command line's millimetres (checked: positive and finite)."""
    def mm(v: Any, what: str) -> float:
        return positive(v, what, "a positive number of mm") * 1e-3
    sizes = None if sizes_mm is None else tuple(mm(v, "--scan-sizes") for v in sizes_mm)
    if sizes is not None and not sizes:
        raise ScanError("--scan-sizes: no size given")
    return ScanOptions(None if spacing_mm is None else mm(spacing_mm, "--scan-grid"), sizes, enabled)


__all__ = ["Rival", "RoundScan", "ScanOptions", "check_centres", "check_regions", "rival_refit",
           "scan_options", "scan_round"]
