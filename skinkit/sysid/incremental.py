"""Incremental analysis (thesis 4.2.3): K, B, I per increment against mean position,
Young's modulus ``E = (1 - nu^2) K / (2 Rp)`` (semi-infinite body under a flat circular
probe of radius Rp), and ascending-versus-descending hysteresis."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from skinkit.sysid.checks import SysidError, check_signals
from skinkit.sysid.inputs import Segment
from skinkit.sysid.linear import LinearModel, identify_signals
from skinkit.sysid.robot import RobotDynamics

#: Poisson's ratio of skin (thesis 4.3, after Tilleman et al. 2004)
SKIN_POISSON = 0.45


def youngs_modulus(K_N_per_m: float | np.ndarray, probe_radius_m: float,
                   poisson: float = SKIN_POISSON) -> float | np.ndarray:
    """``E = (1 - nu^2) K / (2 Rp)`` [Pa] from stiffness [N/m] and probe radius [m]."""
    if probe_radius_m <= 0:
        raise SysidError(f"probe radius must be positive, got {probe_radius_m!r} m")
    if not -1 < poisson <= 0.5:
        raise SysidError(f"Poisson's ratio must lie in (-1, 0.5], got {poisson!r}")
    return (1 - poisson**2) * np.asarray(K_N_per_m) / (2 * probe_radius_m)


@dataclass
class Increment:
    """One increment: its segment, the identified model (or the reason it failed)."""

    segment: Segment
    model: LinearModel | None
    error: str = ""
    issues: list[str] = field(default_factory=list)


@dataclass
class IncrementalResult:
    """Per-increment linear models of an incremental protocol."""

    increments: list[Increment]
    probe_radius_m: float | None = None
    poisson: float = SKIN_POISSON

    def table(self) -> list[dict[str, Any]]:
        """One row per increment (tidy): index, direction, mean force [N], mean position [m],
        K, B, I, VAF, E [Pa] (when the probe radius is known), error, warnings."""
        rows = []
        for inc in self.increments:
            s, m = inc.segment, inc.model
            row: dict[str, Any] = {"index": s.index, "direction": s.direction,
                                   "mean_force_N": s.mean_N, "start": s.start, "stop": s.stop}
            if m is not None:
                row.update({"position_mean_m": m.position_mean_m, "K_N_per_m": m.skin.K,
                            "B_Ns_per_m": m.skin.B, "I_kg": m.skin.I,
                            "vaf_linear_pct": m.vaf_linear_pct, "valid": m.valid})
                if self.probe_radius_m is not None:
                    row["E_Pa"] = float(youngs_modulus(m.skin.K, self.probe_radius_m,
                                                       self.poisson))
            else:
                row.update({k: float("nan") for k in ("position_mean_m", "K_N_per_m",
                                                      "B_Ns_per_m", "I_kg", "vaf_linear_pct")})
                row["valid"] = False
            row["error"] = inc.error
            row["warnings"] = list(inc.issues)
            rows.append(row)
        return rows

    def hysteresis(self) -> list[dict[str, Any]]:
        """Ascending vs descending at each mean force level reached both ways: position
        offset (down minus up) [m] and stiffness ratio (down / up)."""
        ups = {round(i.segment.mean_N, 9): i for i in self.increments
               if i.segment.direction == "up" and i.model is not None}
        out = []
        for inc in self.increments:
            if inc.segment.direction != "down" or inc.model is None:
                continue
            up = ups.get(round(inc.segment.mean_N, 9))
            if up is None or up.model is None:
                continue
            out.append({"mean_force_N": inc.segment.mean_N,
                        "position_offset_m": inc.model.position_mean_m - up.model.position_mean_m,
                        "K_ratio": inc.model.skin.K / up.model.skin.K})
        return out


def identify_incremental(force_N: Any, position_m: Any, rate_hz: float,
                         segments: Sequence[Segment | tuple[int, int]], *,
                         memory_s: float | None = None, robot: RobotDynamics | None = None,
                         probe_radius_m: float | None = None, poisson: float = SKIN_POISSON,
                         hold: str = "foh") -> IncrementalResult:
    """Identify a linear model in every ``"identify"`` segment of an incremental record.

    ``segments`` come from :func:`skinkit.sysid.inputs.incremental` (``Programme.segments``)
    or are ``(start, stop)`` sample ranges. An increment that cannot be identified keeps
    its error message instead of stopping the others.
    """
    f = np.asarray(force_N, float)
    y = np.asarray(position_m, float)
    if f.shape != y.shape or f.ndim != 1:
        raise SysidError(f"force_N {f.shape} and position_m {y.shape} must be equal (N,) arrays")
    segs = [s if isinstance(s, Segment) else Segment(int(s[0]), int(s[1]), "identify",
                                                     float(np.mean(f[s[0]:s[1]])), "", k)
            for k, s in enumerate(segments)]
    segs = [s for s in segs if s.kind == "identify"]
    if not segs:
        raise SysidError("no segments of kind 'identify' to analyse")
    out = []
    for s in segs:
        if not 0 <= s.start < s.stop <= f.size:
            raise SysidError(f"segment {s.start}:{s.stop} lies outside the record of {f.size}")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                sig = check_signals(f[s.start:s.stop], y[s.start:s.stop], rate_hz=rate_hz,
                                    memory_s=memory_s)
                m = identify_signals(sig, memory_s, hold=hold, robot=robot)
                out.append(Increment(s, m, issues=list(m.issues)))
            except SysidError as exc:
                out.append(Increment(s, None, str(exc),
                                     [f"{w.category.__name__}: {w.message}" for w in caught]))
    return IncrementalResult(out, probe_radius_m, poisson)
