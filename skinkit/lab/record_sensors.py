"""The instruments of the real healthy two-pad extension record, as a virtual-lab sensor model.

The virtual lab's default instruments are the microrobot's (:mod:`skinkit.lab.sensors`). A
two-pad extensometer with 2D image tracking records differently, and a virtual session meant to
stand beside the real record (``../shared/data/real/invivo_extension_dic_healthy``, read by
:func:`skinkit.store.dic_import.read_extensometer`) records as it does:

* **force** along the pull only (y and z not measured: NaN), Gaussian noise then rounded to the
  record's 1 mN resolution; the declared level :data:`FORCE_SIGMA_N` is the standard deviation
  of the record's **rest readings** (:func:`measure_record`);
* **pad displacement** along the pull only, likewise, to the record's 1 µm resolution, at the
  rest readings' :data:`POSITION_SIGMA_M`;
* **tracked points** in 2D: x and y with the tracker's own noise :data:`TRACK_SIGMA_M` (the
  import's scatter of each point about a cubic in frame index, 1.4826 MAD), z not measured
  (stored as 0, the track's ``dimensions`` 2, as the import writes it).

The rest readings are the samples about the record's rest sample (its lowest displacement before
the pull) whose displacement is within one resolution step of it: 5 samples (4 to 8), pad at 8 to
9 µm, force 72 to 88 mN. Five samples fix σ only to within a factor of about 0.6 to 2.9 (95 %, χ²
with 4 degrees of freedom); the record's second differences over its whole length give 4.2 mN
(1.4826 MAD / √6), just below that range (they also miss what wanders slowly). The rest readings
are what is used: the sensor's level with the skin still, as a tare would see it.

Figures of the healthy record (``measure_record``): force 7.43 mN, displacement 0.548 µm, track
16.97 µm (x) and 20.13 µm (y). The robot's logging rate (:data:`skinkit.lab.sensors.LOG_RATE_HZ`)
is kept: the virtual session has far more force samples per second than the record's nominal
10 Hz, each as noisy as one of the record's.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from skinkit.lab.sensors import SensorModel

#: the record's force at rest: standard deviation of the 5 rest readings [N] (module docstring)
FORCE_SIGMA_N = 7.43e-3
#: the record's force resolution [N] (values given to 1 mN)
FORCE_RESOLUTION_N = 1e-3
#: the record's pad displacement at rest: standard deviation of the same 5 readings [m]
POSITION_SIGMA_M = 0.548e-6
#: the record's displacement resolution [m] (values given to 1 µm)
POSITION_RESOLUTION_M = 1e-6
#: the tracker's noise per in-plane axis (x, y) [m]: the import's ``noise_m`` of the record
TRACK_SIGMA_M = (16.97e-6, 20.13e-6)
#: where the figures come from (the truth file says it)
SOURCE = ("invivo_extension_dic_healthy: force and displacement sigma of the rest readings (samples "
          "within one resolution step of the rest sample), track noise the import's noise_m")


def _gaussian_part(total: float, step: float) -> float:
    """σ of the Gaussian noise that, rounded to ``step``, reads ``total`` (variance σ² + step²/12)."""
    return math.sqrt(max(total * total - step * step / 12.0, 0.0))


@dataclass(frozen=True)
class ExtensometerSensors(SensorModel):
    """The real two-pad record's instruments (module docstring); ``scale`` multiplies every level
    and resolution, as for the robot's."""

    track_dimensions: ClassVar[int] = 2

    def position_sigma(self) -> np.ndarray:
        """``(3,)`` declared σ of a displacement sample [m] (only x is recorded)."""
        return np.full(3, self.scale * POSITION_SIGMA_M)

    def force_sigma(self) -> np.ndarray:
        """``(3,)`` declared σ of a force sample [N] (only x is recorded)."""
        return np.full(3, self.scale * FORCE_SIGMA_N)

    def sigma(self, channel: str) -> np.ndarray:
        """``(3,)`` declared noise; ``"points"``: x, y the tracker's, z (not recorded) their mean."""
        if channel == "points":
            sx, sy = (self.scale * s for s in TRACK_SIGMA_M)
            return np.array([sx, sy, 0.5 * (sx + sy)])
        return super().sigma(channel)

    def track_noise_m(self) -> list[float]:
        """The track's ``noise_m`` attribute: x, y [m] and NaN for z (not measured)."""
        return [self.scale * TRACK_SIGMA_M[0], self.scale * TRACK_SIGMA_M[1], float("nan")]

    def _along_x(self, v: np.ndarray, offset: np.ndarray, sigma: float, step: float,
                 rng: np.random.Generator) -> np.ndarray:
        v = np.asarray(v, dtype=float)
        out = np.full(v.shape, np.nan)
        noisy = v[:, 0] + _gaussian_part(sigma, step) * rng.standard_normal(len(v))
        out[:, 0] = np.round(noisy / step) * step + offset[0]
        return out

    def measure_position(self, x: np.ndarray, offset: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Recorded displacement ``(T, 3)`` [m] of the true ``x`` ``(T, 3)``: x only, y and z NaN."""
        return self._along_x(x, offset, self.scale * POSITION_SIGMA_M, self.scale * POSITION_RESOLUTION_M,
                             rng)

    def measure_force(self, f: np.ndarray, offset: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Recorded force ``(T, 3)`` [N] of the true ``f`` ``(T, 3)``: x only, y and z NaN."""
        return self._along_x(f, offset, self.scale * FORCE_SIGMA_N, self.scale * FORCE_RESOLUTION_N, rng)

    def measure_points(self, p: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Tracked positions ``(P, F, 3)`` [m] of the true ``p``: x and y with the tracker's noise,
        z 0 (a 2D track)."""
        p = np.asarray(p, dtype=float)
        out = np.zeros(p.shape)
        for j in (0, 1):
            out[..., j] = p[..., j] + self.scale * TRACK_SIGMA_M[j] * rng.standard_normal(p.shape[:2])
        return out

    def to_dict(self) -> dict[str, Any]:
        """The model's numbers (SI), JSON-ready, for the truth file."""
        d = super().to_dict()
        d.update(source=SOURCE, instrument="two-pad extensometer with 2D tracking (the real record's)",
                 tip_position={"sigma_m": self.scale * POSITION_SIGMA_M,
                               "resolution_m": self.scale * POSITION_RESOLUTION_M, "components": "x"},
                 tip_force={"sigma_n": self.scale * FORCE_SIGMA_N,
                            "resolution_n": self.scale * FORCE_RESOLUTION_N, "components": "x"},
                 points={"sigma_m": [self.scale * s for s in TRACK_SIGMA_M], "dimensions": 2})
        return d


def rest_readings(u: np.ndarray, rest: int, step: float) -> np.ndarray:
    """Indices of the rest readings: the contiguous samples about ``rest`` whose displacement
    ``u`` ``(N,)`` [m] is within ``step`` [m] (one resolution step, with rounding) of ``u[rest]``."""
    near = np.abs(np.asarray(u, float) - u[rest]) <= step * (1 + 1e-6)
    lo = hi = int(rest)
    while lo > 0 and near[lo - 1]:
        lo -= 1
    while hi + 1 < len(near) and near[hi + 1]:
        hi += 1
    return np.arange(lo, hi + 1)


def measure_record(folder: str | os.PathLike[str]) -> dict[str, Any]:
    """The noise figures of a two-pad extensometer record folder (the layout of
    :func:`skinkit.store.dic_import.read_extensometer`): ``force_sigma_n`` and
    ``position_sigma_m`` (standard deviation, n − 1, of the rest readings, :func:`rest_readings`),
    ``rest_samples`` (their indices), ``force_second_difference_n`` (1.4826 MAD of the whole
    record's second differences / √6, for comparison) and ``track_sigma_m`` (x, y) [m] (the
    import's ``noise_m``)."""
    from skinkit.store.dic_import import read_extensometer

    imp = read_extensometer(folder)
    u, f = imp.record.tip_position[:, 0], imp.record.tip_force[:, 0]
    idx = rest_readings(u, int(imp.record_attrs["rest_sample"]), POSITION_RESOLUTION_M)
    d2 = np.diff(f, 2)
    mad = 1.4826 * float(np.median(np.abs(d2 - np.median(d2))))
    return {"rest_samples": idx.tolist(), "force_sigma_n": float(np.std(f[idx], ddof=1)),
            "position_sigma_m": float(np.std(u[idx], ddof=1)),
            "force_second_difference_n": mad / math.sqrt(6.0),
            "track_sigma_m": [float(v) for v in imp.track_attrs["noise_m"][:2]]}


__all__ = ["FORCE_RESOLUTION_N", "FORCE_SIGMA_N", "POSITION_RESOLUTION_M", "POSITION_SIGMA_M", "SOURCE",
           "TRACK_SIGMA_M", "ExtensometerSensors", "measure_record", "rest_readings"]
