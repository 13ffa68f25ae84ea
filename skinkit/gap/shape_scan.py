"""The shape of a found region: elongated candidates scored at the region scan's best centre.

The region scan (:mod:`skinkit.gap.scan`) finds where a region effect's signature is strongest
with discs, whose one size cannot say how long a region is or which way it runs; a scar is
rarely round (a healed incision, a burn along a limb). An effect that also comes in an
elliptical form declares it (``region_ellipse``: the form and the local names of its centre,
semi-axes and angle, :class:`skinkit.plugin.effects.BaseEffect`). At the scan's best centre,
ellipses of the best disc's area are then scored the same way — every one an instance of the
effect in that form at its null, one prediction with the sensitivities to their tested
parameters, each one's score test as the scan makes it:

* aspect ratios :data:`ASPECTS` (a/b), each at the angles :data:`ANGLES_DEG` of the ``a`` axis;
* the refit (:func:`skinkit.gap.diagnose`) starts, in the elliptical form, from the shape
  scoring highest, the disc included: when no ellipse scores above the disc, from an ellipse
  :data:`START_ASPECT` times longer than wide along the best-scoring direction, so that the angle
  has a signature to move by (a circle has none).

The shapes tested here are chosen after the scan, at one centre: their statistics choose a start,
not a p-value (the scan's adjusted p stays the candidate's).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit import registry
from skinkit.gap.scan import instance_tables, instance_tests
from skinkit.gap.score import ScoreTest, effect_of
from skinkit.schemas import Observations

#: elongations a/b of the ellipses scored (each of the best disc's area: a·b = r²)
ASPECTS = (2.0, 4.0)
#: directions of the ``a`` axis from x [deg]: a half turn in four (an ellipse turned 180° is itself)
ANGLES_DEG = (-45.0, 0.0, 45.0, 90.0)
#: a/b of the start when the disc scores above every ellipse
START_ASPECT = 1.2


@dataclass
class ShapeScan:
    """The shapes scored at one centre and the refit's start (module docstring).

    Attributes:
        effect: the candidate's label. form: the elliptical form's name. names: the model names
            of its centre, semi-axes and angle (``"<label>.<local>"``).
        shapes: ``(S, 5)`` each shape's x, y, a, b [m] and angle [rad]. tests: their score tests.
        disc: the statistic of the scan's best disc. start: ``(5,)`` the refit's start.
        cost: ``n_forward``, ``columns``, ``wall_s`` [s].
    """

    effect: str
    form: str
    names: tuple[str, ...]
    shapes: np.ndarray
    tests: list[ScoreTest]
    disc: float
    start: np.ndarray
    cost: dict[str, Any] = field(default_factory=dict)

    def values(self) -> dict[str, float]:
        """The refit's start as model values (name -> SI)."""
        return {n: float(v) for n, v in zip(self.names, self.start, strict=True)}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the form, every shape with its statistic, the disc's, the start, the cost."""
        s = self.shapes
        return {"form": self.form, "parameters": list(self.names),
                "shapes": {"x_m": s[:, 0].tolist(), "y_m": s[:, 1].tolist(), "a_m": s[:, 2].tolist(),
                           "b_m": s[:, 3].tolist(), "angle_deg": np.degrees(s[:, 4]).tolist(),
                           "statistic": [t.statistic for t in self.tests]},
                "disc_statistic": self.disc,
                "start": {"x_m": float(self.start[0]), "y_m": float(self.start[1]),
                          "a_m": float(self.start[2]), "b_m": float(self.start[3]),
                          "angle_deg": math.degrees(float(self.start[4]))},
                "cost": dict(self.cost)}


def elliptical(label: str) -> tuple[Any, str, tuple[str, ...]] | None:
    """Candidate ``label``'s effect in its elliptical form — ``(plugin, form, local names of x, y,
    a, b, angle)`` — or None when its effect declares none."""
    plugin = registry.create("skinkit.effects", effect_of(label))
    decl = getattr(plugin, "region_ellipse", None)
    if not decl:
        return None
    form, names = decl
    p = copy.copy(plugin)
    p.form = form
    p.region = tuple(names)      # what region_tests holds: every tested parameter but these
    return p, str(form), tuple(names)


def candidate_shapes(centre: Sequence[float], radius: float, bounds: tuple[float, float]) -> np.ndarray:
    """``(S, 5)`` the ellipses scored at ``centre`` (x, y) [m]: each aspect of :data:`ASPECTS` at
    each angle of :data:`ANGLES_DEG`, of the area of a disc of ``radius`` [m], semi-axes clipped
    to ``bounds`` [m]."""
    out = []
    for q in ASPECTS:
        a, b = (float(np.clip(v, *bounds)) for v in (radius * math.sqrt(q), radius / math.sqrt(q)))
        out += [(centre[0], centre[1], a, b, math.radians(d)) for d in ANGLES_DEG]
    return np.array(out, dtype=float)


def shape_scan(spec: Mapping[str, Any], observations: Observations, values: Mapping[str, float],
               theta: Sequence[str], label: str, best: Sequence[float], disc_statistic: float, *,
               load: Callable[..., Any], progress: Callable[[str], None] | None = None,
               where: str = "the best centre") -> ShapeScan | None:
    """Score elongated shapes of candidate ``label`` at the scan's best region ``best`` (x, y,
    radius) [m] whose disc scored ``disc_statistic``, on the calibrated model ``spec`` at
    ``values`` with fitted parameters ``theta`` (module docstring); None when the effect declares
    no elliptical form. ``where``: the centre's name in the progress line."""
    el = elliptical(label)
    if el is None:
        return None
    plugin, form, local = el
    say = progress or (lambda _m: None)
    declared = {p.name: p for p in plugin.parameters()}
    a_name = local[2]
    shapes = candidate_shapes(best[:2], float(best[2]), (declared[a_name].lower, declared[a_name].upper))
    tested = [n for n in declared if n not in local]
    effect = effect_of(label)
    tables = instance_tables(effect, label, local, shapes, form)
    names = list(theta) + [f"{t['instance']}.{n}" for t in tables for n in tested]
    tests, _, _, wall = instance_tests(spec, observations.fitted(), values, theta, label, plugin, tables,
                                       names, load=load)
    i = max(range(len(tests)), key=lambda k: tests[k].statistic)
    start = shapes[i].copy()
    if not tests[i].statistic > disc_statistic:
        r, q, lim = float(best[2]), START_ASPECT, declared[a_name]
        start[2:4] = np.clip([r * math.sqrt(q), r / math.sqrt(q)], lim.lower, lim.upper)
    out = ShapeScan(label, form, tuple(f"{label}.{n}" for n in local), shapes, tests, float(disc_statistic),
                    start, {"n_forward": 1, "columns": len(names), "wall_s": wall})
    say(f"shape of {label}: {len(shapes)} ellipses at {where}; best a/b "
        f"{shapes[i, 2] / shapes[i, 3]:.3g} at {math.degrees(shapes[i, 4]):.3g} deg "
        f"(LM {tests[i].statistic:.4g}, the disc's {disc_statistic:.4g}); refit starts at "
        f"a {start[2] * 1e3:.3g} mm, b {start[3] * 1e3:.3g} mm, {math.degrees(start[4]):.3g} deg; "
        f"{wall:.1f} s")
    return out


__all__ = ["ANGLES_DEG", "ASPECTS", "START_ASPECT", "ShapeScan", "candidate_shapes", "elliptical",
           "shape_scan"]
