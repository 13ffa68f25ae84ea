"""Virtual scar sessions: a two-pad extension whose truth has a stiff elliptical scar between the pads.

The healthy model is the example ``extension_twopad_scar.toml`` (the real record's two-pad model on
a coarse pinned mesh). A seed draws a scar (:func:`draw_scar`), the truth is that model with the
``inclusion`` effect in its ``ellipse`` form (:func:`scar_truth`), and the virtual lab runs it —
on a mesh of its own by default (:mod:`skinkit.lab.truth_mesh`) — through the model's session (one
pull along x to 3.8 mm and back) and records it with the real record's instruments
(:class:`skinkit.lab.record_sensors.ExtensometerSensors`). The session file holds what those
instruments would give; the scar, its outline and the rest of the truth go to the truth file only.

The scar: stiffness ratio uniform in :data:`RATIO_RANGE`; each of its two diameters uniform in
:data:`SPAN_RANGE_M` (semi-axes half that); its direction uniform over a half turn; then redrawn
until its outline fits inside the pads' gap band — between the pads' facing edges in x, within the
pads' width in y, the region the real record's tracker covers — with its centre uniform over the
positions where it fits. A healthy session (``healthy``) has the same geometry, protocol and noise
draws and no scar: a null session to hold the diagnosis against.

Tracked points: a grid of :data:`TRACK_SPACING_M` over the gap and around the pads
(:data:`TRACK_HALF_M`), clear of the pads by :data:`TRACK_CLEARANCE_M`.
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from skinkit.lab.session import LabError, VirtualSession

#: the example model of the sessions (package data; ``skinkit.examples.example_model``)
MODEL = "extension_twopad_scar"
#: the scar's stiffness over the healthy skin's [1]
RATIO_RANGE = (2.0, 10.0)
#: each diameter of the scar [m] (semi-axes half of it)
SPAN_RANGE_M = (4e-3, 12e-3)
#: tracked points: grid spacing, half extents in x and y around the origin, clearance from a pad [m]
#: (the bonded pads' edges and corners make the strain singular: points nearer than 2 mm, or well
#: ahead of the moving pad, would measure the meshes' error there more than the skin)
TRACK_SPACING_M = 2e-3
TRACK_HALF_M = (24e-3, 10e-3)
TRACK_CLEARANCE_M = 2e-3
#: draws of a scar before giving up on fitting one in the band (each fits with probability > 0.3)
MAX_DRAWS = 1000
#: random stream of the scar, apart from the noise's (protocol index i uses [seed, i])
SCAR_STREAM = 1_000_003
#: points of the outline the truth file holds
OUTLINE_POINTS = 72


@dataclass(frozen=True)
class Scar:
    """An elliptical scar: stiffness ``ratio`` [1], centre ``x``, ``y`` [m], semi-axes ``a``, ``b``
    [m], ``angle`` [rad] of the ``a`` axis from x (in [-π/2, π/2))."""

    ratio: float
    x: float
    y: float
    a: float
    b: float
    angle: float

    def half_extent(self) -> tuple[float, float]:
        """Half the outline's bounding box along x and y [m]."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        return (math.sqrt((self.a * c) ** 2 + (self.b * s) ** 2),
                math.sqrt((self.a * s) ** 2 + (self.b * c) ** 2))

    def outline(self, n: int = OUTLINE_POINTS) -> np.ndarray:
        """``(n, 2)`` points [m] of the outline in the skin plane (the field's half level)."""
        t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
        c, s = math.cos(self.angle), math.sin(self.angle)
        u, v = self.a * np.cos(t), self.b * np.sin(t)
        return np.column_stack([self.x + c * u - s * v, self.y + s * u + c * v])

    def effect(self) -> dict[str, Any]:
        """The ``[[effects]]`` table that puts it into a model (SI values)."""
        return {"name": "inclusion", "form": "ellipse", "ratio": self.ratio, "x": self.x, "y": self.y,
                "a": self.a, "b": self.b, "angle": self.angle}

    def to_dict(self) -> dict[str, Any]:
        """The truth file's ``scar`` entry: SI values, the same in mm and degrees, the outline."""
        return {"ratio": self.ratio, "x_m": self.x, "y_m": self.y, "a_m": self.a, "b_m": self.b,
                "angle_rad": self.angle, "spans_mm": [2e3 * self.a, 2e3 * self.b],
                "centre_mm": [1e3 * self.x, 1e3 * self.y], "angle_deg": math.degrees(self.angle),
                "outline_m": self.outline().tolist()}


def gap_band(spec: Mapping[str, Any]) -> tuple[float, float]:
    """Half the pads' facing-edge gap and half the pad size [m] of a two-pad description."""
    from skinkit.fem.twopad import GAP, PAD_SIZE
    from skinkit.fem.values import quantity

    g = dict(spec.get("geometry", {}) or {})
    if g.get("kind") != "twopad":
        raise LabError(f"scar session: the model's geometry must be kind 'twopad', got {g.get('kind')!r}")
    return (0.5 * quantity(g.get("gap", GAP), "m", "geometry.gap"),
            0.5 * quantity(g.get("pad_size", PAD_SIZE), "m", "geometry.pad_size"))


def draw_scar(rng: np.random.Generator, half_gap: float, half_band: float) -> Scar:
    """A scar drawn by ``rng`` (module docstring) whose outline lies inside the band
    ``|x| <= half_gap``, ``|y| <= half_band`` [m]."""
    lo, hi = SPAN_RANGE_M
    for _ in range(MAX_DRAWS):
        ratio = float(rng.uniform(*RATIO_RANGE))
        a, b = (float(v) for v in 0.5 * rng.uniform(lo, hi, 2))
        angle = float(rng.uniform(-0.5 * math.pi, 0.5 * math.pi))
        hx, hy = Scar(ratio, 0.0, 0.0, a, b, angle).half_extent()
        if hx < half_gap and hy < half_band:
            x = float(rng.uniform(-(half_gap - hx), half_gap - hx))
            y = float(rng.uniform(-(half_band - hy), half_band - hy))
            return Scar(ratio, x, y, a, b, angle)
    raise LabError(f"scar session: no scar of {lo * 1e3:g} to {hi * 1e3:g} mm fits in the pads' band "
                   f"({2e3 * half_gap:g} x {2e3 * half_band:g} mm) after {MAX_DRAWS} draws")


def scar_for_seed(seed: int, spec: Mapping[str, Any]) -> Scar:
    """The scar of ``seed`` for the two-pad description ``spec`` (its own random stream)."""
    return draw_scar(np.random.default_rng([int(seed), SCAR_STREAM]), *gap_band(spec))


def tracked_points(spec: Mapping[str, Any]) -> np.ndarray:
    """``(P, 3)`` [m] tracked points on the flat top: the module's grid, clear of the pads."""
    half_gap, half_pad = gap_band(spec)
    hx, hy = TRACK_HALF_M
    gx = np.arange(-hx, hx + 1e-12, TRACK_SPACING_M)
    gy = np.arange(-hy, hy + 1e-12, TRACK_SPACING_M)
    X, Y = (v.ravel() for v in np.meshgrid(gx, gy, indexing="ij"))
    c = TRACK_CLEARANCE_M
    ax = np.abs(X)
    on_pad = (ax > half_gap - c) & (ax < half_gap + 2 * half_pad + c) & (np.abs(Y) < half_pad + c)
    return np.column_stack([X[~on_pad], Y[~on_pad], np.zeros(int((~on_pad).sum()))])


def model_spec() -> dict[str, Any]:
    """The healthy two-pad description of the sessions (:data:`MODEL`)."""
    from skinkit.examples import example_model
    from skinkit.forward import read_description

    return read_description(example_model(MODEL))


def scar_truth(spec: Mapping[str, Any], scar: Scar | None) -> dict[str, Any]:
    """A copy of ``spec`` with the scar's ``inclusion`` effect added (unchanged when ``scar`` is None)."""
    out = copy.deepcopy(dict(spec))
    if scar is not None:
        out["effects"] = list(out.get("effects", []) or []) + [scar.effect()]
    return out


def check_seed(seed: Any) -> int:
    """``seed`` as a non-negative int, else a one-line :class:`LabError`."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise LabError(f"--seed: expected a non-negative integer, got {seed!r}")
    return int(seed)


def simulate_scar(seed: int, healthy: bool = False, mesh: str = "own",
                  progress: Callable[[str, float], None] | None = None,
                  workers: int | None = None) -> tuple[VirtualSession, Scar | None]:
    """The virtual session of ``seed`` in memory and its scar (None when ``healthy``); nothing
    written. ``mesh``: the truth on a mesh of its own (``"own"``) or the model's (``"shared"``)."""
    from skinkit.lab.record_sensors import ExtensometerSensors
    from skinkit.lab.session import simulate

    seed = check_seed(seed)
    spec = model_spec()
    scar = None if healthy else scar_for_seed(seed, spec)
    vs = simulate(scar_truth(spec, scar), seed, progress=progress, workers=workers,
                  points=tracked_points(spec), mesh=mesh, sensors=ExtensometerSensors())
    vs.truth.update(source=f"skinkit lab scar-session ({MODEL})", healthy=bool(healthy),
                    scar=scar.to_dict() if scar is not None else None,
                    scar_draw={"ratio": list(RATIO_RANGE), "spans_m": list(SPAN_RANGE_M),
                               "band_m": [2 * v for v in gap_band(spec)]})
    return vs, scar


def make_scar_session(out: str | os.PathLike[str], truth_out: str | os.PathLike[str], seed: int,
                      healthy: bool = False, mesh: str = "own",
                      progress: Callable[[str, float], None] | None = None,
                      workers: int | None = None) -> dict[str, Any]:
    """Write the scar session of ``seed`` to ``out`` (experiment file) and its truth to ``truth_out``
    (JSON: the scar with its outline, the truth model, the instruments); returns the truth document.
    Options are checked before the truth runs; nothing is left at either path on failure."""
    from skinkit.lab.session import check_options, write_session

    check_seed(seed)
    check_options(out, truth_out)
    vs, _ = simulate_scar(seed, healthy, mesh, progress, workers)
    return write_session(vs, out, truth_out, progress)


__all__ = ["MODEL", "RATIO_RANGE", "SPAN_RANGE_M", "Scar", "check_seed", "draw_scar", "gap_band",
           "make_scar_session", "model_spec", "scar_for_seed", "scar_truth", "simulate_scar",
           "tracked_points"]
